"""Running the study (:func:`study`): every method at every spread s, on all cores."""

from __future__ import annotations

import math
import os
import time
from typing import Any, Iterable, Optional, Sequence
import warnings
import zlib

import numpy as np

from ...calibration.solvers import calibrate, fitness_data
from ...models.params import Bounds
from .report import StudyResult
from .results import (
    FULL,
    LABELS,
    LM_MAX_ITERATIONS,
    METHODS,
    PAPER_S,
    QUICK,
    SUCCESS_THRESHOLD,
    HeldOut,
    MethodRuns,
    StudyProgress,
    StudySettings,
    output_folder,
    rms,
)


def run_seed(seed: int, s: float, tag: int) -> int:
    """A seed per (study seed, s, stream): the same s gives the same runs whatever the other
    s values of the study."""
    ss = np.random.SeedSequence([seed, zlib.crc32(repr(float(s)).encode()), tag])
    return int(ss.generate_state(1)[0])


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
    >>> r = hmlvs.paper.study.study(quick=True, progress=False)
    >>> r.get("pso+lm", 0.2).success_rate
    1.0
    """
    from ...sim.sessions import simulate

    defaults = QUICK if quick else FULL
    s_vals = _check_s(s_values)
    n_lm = _count("runs_lm", defaults["runs_lm"] if runs_lm is None else runs_lm)
    n_pso = _count("runs_pso", defaults["runs_pso"] if runs_pso is None else runs_pso)
    n_eval = _count("evaluations", defaults["evaluations"] if evaluations is None
                    else evaluations)
    seed = _count("seed", seed, minimum=0)
    n_threads = _count("threads", (os.cpu_count() or 1) if threads is None else threads)
    out = None if out_dir is None else output_folder(out_dir)
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
    from ...diagnostics.identifiability import HmlvsDataWarning

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
                                      seed=run_seed(seed, s, 0), **common)
                        params = r.params.to_array()[None, :]
                    elif method in ("lm", "lm-paper"):
                        # Same seed -> the same Eq. 22 starts for both LM modes, both unbounded
                        # (paper mode as MINPACK lmdif): they differ only in the residual, the
                        # Jacobian and the rotation's parametrisation.
                        r = calibrate(sim.fit, method=method, runs=n_lm, use_bounds=False,
                                      seed=run_seed(seed, s, 1), **common)
                        params = r.run_params
                    else:  # pso, pso+lm: the same seed -> PSO+LM polishes the very PSO runs
                        r = calibrate(sim.fit, method=method, runs=n_pso, bounds=box,
                                      seed=run_seed(seed, s, 2), **common)
                        params = r.run_params
                    if r.termination == "cancelled":
                        raise KeyboardInterrupt
                    errs = [errors(q) for q in params]
                    runs[(method, s)] = MethodRuns(
                        method=method, s=s, fit_rms=np.array([rms(f) for f, _ in errs]),
                        test_rms=np.array([rms(t) for _, t in errs]), seconds=r.seconds,
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
