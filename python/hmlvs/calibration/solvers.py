"""Parameter identification: PSO, Levenberg-Marquardt (Ceres), random search, and PSO + LM."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
import math
import os
import time
from typing import Any, Callable, Iterable, Sequence
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
from .result import CalibrationResult, LmStage, PsoStage, RandomSearchStage, Termination

METHODS = ("pso+lm", "pso", "lm", "lm-paper", "random")
LOSSES = (None, "huber", "cauchy")
_OTHER_OPTIONS = {"spread": None, "test": None, "pixel_noise": None, "point_noise": None,
                  "analyze": True}
_GAUGE_NOTE = ("Su held fixed at {value:g} mm/px: f, Su, Sv and k form an exact scale gauge "
               "(only f/Su, f/Sv and k Su^2 are determined by laser points), so one of them "
               "must be given, e.g. from the camera's datasheet")

ProgressFn = Callable[[int, int, float], Any]


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


def fitness_data(ds: Dataset) -> Any:
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
    fit_errors = np.array(fitness_data(dataset).point_errors(q))
    test_errors = None if test is None else np.array(fitness_data(test).point_errors(q))
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
    check_noise(other["pixel_noise"], other["point_noise"])  # issue 4: fail before the solve
    pr = _problem(dataset, other["test"], bounds, initial, fixed, runs, seed, threads,
                  other["spread"])
    cb, close = _resolve_progress(progress)
    try:
        if method in ("pso", "pso+lm"):
            out = _solve_pso(pr, pso_o, lm_o if method == "pso+lm" else None, loss, cb)
        elif method in ("lm", "lm-paper"):
            out = _solve_lm(pr, lm_o, "modern" if method == "lm" else "paper", loss, cb)
        else:
            out = _solve_random(pr, rs_o, cb)
    finally:
        close()
    result = _result(pr, out, method, time.perf_counter() - start)
    if other["analyze"]:
        _analyse(result, pr, other["pixel_noise"], other["point_noise"], loss)
    return result


@dataclass
class _Problem:
    """A paper-model calibration's checked set-up: the data, the bounds and the box the
    fixed parameters collapse it to, the start, the initial box of Eq. 22 (with a spread),
    runs, seed, threads and the notes for the result."""

    dataset: Dataset
    test: Dataset | None
    data: Any  # the C++ fitness data
    bounds: Bounds
    fixed: tuple[str, ...]
    fixed_mask: np.ndarray
    q0: np.ndarray
    search: Bounds
    init_box: Bounds | None
    spread: float | None
    runs: int
    seed: int
    threads: int
    notes: list[str]


@dataclass
class _Solved:
    """What a method's solve gives: the best parameters, the runs and the stages."""

    q: np.ndarray
    iterations: int
    termination: Termination
    history: np.ndarray = field(default_factory=lambda: np.empty(0))
    run_fitness: np.ndarray = field(default_factory=lambda: np.empty(0))
    run_params: np.ndarray = field(default_factory=lambda: np.empty((0, NUM_PARAMS)))
    pso: PsoStage | None = None
    lm: LmStage | None = None
    random: RandomSearchStage | None = None


def _problem(dataset: Any, test: Any, bounds: Any, initial: Any, fixed: Iterable[str],
             runs: int, seed: int, threads: int | None, spread: Any) -> _Problem:
    """Check the inputs (ValueError naming the problem) and set the problem up."""
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
    runs, seed = check_runs(runs), check_seed(seed)
    cores = min(os.cpu_count() or 1, 1024)
    threads_n = cores if threads is None else check_threads(threads)
    q0 = _start(initial, bounds, fixed_mask)
    # Fixed parameters: the search box collapses onto their values.
    search = Bounds(np.where(fixed_mask, q0, bounds.lower), np.where(fixed_mask, q0, bounds.upper))
    init_box = None
    if spread is not None:
        box = Bounds.around(q0, float(spread))
        init_box = Bounds(np.where(fixed_mask, q0, box.lower), np.where(fixed_mask, q0, box.upper))
    notes: list[str] = []
    if "Su" in fixed:
        notes.append(_GAUGE_NOTE.format(value=q0[param_index("Su")]))
    if threads_n > cores:
        notes.append(f"threads capped at {cores}, the machine's cores (asked: {threads}); the "
                     "result is the same for any thread count")
    others = [n for n in fixed if n != "Su"]
    if others:
        notes.append("held fixed at their initial values: " + ", ".join(others))
    return _Problem(dataset=dataset, test=test, data=fitness_data(dataset), bounds=bounds,
                    fixed=fixed, fixed_mask=fixed_mask, q0=q0, search=search,
                    init_box=init_box, spread=spread, runs=runs, seed=seed,
                    # more threads than cores only slow the solve down
                    threads=min(threads_n, cores), notes=notes)


def _start(initial: Any, bounds: Bounds, fixed_mask: np.ndarray) -> np.ndarray:
    """The start (and the fixed parameters' values): the given one, else the nominal values
    (the box's centre for the free ones the bounds exclude); ValueError if outside."""
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
    return q0


def _solve_pso(pr: _Problem, pso_o: Any, lm_o: Any, loss: str | None, cb: Any) -> _Solved:
    """The swarm (Eq. 19-21), each run's best polished by modern LM when ``lm_o`` is given."""
    box = pr.init_box
    o = pso_struct(pso_o, runs=pr.runs, threads=pr.threads, seed=pr.seed, lower=pr.search.lower,
                   upper=pr.search.upper, init_lower=None if box is None else box.lower,
                   init_upper=None if box is None else box.upper)
    res = _core._run_pso(pr.data, o, cb)
    best = res.runs[res.best_run]
    run_fitness = np.array([r.best_fitness for r in res.runs])
    run_params = np.array([r.best for r in res.runs])
    stage = PsoStage(
        termination=(Termination.CANCELLED if res.cancelled
                     else Termination.from_pso(str(best.termination))),
        iterations=int(best.iterations), best_fitness=float(best.best_fitness),
        best_run=int(res.best_run), run_fitness=run_fitness.copy(),
        run_params=run_params.copy(),
        histories=[np.array(r.history) for r in res.runs], seconds=float(res.seconds))
    out = _Solved(q=np.array(best.best), iterations=stage.iterations,
                  termination=stage.termination, history=np.array(best.history),
                  run_fitness=run_fitness, run_params=run_params, pso=stage)
    if lm_o is None or res.cancelled:
        return out
    lo = lm_struct(lm_o, mode="modern", fixed=pr.fixed_mask, lower=pr.search.lower,
                   upper=pr.search.upper, loss=loss)
    starts = np.array([r.best for r in res.runs])
    lms, errs = _core._run_lm_many(pr.data, starts, lo, pr.threads)
    costs = np.array([r.final_cost if not e else np.inf for r, e in zip(lms, errs)])
    k = int(np.argmin(costs))
    improved = bool(np.isfinite(costs[k]) and costs[k] <= best.best_fitness)
    out.lm = _lm_stage(lms, errs, starts, costs, k, improved)
    if not improved:
        pr.notes.append("LM polishing did not improve the swarm's best")
        return out
    out.q = np.array(lms[k].params)
    out.iterations += out.lm.iterations
    out.termination = out.lm.termination
    # each run keeps the better of its swarm's best and the polished one
    better = costs <= run_fitness
    out.run_params = np.where(better[:, None], np.array([r.params for r in lms]), run_params)
    out.run_fitness = np.where(better, costs, run_fitness)
    return out


def _solve_lm(pr: _Problem, lm_o: Any, mode: str, loss: str | None, cb: Any) -> _Solved:
    """Levenberg-Marquardt from the start, or from ``runs`` starts drawn by Eq. 22."""
    lo = lm_struct(lm_o, mode=mode, fixed=pr.fixed_mask, lower=pr.search.lower,
                   upper=pr.search.upper, loss=loss)
    if pr.runs > 1 or pr.spread is not None:
        if pr.spread is None or pr.init_box is None:
            raise ValueError("several LM runs need spread=s to draw starts by Eq. 22")
        starts = np.random.default_rng(pr.seed).uniform(pr.init_box.lower, pr.init_box.upper,
                                                        size=(pr.runs, NUM_PARAMS))
        if mode == "modern" and lm_o.use_bounds:  # inside the bounds LM keeps
            starts = np.clip(starts, pr.search.lower, pr.search.upper)
    else:
        starts = pr.q0[None, :]
    starts = np.ascontiguousarray(starts)
    lms, errs = _core._run_lm_many(pr.data, starts, lo, pr.threads, cb)
    costs = np.array([r.final_cost if not e else np.inf for r, e in zip(lms, errs)])
    cancelled = any(e == "cancelled" for e in errs)
    if not np.isfinite(costs).any():
        if cancelled:
            raise ValueError("LM was cancelled before any start was solved")
        raise ValueError(f"LM could not start: {next(e for e in errs if e)}")
    k = int(np.argmin(costs))
    stage = _lm_stage(lms, errs, starts, costs, k, True)
    return _Solved(q=np.array(lms[k].params), iterations=stage.iterations,
                   termination=Termination.CANCELLED if cancelled else stage.termination,
                   run_fitness=costs, run_params=stage.run_params, lm=stage)


def _solve_random(pr: _Problem, rs_o: Any, cb: Any) -> _Solved:
    """Random search (Eq. 22) in the initial box, or the search box without a spread."""
    box = pr.init_box if pr.init_box is not None else pr.search
    o = random_search_struct(rs_o, threads=pr.threads, seed=pr.seed, lower=box.lower,
                             upper=box.upper)
    res = _core._run_random_search(pr.data, o, cb)
    termination = Termination.CANCELLED if res.cancelled else Termination.MAX_EVALUATIONS
    stage = RandomSearchStage(termination=termination, evaluations=int(res.evaluations),
                              best_fitness=float(res.best_fitness), seconds=float(res.seconds))
    return _Solved(q=np.array(res.best), iterations=int(res.evaluations),
                   termination=termination, random=stage)


def _result(pr: _Problem, out: _Solved, method: str, seconds: float) -> CalibrationResult:
    """The solve's outcome with its errors on the fitting and held-out points."""
    q = out.q
    if not np.all(np.isfinite(q)) or not math.isfinite(pr.data.evaluate(q)):
        raise ValueError(f"{method} found no parameter vector for which every pixel's ray meets "
                         "the laser plane; widen or check the bounds")
    fit_errors = np.array(pr.data.point_errors(q))
    test_errors = None
    if pr.test is not None:
        test_errors = np.array(fitness_data(pr.test).point_errors(q))
    test_rms = _test_rms(test_errors, pr.notes)
    return CalibrationResult(
        params=Parameters.from_array(q), method=method, fixed=pr.fixed,
        fit_rms=_rms(fit_errors), test_rms=test_rms,
        fit_errors=fit_errors, test_errors=test_errors, cost=float(pr.data.evaluate(q)),
        history=out.history, run_fitness=out.run_fitness, iterations=out.iterations,
        termination=out.termination, seconds=seconds, seed=int(pr.seed),
        threads=pr.threads, bounds=pr.bounds, notes=pr.notes, run_params=out.run_params,
        termination_message=_termination_message(out.termination, out.pso, out.lm, out.random),
        pso=out.pso, lm=out.lm, random=out.random)


def _analyse(result: CalibrationResult, pr: _Problem, pixel_noise: Any, point_noise: Any,
             loss: str | None) -> None:
    """Identifiability and uncertainty at the solution (issue 4); their warnings are issued
    as their kinds' subclasses and kept in the result. A failed analysis is reported, not
    raised: the calibration stands."""
    try:
        result.identifiability, result.uncertainty, data_warnings = diagnose(
            pr.dataset, result.params.to_array(), pr.fixed, pr.bounds, pixel_noise,
            point_noise, loss)
    except (ValueError, np.linalg.LinAlgError) as e:
        data_warnings = [f"identifiability and uncertainty not computed: {e}"]
    for w in data_warnings:
        warnings.warn(w, warning_category(w), stacklevel=4)  # at the caller of calibrate
    result.warnings.extend(data_warnings)
