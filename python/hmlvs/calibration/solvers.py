"""Parameter identification: PSO, Levenberg-Marquardt (Ceres), random search, and PSO + LM."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
import math
import os
import time
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence
import warnings

import numpy as np

from .. import _core
from ..data.dataset import Dataset, fit_and_test
from ..diagnostics.identifiability import warning_category
from ..diagnostics.uncertainty import check_noise, diagnose
from ..models.params import DEFAULT_FIXED, NAMES, NUM_PARAMS, Bounds, Parameters, param_index
from ..models.params import fixed_mask as params_fixed_mask
from .options import (
    LmOptions,
    PsoOptions,
    RandomSearchOptions,
    check_runs,
    check_seed,
    check_threads,
    lm_struct,
    option_names,
    pso_struct,
    random_search_struct,
)
from .result import LmStage, PsoStage, RandomSearchStage, Termination

if TYPE_CHECKING:
    from ..diagnostics.identifiability import IdentifiabilityReport
    from ..diagnostics.uncertainty import Uncertainty

METHODS = ("pso+lm", "pso", "lm", "lm-paper", "random")
LOSSES = (None, "huber", "cauchy")
_OTHER_OPTIONS = {"spread": None, "test": None, "pixel_noise": None, "point_noise": None,
                  "analyze": True}
_GAUGE_NOTE = ("Su held fixed at {value:g} mm/px: f, Su, Sv and k form an exact scale gauge "
               "(only f/Su, f/Sv and k Su^2 are determined by laser points), so one of them "
               "must be given, e.g. from the camera's datasheet")

ProgressFn = Callable[[int, int, float], Any]


@dataclass
class CalibrationResult:
    """The outcome of :func:`calibrate`.

    Attributes
    ----------
    params : the identified parameters
    method : the method used
    fixed : names of the parameters held at their given values
    fit_rms, test_rms : RMS of ||E_i|| (mm) on the fitting points and on held-out points
        (None without a test set)
    fit_errors, test_errors : per-point ||E_i|| (mm)
    cost : F(q) = 1/2 sum ||E_i||^2 on the fitting points (mm^2)
    history : best fitness F after each PSO iteration of the best run (empty for LM/RS)
    run_fitness : each PSO run's best fitness (several runs), or each LM start's final cost
    run_params : (runs, 14) each run's final parameters, in the order of ``run_fitness``
        (NaN rows for LM starts that failed)
    iterations : PSO iterations of the best run, plus LM iterations after it (random search:
        candidates evaluated)
    termination : why the solve stopped (:class:`Termination`; the last stage's reason)
    termination_message : the same as a sentence, e.g. "converged: Function tolerance
        reached ... after 37 LM iterations (PSO: 5000 generations, max_iterations)"
    seconds : wall-clock time of the solve
    notes : what the solver assumed (e.g. the gauge held fixed)
    warnings : problems found with the data or the solution
    identifiability : what the data determine at the solution (Jacobian SVD, named flat
        directions; :func:`hmlvs.identifiability`)
    uncertainty : covariance, standard deviations, correlations and identifiable
        combinations of the free parameters (:func:`hmlvs.uncertainty`)
    pso, lm, random : what each stage did (:class:`PsoStage`, :class:`LmStage`,
        :class:`RandomSearchStage`), None for stages that did not run
    extra : deprecated, read-only: the old untyped dict, built from the stages
    """

    params: Parameters
    method: str
    fixed: tuple[str, ...]
    fit_rms: float
    test_rms: float | None
    fit_errors: np.ndarray
    test_errors: np.ndarray | None
    cost: float
    history: np.ndarray
    run_fitness: np.ndarray
    iterations: int
    termination: Termination
    seconds: float
    seed: int
    threads: int
    bounds: Bounds
    termination_message: str = ""
    run_params: np.ndarray = field(default_factory=lambda: np.empty((0, NUM_PARAMS)))
    pso: PsoStage | None = None
    lm: LmStage | None = None
    random: RandomSearchStage | None = None
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    identifiability: IdentifiabilityReport | None = None
    uncertainty: Uncertainty | None = None

    def parameter_std(self) -> dict[str, float | None]:
        """Standard deviation of each parameter from the uncertainty analysis; None for fixed
        parameters and for those the data do not determine (their std is meaningless)."""
        u = self.uncertainty
        if u is None:
            return {}
        return {n: (float(u.std[n]) if n in u.std and u.determined.get(n, False) else None)
                for n in NAMES}

    @property
    def extra(self) -> dict[str, Any]:
        """Deprecated: the per-run details as the old untyped dict; use :attr:`run_params`,
        :attr:`pso` and :attr:`lm`."""
        d: dict[str, Any] = {}
        if self.pso is not None:
            d["pso_seconds"] = self.pso.seconds
            d["pso_histories"] = self.pso.histories
        if self.lm is not None and self.pso is None:
            d.update(lm_message=self.lm.message, lm_errors=self.lm.errors,
                     starts=self.lm.starts, run_iterations=self.lm.run_iterations,
                     run_termination=self.lm.run_termination)
        if self.pso is not None or self.lm is not None:
            d["run_params"] = self.run_params
        return d

    @property
    def free(self) -> tuple[str, ...]:
        return tuple(n for n in NAMES if n not in self.fixed)

    def summary(self, truth: Parameters | None = None) -> str:
        lines = [f"method {self.method}: {self.termination_message}",
                 f"{self.iterations} iterations in {self.seconds:.3f} s ({self.threads} "
                 f"threads, seed {self.seed})",
                 f"fit RMS {self.fit_rms:.4g} mm over {self.fit_errors.size} points"]
        if self.test_rms is not None:
            lines.append(f"held-out RMS {self.test_rms:.4g} mm over {self.test_errors.size} "
                         "points")
        if self.run_fitness.size > 1:
            lines.append(f"{self.run_fitness.size} runs, best fitness per run: "
                         + ", ".join(f"{f:.3g}" for f in self.run_fitness))
        lines.append(self.params.table(truth) if truth is not None else self.params.table())
        lines += [f"note: {n}" for n in self.notes]
        lines += [f"warning: {w}" for w in self.warnings]
        if self.uncertainty is not None:
            lines.append(self.uncertainty.summary())
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _rms(errors: np.ndarray) -> float:
    """RMS over the points that have an error (a ray that misses the laser plane has none);
    NaN when none has: callers report that as not available, with the reason."""
    e = errors[np.isfinite(errors)]
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def _test_rms(test_errors: np.ndarray | None, notes: list[str]) -> float | None:
    """The held-out RMS, or None with a note saying why it is not available; a note also
    counts held-out points left out because their rays miss the laser plane."""
    if test_errors is None:
        return None
    if test_errors.size == 0:
        notes.append("held-out RMS not available: the held-out set is empty")
        return None
    missing = int((~np.isfinite(test_errors)).sum())
    if missing == test_errors.size:
        notes.append("held-out RMS not available: every held-out point's ray misses the laser "
                     "plane at these parameters")
        return None
    if missing:
        notes.append(f"{missing} of {test_errors.size} held-out points have rays that miss the "
                     "laser plane at these parameters; the held-out RMS is over the others")
    return _rms(test_errors)


def _fitness_data(ds: Dataset) -> Any:
    return _core._FitnessData(ds.pixels, ds.poses.reshape(-1, 16), ds.points)


def _resolve_progress(progress: Any) -> tuple[ProgressFn | None, Callable[[], None]]:
    """A callable (done, total, best) -> bool|None, and a closer; ``True`` gives a rich bar."""
    if progress is None or progress is False:
        return None, lambda: None
    if progress is True:
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        bar = Progress(TextColumn("{task.description}"), BarColumn(),
                       TextColumn("{task.completed}/{task.total}"),
                       TextColumn("best F {task.fields[best]}"),
                       TimeRemainingColumn(), transient=True)
        bar.start()
        task = bar.add_task("calibrating", total=None, best="-")

        def update(done: int, total: int, best: float) -> bool:
            bar.update(task, completed=done, total=total, best=f"{best:.3g}")
            return True

        return update, bar.stop
    if callable(progress):
        return progress, lambda: None
    if hasattr(progress, "update"):  # a tqdm-like bar: advance it to `done`
        state = {"last": 0}

        def advance(done: int, total: int, best: float) -> bool:
            if getattr(progress, "total", None) in (None, 0):
                progress.total = total
            progress.update(done - state["last"])
            state["last"] = done
            return True

        return advance, lambda: None
    raise ValueError("progress must be None, True, a callable (done, total, best) or a "
                     "tqdm-like bar with update()")


def _split_options(options: dict[str, Any], pso: PsoOptions | None, lm: LmOptions | None,
                   random: RandomSearchOptions | None,
                   ) -> tuple[PsoOptions, LmOptions, RandomSearchOptions, dict]:
    """Flat keyword options -> the validated option objects (keywords override the fields of
    a given object) and the remaining non-solver options."""
    groups = ((PsoOptions, pso, "pso"), (LmOptions, lm, "lm"),
              (RandomSearchOptions, random, "random"))
    valid = [n for cls, _, _ in groups for n in option_names(cls)] + list(_OTHER_OPTIONS)
    unknown = [k for k in options if k not in valid]
    if unknown:
        raise ValueError(f"unknown option {unknown[0]!r}; valid: {', '.join(sorted(valid))}")
    built = []
    for cls, given, arg in groups:
        if given is None:
            given = cls()
        elif not isinstance(given, cls):
            raise ValueError(f"{arg} must be a {cls.__name__}, got {given!r}")
        mine = {k: v for k, v in options.items() if k in option_names(cls)}
        built.append(dataclasses.replace(given, **mine) if mine else given)
    other = {k: options.get(k, v) for k, v in _OTHER_OPTIONS.items()}
    return built[0], built[1], built[2], other


def _as_vector(params: Any, name: str) -> np.ndarray:
    if isinstance(params, Parameters):
        return params.to_array()
    if isinstance(params, dict):
        return Parameters.from_dict(params).to_array()
    arr = np.asarray(params, dtype=float).reshape(-1)
    if arr.shape != (NUM_PARAMS,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be {NUM_PARAMS} finite values")
    return arr


def _lm_stage(lms: Any, errs: Sequence[str], starts: np.ndarray, costs: np.ndarray, k: int,
              improved: bool) -> LmStage:
    best = lms[k]
    return LmStage(
        termination=Termination.from_ceres(str(best.termination)),
        ceres_termination=str(best.termination), message=str(best.message),
        iterations=int(best.iterations), initial_cost=float(best.initial_cost),
        final_cost=float(best.final_cost), seconds=float(best.seconds), best_start=k,
        starts=np.asarray(starts), run_costs=costs,
        run_params=np.array([r.params if not e else np.full(NUM_PARAMS, np.nan)
                             for r, e in zip(lms, errs)]),
        run_iterations=np.array([r.iterations if not e else 0 for r, e in zip(lms, errs)]),
        run_termination=[r.termination if not e else ("cancelled" if e == "cancelled"
                                                        else "error")
                         for r, e in zip(lms, errs)],
        errors=[e for e in errs if e], improved=improved)


_REASONS = {
    Termination.CONVERGED: "", Termination.MAX_ITERATIONS: "iteration limit reached",
    Termination.TARGET_FITNESS: "target fitness reached",
    Termination.MAX_EVALUATIONS: "all candidates evaluated",
    Termination.CANCELLED: "stopped by the progress callback", Termination.FAILED: "",
    Termination.NOT_SOLVED: ""}


def _termination_message(termination: Termination, pso: PsoStage | None, lm: LmStage | None,
                         rs: RandomSearchStage | None) -> str:
    """A sentence: why the solve stopped, after how many iterations of which stage."""
    reason = _REASONS[termination]
    head = f"{termination.value} ({reason})" if reason else termination.value
    pso_part = (f"PSO: {pso.iterations} generations, best fitness {pso.best_fitness:.6g}, "
                f"{pso.termination.value}") if pso is not None else ""
    if lm is not None and lm.improved:
        msg = f"{head}: {lm.message.strip().rstrip('.')}, after {lm.iterations} LM iterations"
        if termination == Termination.CANCELLED:
            msg += " (some starts were cancelled)"
        return msg + (f" ({pso_part})" if pso_part else "")
    if pso is not None:
        msg = f"{head}: {pso_part}"
        if lm is not None:
            msg += (f"; LM polishing ({lm.ceres_termination}, {lm.iterations} iterations) did "
                    "not improve the swarm's best")
        return msg
    if rs is not None:
        return f"{head}: random search, {rs.evaluations} candidates evaluated"
    return head


def evaluate(params: Any, dataset: Dataset, test: Dataset | None = None,
             method: str = "evaluated", fixed: Iterable[str] = ()) -> CalibrationResult:
    """A :class:`CalibrationResult` for given parameters (no solve): RMS and per-point errors
    on ``dataset`` (and ``test``), e.g. to report on a calibration file."""
    q = _as_vector(params, "params")
    fit_errors = np.array(_fitness_data(dataset).point_errors(q))
    test_errors = None if test is None else np.array(_fitness_data(test).point_errors(q))
    notes: list[str] = []
    test_rms = _test_rms(test_errors, notes)
    return CalibrationResult(
        params=Parameters.from_array(q), method=method, fixed=tuple(fixed), notes=notes,
        fit_rms=_rms(fit_errors), test_rms=test_rms,
        fit_errors=fit_errors, test_errors=test_errors,
        cost=float(0.5 * np.nansum(fit_errors**2)), history=np.empty(0),
        run_fitness=np.empty(0), iterations=0, termination=Termination.NOT_SOLVED,
        termination_message="not solved: parameters evaluated as given",
        seconds=0.0, seed=0, threads=0, bounds=Bounds.table2())


def initial_candidates(center: Any, s: float, n: int, seed: int = 0,
                       bounds: Bounds | None = None) -> np.ndarray:
    """n initial candidates by the paper's Eq. 22: q_i = q_i0 (1 + (rand - 0.5) s).

    Parameters whose ``center`` is 0 are drawn in the Table 2 range scaled by ``s`` instead
    (:meth:`Bounds.around`). Candidates are clipped to ``bounds`` when given.
    """
    box = Bounds.around(_as_vector(center, "center"), s)
    rng = np.random.default_rng(seed)
    q = rng.uniform(box.lower, box.upper, size=(n, NUM_PARAMS))
    if bounds is not None:
        q = np.clip(q, bounds.lower, bounds.upper)
    return q


def calibrate(dataset: Dataset | Any, method: str = "pso+lm", bounds: Bounds | None = None,
              initial: Parameters | Sequence[float] | None = None,
              fixed: Iterable[str] = DEFAULT_FIXED, runs: int = 1, seed: int = 0,
              threads: int | None = None, loss: str | None = None, progress: Any = None,
              pso: PsoOptions | None = None, lm: LmOptions | None = None,
              random: RandomSearchOptions | None = None,
              **options: Any) -> CalibrationResult:
    """Identify the paper model's 14 sensor parameters from calibration points
    (:func:`hmlvs.calibrate` is the entry point of both models).

    Parameters
    ----------
    dataset : the fitting points (:class:`Dataset`), or a simulation with ``fit``/``test``
    method : "pso+lm" (default: the swarm's best polished by modern LM), "pso" (paper
        Eq. 19-21), "lm" (modern Levenberg-Marquardt: 3 residual components, exact Jacobian,
        rotation on SO(3), bounds), "lm-paper" (the paper's NLSO: scalar residual ||E_i||,
        forward differences, Euler angles, no bounds) or "random" (random search, Eq. 22)
    bounds : search bounds (default Table 2)
    initial : LM start; for PSO/random with ``spread=s`` the centre of the paper's Eq. 22
        initial box; also the values of the fixed parameters (default: nominal)
    fixed : parameter names held at their initial values. By default Su (the scale gauge),
        Sv, Cu and Cv, as on the command line (:data:`hmlvs.models.params.DEFAULT_FIXED`)
    runs : independent PSO runs (the best is kept) or, for "lm"/"lm-paper" with ``spread``,
        starts drawn by Eq. 22
    seed : random seed; results are identical for a seed whatever ``threads``
    threads : worker threads (default: all cores)
    loss : robust loss for LM, None, "huber" or "cauchy", with ``loss_scale`` in mm
    progress : None, True (a progress bar), a callable ``(done, total, best_fitness)`` that may
        return False to stop, or a tqdm-like bar. Counts PSO iterations (summed over runs),
        random-search evaluations or LM starts solved
    pso, lm, random : option objects (:class:`PsoOptions`, :class:`LmOptions`,
        :class:`RandomSearchOptions`); the keyword options below override their fields
    **options : swarm_size, iterations, w_max, w_min, c1, c2, vmax, target_fitness,
        progress_every (PSO); max_iterations, loss_scale, use_bounds (LM); evaluations
        (random search); spread (Eq. 22 spread s); test (a held-out :class:`Dataset`);
        pixel_noise (px), point_noise (mm): noise levels for the uncertainty (default:
        estimated from the residuals); analyze (default True): compute identifiability and
        uncertainty at the solution (False: the solve alone, e.g. for timing)

    Returns
    -------
    CalibrationResult
    """
    start = time.perf_counter()
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if loss not in LOSSES:
        raise ValueError(f"loss must be None, 'huber' or 'cauchy', got {loss!r}")
    pso_o, lm_o, rs_o, other = _split_options(options, pso, lm, random)
    test = other["test"]
    check_noise(other["pixel_noise"], other["point_noise"])  # issue 4: fail before the solve
    dataset, test = fit_and_test(dataset, test)
    bounds = Bounds.table2() if bounds is None else bounds
    if not isinstance(bounds, Bounds):
        bounds = Bounds(*bounds)
    fixed, fixed_mask = params_fixed_mask(fixed)
    n_free = int((~fixed_mask).sum())
    if n_free == 0:
        raise ValueError("every parameter is fixed: nothing to estimate")
    if len(dataset) < n_free:
        raise ValueError(f"too few points: {len(dataset)} calibration points for {n_free} free "
                         f"parameters (need at least {n_free}; many more are better)")
    runs = check_runs(runs)
    seed = check_seed(seed)
    cores = min(os.cpu_count() or 1, 1024)
    threads_n = cores if threads is None else check_threads(threads)
    capped = threads_n > cores
    threads_n = min(threads_n, cores)  # more threads than cores only slow the solve down
    if initial is None:
        q0 = Parameters.nominal().to_array()
        if not bounds.contains(q0):
            q0 = np.where(fixed_mask, q0, (bounds.lower + bounds.upper) / 2)
    else:
        q0 = _as_vector(initial, "initial")
    outside = [(NAMES[i], q0[i]) for i in range(NUM_PARAMS)
               if not bounds.lower[i] <= q0[i] <= bounds.upper[i]]
    if outside and (initial is not None or fixed_mask[[param_index(n) for n, _ in outside]].any()):
        n, v = outside[0]
        i = param_index(n)
        raise ValueError(f"initial {n} = {v:g} lies outside its bounds "
                         f"[{bounds.lower[i]:g}, {bounds.upper[i]:g}]")
    # Fixed parameters: the search box collapses onto their values.
    search = Bounds(np.where(fixed_mask, q0, bounds.lower), np.where(fixed_mask, q0, bounds.upper))
    spread = other["spread"]
    init_box = None
    if spread is not None:
        box = Bounds.around(q0, float(spread))
        init_box = Bounds(np.where(fixed_mask, q0, box.lower), np.where(fixed_mask, q0, box.upper))

    data = _fitness_data(dataset)
    notes: list[str] = []
    if "Su" in fixed:
        notes.append(_GAUGE_NOTE.format(value=q0[param_index("Su")]))
    if capped:
        notes.append(f"threads capped at {cores}, the machine's cores (asked: {threads}); the "
                     "result is the same for any thread count")
    others = [n for n in fixed if n != "Su"]
    if others:
        notes.append("held fixed at their initial values: " + ", ".join(others))
    cb, close = _resolve_progress(progress)
    history = np.empty(0)
    run_fitness = np.empty(0)
    run_params = np.empty((0, NUM_PARAMS))
    pso_stage = lm_stage = rs_stage = None
    try:
        if method in ("pso", "pso+lm"):
            o = pso_struct(pso_o, runs=runs, threads=threads_n, seed=seed, lower=search.lower,
                           upper=search.upper,
                           init_lower=None if init_box is None else init_box.lower,
                           init_upper=None if init_box is None else init_box.upper)
            res = _core._run_pso(data, o, cb)
            best = res.runs[res.best_run]
            q = np.array(best.best)
            history = np.array(best.history)
            run_fitness = np.array([r.best_fitness for r in res.runs])
            run_params = np.array([r.best for r in res.runs])
            pso_stage = PsoStage(
                termination=(Termination.CANCELLED if res.cancelled
                             else Termination.from_pso(str(best.termination))),
                iterations=int(best.iterations), best_fitness=float(best.best_fitness),
                best_run=int(res.best_run), run_fitness=run_fitness.copy(),
                run_params=run_params.copy(),
                histories=[np.array(r.history) for r in res.runs], seconds=float(res.seconds))
            iterations, termination = pso_stage.iterations, pso_stage.termination
            if method == "pso+lm" and not res.cancelled:
                lo = lm_struct(lm_o, mode="modern", fixed=fixed_mask, lower=search.lower,
                               upper=search.upper, loss=loss)
                starts = np.array([r.best for r in res.runs])
                lms, errs = _core._run_lm_many(data, starts, lo, threads_n)
                costs = np.array([r.final_cost if not e else np.inf for r, e in zip(lms, errs)])
                k = int(np.argmin(costs))
                improved = bool(np.isfinite(costs[k]) and costs[k] <= best.best_fitness)
                lm_stage = _lm_stage(lms, errs, starts, costs, k, improved)
                if improved:
                    q = np.array(lms[k].params)
                    iterations += lm_stage.iterations
                    termination = lm_stage.termination
                    # each run keeps the better of its swarm's best and the polished one
                    better = costs <= run_fitness
                    run_params = np.where(better[:, None],
                                          np.array([r.params for r in lms]), run_params)
                    run_fitness = np.where(better, costs, run_fitness)
                else:
                    notes.append("LM polishing did not improve the swarm's best")
        elif method in ("lm", "lm-paper"):
            mode = "modern" if method == "lm" else "paper"
            lo = lm_struct(lm_o, mode=mode, fixed=fixed_mask, lower=search.lower,
                           upper=search.upper, loss=loss)
            if runs > 1 or spread is not None:
                if spread is None:
                    raise ValueError("several LM runs need spread=s to draw starts by Eq. 22")
                starts = np.random.default_rng(seed).uniform(init_box.lower, init_box.upper,
                                                             size=(runs, NUM_PARAMS))
                if mode == "modern" and lm_o.use_bounds:  # inside the bounds LM keeps
                    starts = np.clip(starts, search.lower, search.upper)
            else:
                starts = q0[None, :]
            starts = np.ascontiguousarray(starts)
            lms, errs = _core._run_lm_many(data, starts, lo, threads_n, cb)
            costs = np.array([r.final_cost if not e else np.inf for r, e in zip(lms, errs)])
            cancelled = any(e == "cancelled" for e in errs)
            if not np.isfinite(costs).any():
                if cancelled:
                    raise ValueError("LM was cancelled before any start was solved")
                raise ValueError(f"LM could not start: {next(e for e in errs if e)}")
            k = int(np.argmin(costs))
            q = np.array(lms[k].params)
            lm_stage = _lm_stage(lms, errs, starts, costs, k, True)
            iterations, termination = lm_stage.iterations, lm_stage.termination
            if cancelled:
                termination = Termination.CANCELLED
            run_fitness = costs
            run_params = lm_stage.run_params
        else:  # random search
            box = init_box if init_box is not None else search
            o = random_search_struct(rs_o, threads=threads_n, seed=seed, lower=box.lower,
                                     upper=box.upper)
            res = _core._run_random_search(data, o, cb)
            q = np.array(res.best)
            iterations = int(res.evaluations)
            termination = Termination.CANCELLED if res.cancelled else Termination.MAX_EVALUATIONS
            rs_stage = RandomSearchStage(termination=termination, evaluations=iterations,
                                         best_fitness=float(res.best_fitness),
                                         seconds=float(res.seconds))
    finally:
        close()

    if not np.all(np.isfinite(q)) or not math.isfinite(data.evaluate(q)):
        raise ValueError(f"{method} found no parameter vector for which every pixel's ray meets "
                         "the laser plane; widen or check the bounds")
    fit_errors = np.array(data.point_errors(q))
    test_errors = None
    if test is not None:
        test_errors = np.array(_fitness_data(test).point_errors(q))
    test_rms = _test_rms(test_errors, notes)
    result = CalibrationResult(
        params=Parameters.from_array(q), method=method, fixed=fixed,
        fit_rms=_rms(fit_errors), test_rms=test_rms,
        fit_errors=fit_errors, test_errors=test_errors, cost=float(data.evaluate(q)),
        history=history, run_fitness=run_fitness, iterations=iterations,
        termination=termination, seconds=time.perf_counter() - start, seed=int(seed),
        threads=threads_n, bounds=bounds, notes=notes, run_params=run_params,
        termination_message=_termination_message(termination, pso_stage, lm_stage, rs_stage),
        pso=pso_stage, lm=lm_stage, random=rs_stage)
    # --- identifiability and uncertainty at the solution (issue 4) ---------------------------
    if not other["analyze"]:
        return result
    try:
        result.identifiability, result.uncertainty, data_warnings = diagnose(
            dataset, q, fixed, bounds, other["pixel_noise"], other["point_noise"], loss)
    except (ValueError, np.linalg.LinAlgError) as e:  # report, do not fail the calibration
        data_warnings = [f"identifiability and uncertainty not computed: {e}"]
    for w in data_warnings:
        warnings.warn(w, warning_category(w), stacklevel=2)  # the kind's subclass
    result.warnings.extend(data_warnings)
    # --- end of issue 4 ------------------------------------------------------------------------
    return result
