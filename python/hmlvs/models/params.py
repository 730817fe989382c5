"""Sensor parameters (paper Eq. 10) with their units, nominal values and Table 2 bounds."""

from __future__ import annotations

from dataclasses import dataclass, fields
import math
from typing import ClassVar, Iterable, Mapping, Sequence

import numpy as np

NAMES: tuple[str, ...] = (
    "f", "Su", "Sv", "Cu", "Cv", "k", "H", "theta",
    "omega", "phi", "varphi", "tx", "ty", "tz",
)
UNITS: dict[str, str] = {
    "f": "mm", "Su": "mm/px", "Sv": "mm/px", "Cu": "px", "Cv": "px", "k": "1/mm^2",
    "H": "mm", "theta": "rad", "omega": "rad", "phi": "rad", "varphi": "rad",
    "tx": "mm", "ty": "mm", "tz": "mm",
}
DESCRIPTIONS: dict[str, str] = {
    "f": "effective focal length",
    "Su": "horizontal pixel pitch",
    "Sv": "vertical pixel pitch",
    "Cu": "principal point, column",
    "Cv": "principal point, row",
    "k": "first radial distortion coefficient (division model)",
    "H": "laser baseline",
    "theta": "laser projection angle",
    "omega": "hand-to-camera Euler Z (first)",
    "phi": "hand-to-camera Euler Y",
    "varphi": "hand-to-camera Euler Z (second)",
    "tx": "camera origin in the hand frame, x",
    "ty": "camera origin in the hand frame, y",
    "tz": "camera origin in the hand frame, z",
}
#: What a calibration holds fixed unless told otherwise (library and command line alike): the
#: scale gauge (Su) and the three parameters the laser data cannot separate from the camera's
#: position and tilt (Sv, Cu, Cv; docs/model.md, "What the data can and cannot determine").
#: Give them from the camera's datasheet or a prior camera calibration.
DEFAULT_FIXED: tuple[str, ...] = ("Su", "Sv", "Cu", "Cv")
#: why each of them is held, in a line
FIXED_WHY: dict[str, str] = {
    "Su": "scale gauge: f, Su, Sv, k scale together, so one of them must be given",
    "Sv": "with k = 0 the camera's shift along its y axis is absorbed by H, Sv and Cv",
    "Cu": "with Su, Sv and Cv, removes the last flat directions of the paper's data",
    "Cv": "mixes with the camera's y/z position and tilt about its x axis",
}
NOMINAL = np.array(
    [8.0, 0.0074, 0.0074, 320.0, 240.0, 0.0, 140.0, 5 * math.pi / 36,
     0.0, 0.0, 0.0, 60.0, 0.0, -45.0]
)
TABLE2_LOWER = np.array(
    [6.0, 0.005, 0.005, 300.0, 220.0, 0.0, 120.0, 0.0,
     -math.pi / 16, -math.pi / 16, -math.pi / 16, 40.0, -10.0, -60.0]
)
TABLE2_UPPER = np.array(
    [10.0, 0.01, 0.01, 340.0, 260.0, 0.1, 150.0, math.pi / 4,
     math.pi / 16, math.pi / 16, math.pi / 16, 80.0, 10.0, -30.0]
)
NUM_PARAMS = len(NAMES)


def param_index(name: str) -> int:
    """Index of a parameter in paper order; ``ValueError`` naming the valid ones otherwise."""
    try:
        return NAMES.index(name)
    except ValueError:
        raise ValueError(f"{name!r} is not a parameter; the parameters are {', '.join(NAMES)}") \
            from None


def fixed_mask(fixed: Iterable[str] | str) -> tuple[tuple[str, ...], np.ndarray]:
    """Parameter names to hold fixed -> (unique names in order, boolean mask over the 14).

    A single name may be given as a string; an unknown name raises ``ValueError``.
    """
    if isinstance(fixed, str):
        fixed = (fixed,)
    names = tuple(dict.fromkeys(fixed))
    mask = np.zeros(NUM_PARAMS, dtype=bool)
    for n in names:
        mask[param_index(n)] = True
    return names, mask


@dataclass(frozen=True)
class Parameters:
    """The 14 HMLVS parameters in the paper's order (Eq. 10). Units: mm, rad, pixels.

    Attributes
    ----------
    f : effective focal length (mm)
    Su, Sv : pixel pitch, horizontal and vertical (mm/px)
    Cu, Cv : principal point, column and row (px)
    k : radial distortion, division model (1/mm^2)
    H : laser baseline (mm)
    theta : laser projection angle (rad)
    omega, phi, varphi : ZYZ Euler angles of the hand_from_camera rotation (rad)
    tx, ty, tz : camera origin in the hand frame (mm)
    """

    f: float
    Su: float
    Sv: float
    Cu: float
    Cv: float
    k: float
    H: float
    theta: float
    omega: float
    phi: float
    varphi: float
    tx: float
    ty: float
    tz: float

    NAMES: ClassVar[tuple[str, ...]] = NAMES
    UNITS: ClassVar[dict[str, str]] = UNITS

    def __post_init__(self) -> None:
        for fld in fields(self):
            value = getattr(self, fld.name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"parameter {fld.name} must be a number, got {value!r}") from None
            if not math.isfinite(value):
                raise ValueError(f"parameter {fld.name} is not finite ({value})")
            object.__setattr__(self, fld.name, value)

    @classmethod
    def nominal(cls) -> "Parameters":
        """The paper's nominal values (Table 2)."""
        return cls.from_array(NOMINAL)

    @classmethod
    def from_array(cls, values: Sequence[float] | np.ndarray) -> "Parameters":
        arr = np.asarray(values, dtype=float).reshape(-1)
        if arr.shape != (NUM_PARAMS,):
            raise ValueError(f"a parameter vector has {NUM_PARAMS} values, got {arr.size}")
        return cls(*arr.tolist())

    @classmethod
    def from_dict(cls, values: Mapping[str, float]) -> "Parameters":
        unknown = set(values) - set(NAMES)
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}; the parameters are "
                             f"{', '.join(NAMES)}")
        missing = [n for n in NAMES if n not in values]
        if missing:
            raise ValueError(f"missing parameter(s) {missing}")
        return cls(**{n: values[n] for n in NAMES})

    def to_array(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in NAMES], dtype=float)

    def to_dict(self) -> dict[str, float]:
        return {n: getattr(self, n) for n in NAMES}

    def replace(self, **changes: float) -> "Parameters":
        d = self.to_dict()
        for name in changes:
            param_index(name)
        d.update(changes)
        return Parameters(**d)

    def table(self, other: "Parameters | None" = None, other_label: str = "true",
              std: Mapping[str, float] | None = None) -> str:
        """A fixed-width table of the parameters, optionally next to another set."""
        head = f"{'param':<7} {'unit':<7} {'value':>14}"
        if std is not None:
            head += f" {'std':>11}"
        if other is not None:
            head += f" {other_label:>14} {'difference':>12}"
        lines = [head, "-" * len(head)]
        for n in NAMES:
            v = getattr(self, n)
            line = f"{n:<7} {UNITS[n]:<7} {v:>14.7g}"
            if std is not None:
                s = std.get(n)
                line += f" {s:>11.3g}" if s is not None and math.isfinite(s) else f" {'fixed':>11}"
            if other is not None:
                o = getattr(other, n)
                line += f" {o:>14.7g} {v - o:>12.3g}"
            lines.append(line)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.table()


@dataclass(frozen=True)
class Bounds:
    """Lower and upper search bounds per parameter (paper Eq. 12; Table 2 by default)."""

    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self) -> None:
        lo = np.asarray(self.lower, dtype=float).reshape(-1)
        hi = np.asarray(self.upper, dtype=float).reshape(-1)
        if lo.shape != (NUM_PARAMS,) or hi.shape != (NUM_PARAMS,):
            raise ValueError(f"bounds need {NUM_PARAMS} lower and {NUM_PARAMS} upper values, got "
                             f"{lo.size} and {hi.size}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("bounds must be finite")
        bad = np.nonzero(lo > hi)[0]
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"bounds of {NAMES[i]}: lower {lo[i]:g} > upper {hi[i]:g}")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @classmethod
    def table2(cls) -> "Bounds":
        """The paper's search bounds (Table 2)."""
        return cls(TABLE2_LOWER.copy(), TABLE2_UPPER.copy())

    @classmethod
    def around(cls, center: Parameters | np.ndarray, s: float) -> "Bounds":
        """The box of the paper's Eq. 22, q0 (1 + (rand - 0.5) s), for the spread ``s``.

        Parameters whose centre is exactly 0 (omega, phi, varphi, ty and k at the nominal
        values) would get an empty box; as docs/model.md suggests they get the Table 2 bounds
        scaled by ``s`` instead, e.g. k in [0, 0.1 s] and omega in [-pi/16 s, pi/16 s].
        """
        q0 = center.to_array() if isinstance(center, Parameters) else np.asarray(center, float)
        if not s > 0:
            raise ValueError(f"the spread s must be > 0, got {s}")
        half = np.abs(q0) * s / 2
        lo, hi = q0 - half, q0 + half
        zero = q0 == 0
        lo[zero] = TABLE2_LOWER[zero] * s
        hi[zero] = TABLE2_UPPER[zero] * s
        return cls(lo, hi)

    @classmethod
    def plus_minus(cls, center: Parameters | np.ndarray,
                   half_widths: Mapping[str, float] | Sequence[float],
                   base: "Bounds | None" = None) -> "Bounds":
        """Absolute ranges ``center +- half_width`` (in each parameter's unit, e.g. tx +- 5 mm,
        phi +- 0.1 rad), for the parameters named in a mapping (the others keep ``base``,
        default Table 2) or for all 14 from a sequence."""
        q0 = center.to_array() if isinstance(center, Parameters) else np.asarray(center, float)
        base = cls.table2() if base is None else base
        lo, hi = base.lower.copy(), base.upper.copy()
        items = (half_widths.items() if isinstance(half_widths, Mapping)
                 else zip(NAMES, half_widths))
        for name, h in items:
            i = param_index(name)
            h = float(h)
            if not (h >= 0 and math.isfinite(h)):
                raise ValueError(f"the +- half-width of {name} must be a number >= 0, got {h}")
            lo[i], hi[i] = q0[i] - h, q0[i] + h
        return cls(lo, hi)

    def contains(self, params: Parameters | np.ndarray) -> bool:
        q = params.to_array() if isinstance(params, Parameters) else np.asarray(params, float)
        return bool(np.all(q >= self.lower) and np.all(q <= self.upper))

    @property
    def width(self) -> np.ndarray:
        return self.upper - self.lower

    def table(self) -> str:
        lines = [f"{'param':<7} {'unit':<7} {'lower':>12} {'upper':>12}"]
        for i, n in enumerate(NAMES):
            lines.append(f"{n:<7} {UNITS[n]:<7} {self.lower[i]:>12.6g} {self.upper[i]:>12.6g}")
        return "\n".join(lines)
