"""The paper's simulation study (section 4): Table 1 and Fig. 8, with our methods added.

For each initial spread s (paper Eq. 22) the same noise-free data set (100 random pixels at the
Table 2 nominal parameters, the first 50 to fit, the last 50 held out) is identified by

* ``random``: random search, one run of 1,000,000 evaluations in the Eq. 22 box (paper: RS),
* ``lm-paper``: the paper's NLSO, LM on the scalar residual ||E_i|| with a forward-difference
  Jacobian, Euler angles, no bounds, at most 300 x 14 iterations, 1000 starts (paper: NLSO),
* ``pso``: the paper's PSO, 10 runs, swarm 50, 5000 iterations, Eq. 22 box (paper: PSO),
* ``lm``: modern LM (3 residual components, exact Jacobian, rotation on SO(3), no bounds,
  like the paper's) from the *same* 1000 starts as ``lm-paper``,
* ``pso+lm``: the same 10 PSO runs (same seed), each polished by modern LM.

All 14 parameters are estimated (nothing fixed), as in the paper. A run succeeds when its RMS
of ||E_i|| over the 50 held-out points is below :data:`SUCCESS_THRESHOLD` (0.01 mm).

``hmlvs.study(...)`` runs it and returns a :class:`StudyResult`; ``hmlvs study`` is the
command line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import io
import math
import os
from pathlib import Path
import time
from typing import Any, Callable, Iterable, Optional, Sequence
import warnings
import zlib

import numpy as np

from .._io import atomic_folder, atomic_write
from ..calibration.solvers import calibrate, fitness_data
from ..models.params import NUM_PARAMS, Bounds

PAPER_S: tuple[float, ...] = (1e-4, 1e-3, 1e-2, 0.1, 0.2)
METHODS: tuple[str, ...] = ("random", "lm-paper", "pso", "lm", "pso+lm")
LABELS: dict[str, str] = {
    "random": "RS",
    "lm-paper": "NLSO (paper-mode LM)",
    "pso": "PSO",
    "lm": "LM (modern)",
    "pso+lm": "PSO+LM",
}
SUCCESS_THRESHOLD = 0.01
"""Held-out RMS (mm) below which a run counts as a success. On noise-free data the true
parameters give 0 and modern LM reaches ~1e-13 mm; 0.01 mm is 13x finer than the sensor's
best resolution (0.134 mm/px, docs/paper.md "Sensor design analysis") and 35x below the paper's
experimental accuracy (0.355 mm), so a run below it is as good as exact for any use, and a run
above it has not found the minimum."""

FULL = {"runs_lm": 1000, "runs_pso": 10, "evaluations": 1_000_000}
QUICK = {"runs_lm": 30, "runs_pso": 5, "evaluations": 200_000}
PSO_ITERATIONS = 5000
SWARM_SIZE = 50
LM_MAX_ITERATIONS = 300 * NUM_PARAMS

# Paper Table 1 (fit RMS of ||E_i||, mm; the paper labels some rows E(q), some F(q)), per s in
# PAPER_S. Note: the PSO standard deviation at s = 0.2 (1.13e-3) cannot be right: with best
# 2.55e-3, worst 1.96e-2 and mean 1.16e-2 over 10 runs it is at least ~3.8e-3.
PAPER_TABLE1: dict[tuple[str, str], tuple[float, ...]] = {
    ("random", "best"): (1.25e-2, 7.48e-2, 1.79, 12.8, 19.1),
    ("lm-paper", "best"): (2.01e-5, 1.70e-4, 7.50e-4, 5.81e-3, 2.49e-2),
    ("lm-paper", "worst"): (0.13, 88.5, 1.26e3, 7.24e2, 1.11e3),
    ("lm-paper", "mean"): (1.01e-1, 6.75, 4.67e2, 6.20e2, 6.00e2),
    ("lm-paper", "std"): (3.13e-2, 20.5, 48.6, 4.43e2, 4.60e2),
    ("pso", "best"): (1.69e-5, 7.78e-5, 3.79e-4, 1.41e-3, 2.55e-3),
    ("pso", "worst"): (1.50e-4, 2.72e-4, 1.10e-3, 1.04e-2, 1.96e-2),
    ("pso", "mean"): (9.34e-5, 1.89e-4, 8.65e-4, 5.55e-3, 1.16e-2),
    ("pso", "std"): (9.11e-5, 1.58e-4, 6.05e-4, 5.76e-3, 1.13e-3),
}
STATS: tuple[str, ...] = ("best", "worst", "mean", "std")

StudyProgress = Callable[[str, float, int, int], Any]


def paper_value(method: str, stat: str, s: float) -> Optional[float]:
    """The paper's Table 1 entry for ``method``, ``stat`` and ``s``, or None if it has none."""
    row = PAPER_TABLE1.get((method, stat))
    for ps, v in zip(PAPER_S, row or ()):
        if math.isclose(ps, s, rel_tol=1e-9):
            return v
    return None


@dataclass(frozen=True)
class Stats:
    """Statistics of per-run RMS values (mm). ``std`` is the sample standard deviation
    (ddof = 1; NaN for one run). Runs whose parameters give no measurement count as inf."""

    best: float
    worst: float
    mean: float
    median: float
    std: float

    @classmethod
    def of(cls, values: np.ndarray) -> "Stats":
        v = np.asarray(values, dtype=float)
        with np.errstate(invalid="ignore", over="ignore"):
            return cls(best=float(v.min()), worst=float(v.max()), mean=float(v.mean()),
                       median=float(np.median(v)),
                       std=float(v.std(ddof=1)) if v.size > 1 else float("nan"))

    def get(self, name: str) -> float:
        return float(getattr(self, name))


@dataclass
class MethodRuns:
    """All runs of one method at one spread s.

    Attributes
    ----------
    method : one of :data:`METHODS`
    s : the Eq. 22 spread
    fit_rms : (runs,) RMS of ||E_i|| over the fitting points (mm), per run
    test_rms : (runs,) the same over the held-out points (mm)
    seconds : wall-clock time of all runs (s)
    threshold : success threshold on ``test_rms`` (mm)
    iterations : (runs,) LM iterations per run, or None (PSO, RS)
    iteration_limit : the LM iteration limit, or None
    params : (runs, 14) final parameters per run
    """

    method: str
    s: float
    fit_rms: np.ndarray
    test_rms: np.ndarray
    seconds: float
    threshold: float
    params: np.ndarray
    iterations: Optional[np.ndarray] = None
    iteration_limit: Optional[int] = None

    @property
    def runs(self) -> int:
        return int(self.fit_rms.size)

    @property
    def fit(self) -> Stats:
        return Stats.of(self.fit_rms)

    @property
    def test(self) -> Stats:
        return Stats.of(self.test_rms)

    @property
    def successes(self) -> int:
        return int(np.sum(self.test_rms < self.threshold))

    @property
    def success_rate(self) -> float:
        return self.successes / self.runs

    @property
    def capped(self) -> Optional[int]:
        """LM runs stopped by the iteration limit (None for PSO and RS)."""
        if self.iterations is None or self.iteration_limit is None:
            return None
        return int(np.sum(self.iterations >= self.iteration_limit))

    def to_dict(self, include_runs: bool = False) -> dict[str, Any]:
        d: dict[str, Any] = {
            "method": self.method, "s": self.s, "runs": self.runs, "seconds": self.seconds,
            "fit_rms": _stats_dict(self.fit), "test_rms": _stats_dict(self.test),
            "successes": self.successes, "success_rate": self.success_rate,
            "capped": self.capped,
        }
        if include_runs:
            d["fit_rms_runs"] = [_num(x) for x in self.fit_rms]
            d["test_rms_runs"] = [_num(x) for x in self.test_rms]
        return d


@dataclass
class HeldOut:
    """Fig. 8: per-point errors ||E_i|| (mm) on the 50 held-out points for the PSO runs with
    the best and the worst fitness at one spread s."""

    s: float
    method: str
    best_run: int
    worst_run: int
    best_errors: np.ndarray
    worst_errors: np.ndarray
    best_fit_rms: float
    worst_fit_rms: float

    @property
    def best_test_rms(self) -> float:
        return _rms(self.best_errors)

    @property
    def worst_test_rms(self) -> float:
        return _rms(self.worst_errors)

    @property
    def best_sse(self) -> float:
        """Sum of squared held-out errors (mm^2), the paper's Fig. 8 quantity."""
        return float(np.sum(self.best_errors**2))

    @property
    def worst_sse(self) -> float:
        return float(np.sum(self.worst_errors**2))

    def to_dict(self) -> dict[str, Any]:
        return {"s": self.s, "method": self.method, "best_run": self.best_run,
                "worst_run": self.worst_run, "best_fit_rms": self.best_fit_rms,
                "worst_fit_rms": self.worst_fit_rms, "best_test_rms": self.best_test_rms,
                "worst_test_rms": self.worst_test_rms, "best_sse": self.best_sse,
                "worst_sse": self.worst_sse,
                "best_errors": [float(x) for x in self.best_errors],
                "worst_errors": [float(x) for x in self.worst_errors]}


@dataclass(frozen=True)
class StudySettings:
    """What was run: run counts, data, seeds and threads."""

    s_values: tuple[float, ...]
    runs_lm: int
    runs_pso: int
    evaluations: int
    quick: bool
    seed: int
    threads: int
    threshold: float = SUCCESS_THRESHOLD
    pso_iterations: int = PSO_ITERATIONS
    swarm_size: int = SWARM_SIZE
    lm_max_iterations: int = LM_MAX_ITERATIONS
    fit_points: int = 50
    test_points: int = 50

    def describe(self) -> str:
        return (f"{'quick' if self.quick else 'full'} study, seed {self.seed}: "
                f"{self.fit_points} fitting and {self.test_points} held-out points (noise-free, "
                f"Table 2 nominal, `hmlvs.simulate(seed={self.seed})`); all 14 parameters "
                f"free; RS {self.evaluations:,} evaluations (1 run); NLSO and modern LM "
                f"{self.runs_lm} runs from the same Eq. 22 starts, at most "
                f"{self.lm_max_iterations} iterations; PSO and PSO+LM {self.runs_pso} runs "
                f"(swarm {self.swarm_size}, {self.pso_iterations} iterations); "
                f"{self.threads} threads")


@dataclass
class StudyResult:
    """The outcome of :func:`study`.

    Attributes
    ----------
    settings : what was run
    runs : per (method, s) the runs of that method (:class:`MethodRuns`)
    held_out : Fig. 8 data per s (:class:`HeldOut`, best and worst PSO run)
    seconds : wall-clock time of the whole study (s)
    cpu_seconds : CPU time of this process over the study, all threads (s)
    """

    settings: StudySettings
    runs: dict[tuple[str, float], MethodRuns]
    held_out: list[HeldOut]
    seconds: float
    cpu_seconds: float
    files: list[Path] = field(default_factory=list)

    def get(self, method: str, s: float) -> MethodRuns:
        """The runs of ``method`` at spread ``s``."""
        for (m, ss), r in self.runs.items():
            if m == method and math.isclose(ss, s, rel_tol=1e-9):
                return r
        raise ValueError(f"no runs of {method!r} at s = {s:g}; methods: {', '.join(METHODS)}; "
                         f"s values: {', '.join(f'{x:g}' for x in self.settings.s_values)}")

    def method_seconds(self, method: str) -> float:
        return float(sum(self.get(method, s).seconds for s in self.settings.s_values))

    def table(self) -> str:
        """Markdown: Table 1's layout (ours with the paper's in parentheses), held-out RMS,
        success rates and run times, and the Fig. 8 numbers."""
        return _markdown(self)

    def __str__(self) -> str:
        return self.table()

    def to_dict(self, include_runs: bool = False) -> dict[str, Any]:
        st = self.settings
        return {
            "settings": {k: (list(v) if isinstance(v, tuple) else v)
                         for k, v in st.__dict__.items()},
            "seconds": self.seconds, "cpu_seconds": self.cpu_seconds,
            "methods": [self.get(m, s).to_dict(include_runs) for m in METHODS
                        for s in st.s_values],
            "method_seconds": {m: self.method_seconds(m) for m in METHODS},
            "held_out": [h.to_dict() for h in self.held_out],
            "files": [str(p) for p in self.files],
        }

    def plot(self, out_dir: str | os.PathLike) -> list[Path]:
        """Write ``study_table1.png`` (RMS of every run per method and s, log scale, with the
        paper's best and worst) and ``study_fig8.png`` (held-out error per point of the best
        and worst PSO run per s) into ``out_dir``; returns the files (written atomically)."""
        out = _out_dir(out_dir)
        return [_plot_table1(self, out / "study_table1.png"),
                _plot_fig8(self, out / "study_fig8.png")]

    def write(self, out_dir: str | os.PathLike) -> list[Path]:
        """Write ``study.md`` (:meth:`table`) and the plots (:meth:`plot`) into ``out_dir``."""
        out = _out_dir(out_dir)
        # all three files or none (a run stopped while writing leaves the folder as it was)
        with atomic_folder(out, last=("study.md",)) as tmp:
            files = self.plot(tmp)
            with atomic_write(tmp / "study.md") as fh:
                fh.write(self.table())
        self.files = [out / "study.md", *(out / f.name for f in files)]
        return self.files


# ------------------------------------------------------------------------------------------
# Running the study


def _rms(errors: np.ndarray) -> float:
    e = np.asarray(errors, dtype=float)
    if e.size == 0 or not np.all(np.isfinite(e)):
        return float("inf")
    return float(np.sqrt(np.mean(e**2)))


def _num(x: float) -> Optional[float]:
    return float(x) if math.isfinite(x) else None


def _stats_dict(s: Stats) -> dict[str, Optional[float]]:
    return {k: _num(getattr(s, k)) for k in ("best", "worst", "mean", "median", "std")}


def _seed(seed: int, s: float, tag: int) -> int:
    """A seed per (study seed, s, stream): the same s gives the same runs whatever the other
    s values of the study."""
    ss = np.random.SeedSequence([seed, zlib.crc32(repr(float(s)).encode()), tag])
    return int(ss.generate_state(1)[0])


def _out_dir(out_dir: str | os.PathLike) -> Path:
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a folder")
    return out


def _count(name: str, value: Any, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _check_s(s_values: Iterable[float]) -> tuple[float, ...]:
    try:
        vals = tuple(float(s) for s in s_values)
    except (TypeError, ValueError):
        raise ValueError(f"s_values must be numbers, got {s_values!r}") from None
    if not vals:
        raise ValueError("s_values is empty: give at least one spread s")
    for s in vals:
        if not (math.isfinite(s) and 0 < s <= 1):
            raise ValueError(f"every spread s must lie in (0, 1], got {s:g}")
    if len(set(vals)) != len(vals):
        raise ValueError(f"s_values has repeated values: {', '.join(f'{s:g}' for s in vals)}")
    return vals


class _Reporter:
    """Progress of the study: a rich bar per step (method x s: its runs, PSO generations or
    random-search evaluations done / total) over a bar of the whole study in runs done / total,
    each with an ETA; or a callable; or nothing."""

    def __init__(self, progress: Any, total_runs: int) -> None:
        self.bar = None
        self.fn: Optional[StudyProgress] = None
        if progress is True:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self.bar = Progress(TextColumn("{task.description:<32}"), BarColumn(),
                                MofNCompleteColumn(), TimeElapsedColumn(),
                                TextColumn("ETA"), TimeRemainingColumn(),
                                console=Console(stderr=True), transient=True)
            self.overall = self.bar.add_task("study (runs)", total=total_runs)
            self.step = self.bar.add_task("", total=None)
            self.bar.start()
        elif callable(progress):
            self.fn = progress
        elif progress not in (None, False):
            raise ValueError("progress must be True, False, None or a callable "
                             "(method, s, done, total)")
        self.method, self.s = "", 0.0
        self.runs_before, self.runs = 0, 0

    def begin(self, method: str, s: float, runs: int) -> None:
        """A step of `runs` runs starts."""
        self.method, self.s, self.runs = method, s, runs
        if self.bar is not None:
            self.bar.reset(self.step, total=None,
                           description=f"{LABELS[method]}, s = {s:g}")
        if self.fn is not None:
            self.fn(method, s, 0, 0)

    def update(self, done: int, total: int, _best: float = 0.0) -> bool:
        if self.bar is not None:
            self.bar.update(self.step, completed=done, total=total)
            if total > 0:  # the step's share of its runs, whatever unit it counts in
                self.bar.update(self.overall,
                                completed=self.runs_before + self.runs * min(done, total) / total)
        if self.fn is not None:
            r = self.fn(self.method, self.s, int(done), int(total))
            return r is None or bool(r)
        return True

    def end(self) -> None:
        self.runs_before += self.runs
        if self.bar is not None:
            self.bar.update(self.overall, completed=self.runs_before)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def study(s_values: Sequence[float] = PAPER_S, runs_lm: Optional[int] = None,
          runs_pso: Optional[int] = None, evaluations: Optional[int] = None,
          quick: bool = False, seed: int = 0, threads: Optional[int] = None,
          progress: Any = True, out_dir: Optional[str | os.PathLike] = None) -> StudyResult:
    """Run the paper's simulation study (section 4, Table 1 and Fig. 8) with our methods.

    Parameters
    ----------
    s_values : spreads s of the initial candidates (paper Eq. 22)
    runs_lm : LM starts per s, the same for paper-mode and modern LM (default 1000; quick 30)
    runs_pso : PSO runs per s, also polished by LM for PSO+LM (default 10; quick 5)
    evaluations : random-search evaluations per s (default 1,000,000; quick 200,000)
    quick : smaller defaults for the run counts (explicit counts win)
    seed : seed of the data (``hmlvs.simulate(seed=seed)``) and of every method
    threads : worker threads (default: all cores); results do not depend on it
    progress : True (a rich progress bar on stderr), False/None, or a callable
        ``(method, s, done, total)``; it may raise (e.g. KeyboardInterrupt) to stop
    out_dir : if given, ``study.md`` and the PNG plots are written there

    Returns
    -------
    StudyResult

    Examples
    --------
    >>> r = hmlvs.study(quick=True, progress=False)
    >>> r.get("pso+lm", 0.2).success_rate
    1.0
    """
    from ..sim.sessions import simulate

    defaults = QUICK if quick else FULL
    s_vals = _check_s(s_values)
    n_lm = _count("runs_lm", defaults["runs_lm"] if runs_lm is None else runs_lm)
    n_pso = _count("runs_pso", defaults["runs_pso"] if runs_pso is None else runs_pso)
    n_eval = _count("evaluations", defaults["evaluations"] if evaluations is None
                    else evaluations)
    seed = _count("seed", seed, minimum=0)
    n_threads = _count("threads", (os.cpu_count() or 1) if threads is None else threads)
    out = None if out_dir is None else _out_dir(out_dir)
    sim = simulate(seed=seed)
    settings = StudySettings(s_values=s_vals, runs_lm=n_lm, runs_pso=n_pso, evaluations=n_eval,
                             quick=bool(quick), seed=seed, threads=n_threads,
                             fit_points=len(sim.fit), test_points=len(sim.test))
    truth = sim.truth
    fit_data, test_data = fitness_data(sim.fit), fitness_data(sim.test)

    def errors(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if not np.all(np.isfinite(q)):
            return np.full(len(sim.fit), np.inf), np.full(len(sim.test), np.inf)
        return np.array(fit_data.point_errors(q)), np.array(test_data.point_errors(q))

    def step_runs(method: str) -> int:
        return 1 if method == "random" else n_lm if method in ("lm", "lm-paper") else n_pso

    reporter = _Reporter(progress, len(s_vals) * sum(step_runs(m) for m in METHODS))
    runs: dict[tuple[str, float], MethodRuns] = {}
    held_out: list[HeldOut] = []
    wall0, cpu0 = time.perf_counter(), time.process_time()
    from ..diagnostics.identifiability import HmlvsDataWarning

    try:
        with warnings.catch_warnings():
            # All 14 parameters are free on purpose (the paper's set-up): the flat-direction
            # warnings each solve would give are the study's subject, stated in its Notes.
            warnings.simplefilter("ignore", HmlvsDataWarning)
            for s in s_vals:
                box = Bounds.around(truth, s)
                common = dict(initial=truth, spread=s, fixed=(), threads=n_threads,
                              progress=reporter.update)
                for method in METHODS:
                    reporter.begin(method, s, step_runs(method))
                    if method == "random":
                        r = calibrate(sim.fit, method="random", bounds=box, evaluations=n_eval,
                                      seed=_seed(seed, s, 0), **common)
                        params = r.params.to_array()[None, :]
                    elif method in ("lm", "lm-paper"):
                        # Same seed -> the same Eq. 22 starts for both LM modes, both unbounded
                        # (paper mode as MINPACK lmdif): they differ only in the residual, the
                        # Jacobian and the rotation's parametrisation.
                        r = calibrate(sim.fit, method=method, runs=n_lm, use_bounds=False,
                                      seed=_seed(seed, s, 1), **common)
                        params = r.run_params
                    else:  # pso, pso+lm: the same seed -> PSO+LM polishes the very PSO runs
                        r = calibrate(sim.fit, method=method, runs=n_pso, bounds=box,
                                      seed=_seed(seed, s, 2), **common)
                        params = r.run_params
                    if r.termination == "cancelled":
                        raise KeyboardInterrupt
                    errs = [errors(q) for q in params]
                    runs[(method, s)] = MethodRuns(
                        method=method, s=s, fit_rms=np.array([_rms(f) for f, _ in errs]),
                        test_rms=np.array([_rms(t) for _, t in errs]), seconds=r.seconds,
                        threshold=SUCCESS_THRESHOLD, params=np.array(params),
                        iterations=(np.asarray(r.lm.run_iterations)
                                    if method in ("lm", "lm-paper") else None),
                        iteration_limit=LM_MAX_ITERATIONS if method in ("lm", "lm-paper") else None)
                    if method == "pso":
                        pr = runs[(method, s)]
                        b, w = int(np.argmin(pr.fit_rms)), int(np.argmax(pr.fit_rms))
                        held_out.append(HeldOut(s=s, method="pso", best_run=b, worst_run=w,
                                                best_errors=errs[b][1], worst_errors=errs[w][1],
                                                best_fit_rms=float(pr.fit_rms[b]),
                                                worst_fit_rms=float(pr.fit_rms[w])))
                    reporter.end()
    finally:
        reporter.close()
    result = StudyResult(settings=settings, runs=runs, held_out=held_out,
                         seconds=time.perf_counter() - wall0,
                         cpu_seconds=time.process_time() - cpu0)
    if out is not None:
        result.write(out)
    return result


# ------------------------------------------------------------------------------------------
# Markdown


def _fmt(v: Optional[float]) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if math.isinf(v):
        return "inf"
    if v == 0:
        return "0"
    if 1e-2 <= abs(v) < 1e4:
        return f"{v:.3g}"
    return f"{v:.2e}"


def _fmt_paper(v: Optional[float]) -> str:
    return "" if v is None else f" ({_fmt(v)})"


def _s_header(st: StudySettings) -> tuple[str, str]:
    head = "| method | RMS (mm) | " + " | ".join(f"s = {s:g}" for s in st.s_values) + " |"
    sep = "|---|---|" + "---:|" * len(st.s_values)
    return head, sep


def _method_label(r: StudyResult, m: str) -> str:
    st = r.settings
    n = {"random": f"1 run, {st.evaluations:,} evaluations", "lm-paper": f"{st.runs_lm} runs",
         "lm": f"{st.runs_lm} runs", "pso": f"{st.runs_pso} runs",
         "pso+lm": f"{st.runs_pso} runs"}[m]
    return f"{LABELS[m]}, {n}"


VALLEY_PARAMS: tuple[tuple[str, str], ...] = (
    ("f", "mm"), ("Sv", "mm/px"), ("Cv", "px"), ("H", "mm"), ("theta", "rad"), ("ty", "mm"),
    ("tz", "mm"), ("omega", "rad"), ("phi", "rad"), ("omega + varphi", "rad"), ("f / Su", "px"))


def _valley_values(params: np.ndarray, name: str) -> np.ndarray:
    from ..models.params import param_index

    if name == "omega + varphi":
        return params[:, param_index("omega")] + params[:, param_index("varphi")]
    if name == "f / Su":
        return params[:, param_index("f")] / params[:, param_index("Su")]
    return params[:, param_index(name)]


def _valley_lines(r: StudyResult) -> list[str]:
    """Parameter ranges over modern LM's successful runs at the largest s."""
    s = max(r.settings.s_values)
    lm = r.get("lm", s)
    ok = lm.test_rms < lm.threshold
    if ok.sum() < 2:
        return []
    from ..models.params import Parameters

    truth = Parameters.nominal().to_array()[None, :]  # the study simulates at the nominal
    lines = ["", f"## Same RMS, different parameters: modern LM at s = {s:g}", "",
             f"The {int(ok.sum())} successful modern-LM runs at s = {s:g} all fit to a held-out "
             f"RMS of at most {_fmt(float(lm.test_rms[ok].max()))} mm, yet their parameters "
             "differ: the data fix only some combinations of the 14 (docs/model.md, \"What the "
             "data can and cannot determine\").", "",
             "| parameter | smallest | largest | true |", "|---|---:|---:|---:|"]
    for name, unit in VALLEY_PARAMS:
        v = _valley_values(lm.params[ok], name)
        t = float(_valley_values(truth, name)[0])
        lines.append(f"| {name} ({unit}) | {v.min():.6g} | {v.max():.6g} | {t:.6g} |")
    return lines


def _markdown(r: StudyResult) -> str:
    st = r.settings
    head, sep = _s_header(st)
    thr = _fmt(st.threshold)
    lines = [
        "# Simulation study: paper Table 1 and Fig. 8",
        "",
        f"Written by `hmlvs study{' --quick' if st.quick else ''}`: {st.describe()}.",
        f"Wall time {r.seconds:.1f} s, CPU time {r.cpu_seconds:.1f} s (all threads).",
        "",
        "## Table 1: fit RMS over the fitting points, ours (paper)",
        "",
        "RMS of ||E_i|| (mm) over the 50 fitting points per run; in parentheses the paper's "
        "Table 1 entry where it has one.",
        "",
        head, sep,
    ]
    for m in METHODS:
        stats = ("best",) if m == "random" else STATS
        for i, stat in enumerate(stats):
            label = _method_label(r, m) if i == 0 else ""
            cells = [_fmt(r.get(m, s).fit.get(stat)) + _fmt_paper(paper_value(m, stat, s))
                     for s in st.s_values]
            lines.append(f"| {label} | {stat} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Held-out RMS over the 50 test points",
        "",
        head, sep,
    ]
    for m in METHODS:
        stats = ("best",) if m == "random" else ("best", "worst", "median", "mean", "std")
        for i, stat in enumerate(stats):
            label = _method_label(r, m) if i == 0 else ""
            cells = [_fmt(r.get(m, s).test.get(stat)) for s in st.s_values]
            lines.append(f"| {label} | {stat} | " + " | ".join(cells) + " |")
    lines += [
        "",
        f"## Success rate (held-out RMS < {thr} mm) and run time",
        "",
        "| method | | " + " | ".join(f"s = {s:g}" for s in st.s_values) + " | total |",
        "|---|---|" + "---:|" * (len(st.s_values) + 1),
    ]
    for m in METHODS:
        rr = [r.get(m, s) for s in st.s_values]
        succ = sum(x.successes for x in rr)
        n = sum(x.runs for x in rr)
        lines.append(f"| {_method_label(r, m)} | successes | "
                     + " | ".join(f"{x.successes}/{x.runs}" for x in rr)
                     + f" | {succ}/{n} |")
        if m in ("lm", "lm-paper"):
            lines.append(f"| | stopped at {st.lm_max_iterations} iterations | "
                         + " | ".join(str(x.capped) for x in rr)
                         + f" | {sum(x.capped or 0 for x in rr)} |")
        lines.append("| | time (s) | " + " | ".join(f"{x.seconds:.2f}" for x in rr)
                     + f" | {r.method_seconds(m):.1f} |")
    lines += [
        "",
        "## Fig. 8: held-out errors of the best and the worst PSO run",
        "",
        "The paper's Fig. 8 evaluates the PSO solutions with the best and the worst fitness on "
        "the 50 held-out points. SSE: sum of squared errors (mm^2).",
        "",
        "| s | best run: fit RMS | held-out RMS | held-out SSE | worst run: fit RMS "
        "| held-out RMS | held-out SSE | max point error (worst run) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for h in r.held_out:
        lines.append(f"| {h.s:g} | {_fmt(h.best_fit_rms)} | {_fmt(h.best_test_rms)} | "
                     f"{_fmt(h.best_sse)} | {_fmt(h.worst_fit_rms)} | "
                     f"{_fmt(h.worst_test_rms)} | {_fmt(h.worst_sse)} | "
                     f"{_fmt(float(np.max(h.worst_errors)))} |")
    lines += _valley_lines(r)
    lines += [
        "",
        "## Notes",
        "",
        "- Data: noise-free, so the true parameters give RMS 0; no run can do better than 0 "
        "and the differences between methods are optimisation errors only.",
        "- Starts and boxes: Eq. 22, q_i = q_i0 (1 + (rand - 0.5) s); parameters whose nominal "
        "is 0 (k, omega, phi, varphi, ty) are drawn in their Table 2 range scaled by s. RS, "
        "PSO and PSO+LM search this box (PSO+LM's LM is bounded by it). Both LM modes start "
        "from the same candidates and are unbounded, as MINPACK lmdif was: they differ only "
        "in the residual (||E_i|| vs its 3 components), the Jacobian (forward differences vs "
        "exact) and the rotation (Euler angles vs SO(3)). NLSO here is Ceres' LM with the "
        "paper's ingredients and MINPACK's tolerances, not MINPACK itself "
        "(`docs/study/minpack_check.py` runs MINPACK on the same starts).",
        "- All 14 parameters are free for every method, as in the paper. The exact scale gauge "
        "(f, Su, Sv, k) of docs/model.md makes the parameter vector non-unique, but not the RMS: "
        "modern LM's damping handles the null directions.",
        f"- Success: held-out RMS < {thr} mm (13x below the sensor's best resolution, "
        "0.134 mm/px, and 35x below the paper's experimental 0.355 mm).",
        "- Statistics: std is the sample standard deviation (ddof = 1). The paper labels "
        "some Table 1 rows E(q) and others F(q); all are read as RMS (mm) here. Its PSO std at "
        "s = 0.2 (1.13e-3) is inconsistent with its best, worst and mean (it must be at least "
        "~3.8e-3).",
        "- Times: wall clock on a machine that may be shared; the solvers are deterministic "
        "for a seed whatever the thread count.",
        "",
    ]
    if st.quick:
        lines[4:4] = ["", "**Quick run**: fewer runs than the paper; the full study is "
                      "`hmlvs study` (1000 LM runs, 10 PSO runs, 1,000,000 RS evaluations)."]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------
# Plots

PLOT_DPI = 90
COLORS = {"random": "C7", "lm-paper": "C3", "pso": "C0", "lm": "C2", "pso+lm": "C1"}


def _save(fig: Any, path: Path) -> Path:
    """Render a figure to PNG in memory (Agg), reduce it to a 128-colour palette (a third of
    the size, for committing the plots), then write it atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=PLOT_DPI)
    buf.seek(0)
    # method 0: median cut, dither 0: none (integers: the enum names vary across Pillow)
    img = Image.open(buf).convert("RGB").quantize(colors=128, method=0, dither=0)
    small = io.BytesIO()
    img.save(small, format="png", optimize=True)
    with atomic_write(path, "wb") as fh:
        fh.write(small.getvalue())
    return path


def _floor(values: np.ndarray, floor: float) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    return np.where(np.isfinite(v), np.maximum(v, floor), np.nan)


def _plot_table1(r: StudyResult, path: Path) -> Path:
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    st = r.settings
    fig = Figure(figsize=(12, 8.2), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    width = 0.8 / len(METHODS)
    rng = np.random.default_rng(0)  # horizontal jitter only
    floor = 1e-14
    for ax, kind in zip(axes, ("fit", "test")):
        for j, m in enumerate(METHODS):
            for i, s in enumerate(st.s_values):
                mr = r.get(m, s)
                vals = _floor(mr.fit_rms if kind == "fit" else mr.test_rms, floor)
                x = i + (j - (len(METHODS) - 1) / 2) * width
                jit = rng.uniform(-0.35, 0.35, vals.size) * width if vals.size > 1 else 0.0
                ax.plot(x + jit, vals, ".", ms=2.5 if vals.size > 50 else 5, alpha=0.35
                        if vals.size > 50 else 0.8, color=COLORS[m], rasterized=True)
                ax.plot([x - width / 2.2, x + width / 2.2], [np.nanmedian(vals)] * 2, "-",
                        color="k", lw=1.2)
                if kind == "fit":
                    for stat, marker in (("best", "v"), ("worst", "^")):
                        pv = paper_value(m, stat, s)
                        if pv is not None:
                            ax.plot(x, pv, marker, mfc="none", mec=COLORS[m], ms=8, mew=1.5)
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="major")
        ax.set_ylabel(("fit" if kind == "fit" else "held-out") + " RMS of ||E_i|| (mm)")
    axes[1].axhline(st.threshold, color="k", ls="--", lw=0.8)
    axes[1].text(-0.45, st.threshold * 1.5, f"success threshold {st.threshold:g} mm",
                 ha="left", va="bottom", fontsize=8)
    axes[1].set_xticks(range(len(st.s_values)), [f"s = {s:g}" for s in st.s_values])
    axes[1].set_xlim(-0.5, len(st.s_values) - 0.5)
    handles = [Line2D([], [], ls="none", marker="o", color=COLORS[m], label=_method_label(r, m))
               for m in METHODS]
    handles += [Line2D([], [], color="k", label="median"),
                Line2D([], [], ls="none", marker="v", mfc="none", mec="0.3",
                       label="paper Table 1: best"),
                Line2D([], [], ls="none", marker="^", mfc="none", mec="0.3",
                       label="paper Table 1: worst")]
    fig.legend(handles=handles, fontsize=8, ncol=4, loc="outside lower center")
    axes[0].set_title(f"Table 1: RMS of every run (dots; values below {floor:g} mm drawn at "
                      f"{floor:g}), fitting points (top) and held-out points (bottom)")
    fig.suptitle(f"Simulation study, {'quick' if st.quick else 'full'} run (seed {st.seed}): "
                 "all 14 parameters free, noise-free data")
    return _save(fig, path)


def _plot_fig8(r: StudyResult, path: Path) -> Path:
    from matplotlib.figure import Figure

    n = len(r.held_out)
    panels = n + 1  # one per s, then the held-out RMS against s
    cols = min(panels, 3)
    rows = math.ceil(panels / cols)
    fig = Figure(figsize=(4.4 * cols, 3.4 * rows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, h in zip(axes, r.held_out):
        idx = np.arange(1, h.best_errors.size + 1)
        ax.plot(idx, _floor(h.best_errors, 1e-14), "o-", ms=3, lw=0.8, color="C0",
                label=f"best PSO run: held-out RMS {_fmt(h.best_test_rms)}")
        ax.plot(idx, _floor(h.worst_errors, 1e-14), "s-", ms=3, lw=0.8, color="C3",
                label=f"worst PSO run: held-out RMS {_fmt(h.worst_test_rms)}")
        ax.set_yscale("log")
        ax.set_title(f"s = {h.s:g}")
        ax.set_xlabel("held-out point")
        ax.set_ylabel("||E_i|| (mm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax = axes[n]
    s_vals = np.array([h.s for h in r.held_out])
    ax.plot(s_vals, [h.best_test_rms for h in r.held_out], "o-", color="C0",
            label="best PSO run, held-out")
    ax.plot(s_vals, [h.best_fit_rms for h in r.held_out], "o--", color="C0", mfc="none",
            label="best PSO run, fit")
    ax.plot(s_vals, [h.worst_test_rms for h in r.held_out], "s-", color="C3",
            label="worst PSO run, held-out")
    ax.plot(s_vals, [h.worst_fit_rms for h in r.held_out], "s--", color="C3", mfc="none",
            label="worst PSO run, fit")
    ax.plot(s_vals, [_floor(np.array([r.get("pso+lm", s).test.worst]), 1e-14)[0]
                     for s in s_vals], "^-", color="C1", label="worst PSO+LM run, held-out")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("spread s")
    ax.set_ylabel("RMS of ||E_i|| (mm)")
    ax.set_title("RMS against s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    for extra in axes[panels:]:
        extra.set_visible(False)
    fig.suptitle("Fig. 8: error at each of the 50 held-out points for the PSO solutions with "
                 "the best and the worst fitness")
    return _save(fig, path)
