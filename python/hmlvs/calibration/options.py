"""Typed, validated solver options: the one place the C++ option structs are built from.

Each dataclass is frozen and checks its values on construction, so a wrong type or value
reaches the user as a ``ValueError`` naming the option ("pso.swarm_size must be a positive
integer, got '50'") instead of a pybind11 ``TypeError`` from inside the solve.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import math
from numbers import Integral, Real
from typing import Any

INT32_MAX = 2**31 - 1
MAX_THREADS = 2**31 - 1  # any count is accepted; calibrate caps it at the cores


def _count(prefix: str, name: str, value: Any, *, minimum: int = 1,
           maximum: int = INT32_MAX) -> int:
    """A whole number in [minimum, maximum]; bools and fractional values are refused."""
    kind = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ValueError(f"{prefix}.{name} must be {kind}, got {value!r}")
    if value < minimum:
        raise ValueError(f"{prefix}.{name} must be {kind}, got {value!r}")
    if value > maximum:
        raise ValueError(f"{prefix}.{name} must be at most {maximum}, got {value!r}")
    return int(value)


def _real(prefix: str, name: str, value: Any, *, minimum: float = 0.0,
          strict: bool = False, maximum: float = 1e12) -> float:
    """A finite real number >= minimum (> minimum when strict) and <= maximum."""
    bound = f"> {minimum:g}" if strict else f">= {minimum:g}"
    what = f"a finite number {bound}"
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{prefix}.{name} must be {what}, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < minimum or (strict and v == minimum):
        raise ValueError(f"{prefix}.{name} must be {what}, got {value!r}")
    if v > maximum:
        raise ValueError(f"{prefix}.{name} must be at most {maximum:g}, got {value!r}")
    return v


def _flag(prefix: str, name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{prefix}.{name} must be True or False, got {value!r}")
    return value


def _set(obj: Any, name: str, value: Any) -> None:
    object.__setattr__(obj, name, value)  # normalise (e.g. numpy ints) inside a frozen class


@dataclass(frozen=True)
class PsoOptions:
    """Particle swarm (paper Eq. 19-21) options.

    swarm_size : particles; iterations : generations per run; w_max, w_min : inertia weight
    decreasing linearly; c1, c2 : acceleration constants; vmax : velocity limit as a
    fraction of each parameter's range; target_fitness : stop once F <= this (mm^2, 0: never);
    progress_every : iterations between progress reports.
    """

    swarm_size: int = 50
    iterations: int = 5000
    w_max: float = 0.9
    w_min: float = 0.4
    c1: float = 2.0
    c2: float = 2.0
    vmax: float = 0.1
    target_fitness: float = 0.0
    progress_every: int = 100

    def __post_init__(self) -> None:
        p = "pso"
        _set(self, "swarm_size", _count(p, "swarm_size", self.swarm_size, maximum=1_000_000))
        _set(self, "iterations", _count(p, "iterations", self.iterations))
        for n in ("w_max", "w_min", "c1", "c2"):
            _set(self, n, _real(p, n, getattr(self, n), maximum=1e3))
        _set(self, "vmax", _real(p, "vmax", self.vmax, strict=True, maximum=1e3))
        _set(self, "target_fitness", _real(p, "target_fitness", self.target_fitness))
        _set(self, "progress_every", _count(p, "progress_every", self.progress_every))
        if self.w_min > self.w_max:
            raise ValueError(f"pso.w_min ({self.w_min:g}) must not exceed pso.w_max "
                             f"({self.w_max:g})")


@dataclass(frozen=True)
class LmOptions:
    """Levenberg-Marquardt (Ceres) options.

    max_iterations : iteration limit (0: the mode's default); loss_scale : robust loss scale
    (mm); use_bounds : keep the parameters inside the bounds (modern mode).
    """

    max_iterations: int = 0
    loss_scale: float = 1.0
    use_bounds: bool = True

    def __post_init__(self) -> None:
        p = "lm"
        _set(self, "max_iterations", _count(p, "max_iterations", self.max_iterations, minimum=0))
        _set(self, "loss_scale", _real(p, "loss_scale", self.loss_scale, strict=True))
        _flag(p, "use_bounds", self.use_bounds)


@dataclass(frozen=True)
class RandomSearchOptions:
    """Random search (paper Eq. 22) options. evaluations : candidates drawn."""

    evaluations: int = 1_000_000

    def __post_init__(self) -> None:
        _set(self, "evaluations", _count("random", "evaluations", self.evaluations))


def check_threads(threads: Any) -> int:
    return _count("calibrate", "threads", threads, maximum=MAX_THREADS)


def check_runs(runs: Any) -> int:
    return _count("calibrate", "runs", runs, maximum=1_000_000)


def check_seed(seed: Any) -> int:
    return _count("calibrate", "seed", seed, minimum=0, maximum=2**64 - 1)


def option_names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in fields(cls))


# --- the one place C++ option structs are built ----------------------------------------------

def pso_struct(o: PsoOptions, *, runs: int, threads: int, seed: int, lower: Any, upper: Any,
               init_lower: Any = None, init_upper: Any = None) -> Any:
    from .. import _core

    s = _core._PsoOptions()
    for n in option_names(PsoOptions):
        setattr(s, n, getattr(o, n))
    s.runs, s.threads, s.seed = runs, threads, seed
    s.lower, s.upper = lower, upper
    if init_lower is not None:
        s.init_lower, s.init_upper = init_lower, init_upper
    return s


def lm_struct(o: LmOptions, *, mode: str, fixed: Any, lower: Any, upper: Any,
              loss: str | None) -> Any:
    from .. import _core

    s = _core._LmOptions()
    s.mode = getattr(_core._LmMode, mode)
    s.fixed = [bool(x) for x in fixed]
    s.lower, s.upper = lower, upper
    s.use_bounds = o.use_bounds
    s.max_iterations = o.max_iterations
    s.loss = getattr(_core._LossKind, "none" if loss is None else loss)
    s.loss_scale = o.loss_scale
    if mode == "paper":  # MINPACK lmdif's default tolerances, as the paper used MINPACK
        s.function_tolerance = s.parameter_tolerance = 1.49012e-8
        s.gradient_tolerance = 0.0
    return s


def random_search_struct(o: RandomSearchOptions, *, threads: int, seed: int, lower: Any,
                         upper: Any) -> Any:
    from .. import _core

    s = _core._RandomSearchOptions()
    s.evaluations = o.evaluations
    s.threads, s.seed = threads, seed
    s.lower, s.upper = lower, upper
    return s
