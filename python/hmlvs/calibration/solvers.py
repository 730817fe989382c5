"""Parameter identification: PSO, Levenberg-Marquardt (Ceres), random search, and PSO + LM."""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import os
import time
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence
import warnings

import numpy as np

from .. import _core
from ..data.dataset import Dataset, fit_and_test
from ..diagnostics.identifiability import HmlvsDataWarning
from ..diagnostics.uncertainty import check_noise, diagnose
from ..models.params import NAMES, NUM_PARAMS, Bounds, Parameters, param_index
from ..models.params import fixed_mask as params_fixed_mask

if TYPE_CHECKING:
    from ..diagnostics.identifiability import IdentifiabilityReport
    from ..diagnostics.uncertainty import Uncertainty

METHODS = ("pso+lm", "pso", "lm", "lm-paper", "random")
LOSSES = (None, "huber", "cauchy")
_PSO_OPTIONS = {"swarm_size": 50, "iterations": 5000, "w_max": 0.9, "w_min": 0.4, "c1": 2.0,
                "c2": 2.0, "vmax": 0.1, "target_fitness": 0.0, "progress_every": 100}
_LM_OPTIONS = {"max_iterations": 0, "loss_scale": 1.0, "use_bounds": True}
_OTHER_OPTIONS = {"evaluations": 1_000_000, "spread": None, "test": None,
                  "pixel_noise": None, "point_noise": None, "analyze": True}
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
    iterations : PSO iterations of the best run, plus LM iterations after it
    termination : why the solve stopped (e.g. "max_iterations", "CONVERGENCE")
    seconds : wall-clock time of the solve
    notes : what the solver assumed (e.g. the gauge held fixed)
    warnings : problems found with the data or the solution
    identifiability : what the data determine at the solution (Jacobian SVD, named flat
        directions; :func:`hmlvs.identifiability`)
    uncertainty : covariance, standard deviations, correlations and identifiable
        combinations of the free parameters (:func:`hmlvs.uncertainty`)
    extra : per-run details of several runs: ``run_params`` ((runs, 14), each run's final
        parameters, in the order of ``run_fitness``; NaN rows for LM starts that failed),
        ``starts`` ((runs, 14), the LM starts), ``run_iterations`` and ``run_termination``
        (LM), ``pso_seconds`` and ``pso_histories`` (PSO)
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
    termination: str
    seconds: float
    seed: int
    threads: int
    bounds: Bounds
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
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
    def free(self) -> tuple[str, ...]:
        return tuple(n for n in NAMES if n not in self.fixed)

    def summary(self, truth: Parameters | None = None) -> str:
        lines = [f"method {self.method}: {self.termination} after {self.iterations} iterations "
                 f"in {self.seconds:.3f} s ({self.threads} threads, seed {self.seed})",
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
    return float(np.sqrt(np.mean(errors**2))) if errors.size else float("nan")


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


def _split_options(options: dict[str, Any]) -> tuple[dict, dict, dict]:
    unknown = set(options) - set(_PSO_OPTIONS) - set(_LM_OPTIONS) - set(_OTHER_OPTIONS)
    if unknown:
        raise ValueError(f"unknown option(s) {sorted(unknown)}; valid options: "
                         f"{', '.join(sorted({**_PSO_OPTIONS, **_LM_OPTIONS, **_OTHER_OPTIONS}))}")
    pso = {k: options.get(k, v) for k, v in _PSO_OPTIONS.items()}
    lm = {k: options.get(k, v) for k, v in _LM_OPTIONS.items()}
    other = {k: options.get(k, v) for k, v in _OTHER_OPTIONS.items()}
    return pso, lm, other


def _as_vector(params: Any, name: str) -> np.ndarray:
    if isinstance(params, Parameters):
        return params.to_array()
    if isinstance(params, dict):
        return Parameters.from_dict(params).to_array()
    arr = np.asarray(params, dtype=float).reshape(-1)
    if arr.shape != (NUM_PARAMS,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be {NUM_PARAMS} finite values")
    return arr


def _lm_options(mode: str, fixed_mask: np.ndarray, bounds: Bounds, loss: str | None,
                lm: dict[str, Any]) -> Any:
    o = _core._LmOptions()
    o.mode = getattr(_core._LmMode, mode)
    o.fixed = [bool(x) for x in fixed_mask]
    o.lower, o.upper = bounds.lower, bounds.upper
    o.use_bounds = bool(lm["use_bounds"])
    o.max_iterations = int(lm["max_iterations"])
    o.loss = getattr(_core._LossKind, "none" if loss is None else loss)
    o.loss_scale = float(lm["loss_scale"])
    if mode == "paper":  # MINPACK lmdif's default tolerances, as the paper used MINPACK
        o.function_tolerance = o.parameter_tolerance = 1.49012e-8
        o.gradient_tolerance = 0.0
    return o


def evaluate(params: Any, dataset: Dataset, test: Dataset | None = None,
             method: str = "evaluated", fixed: Iterable[str] = ()) -> CalibrationResult:
    """A :class:`CalibrationResult` for given parameters (no solve): RMS and per-point errors
    on ``dataset`` (and ``test``), e.g. to report on a calibration file."""
    q = _as_vector(params, "params")
    fit_errors = np.array(_fitness_data(dataset).point_errors(q))
    test_errors = None if test is None else np.array(_fitness_data(test).point_errors(q))
    return CalibrationResult(
        params=Parameters.from_array(q), method=method, fixed=tuple(fixed),
        fit_rms=_rms(fit_errors), test_rms=None if test_errors is None else _rms(test_errors),
        fit_errors=fit_errors, test_errors=test_errors,
        cost=float(0.5 * np.nansum(fit_errors**2)), history=np.empty(0),
        run_fitness=np.empty(0), iterations=0, termination="none (evaluation only)",
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
              fixed: Iterable[str] = ("Su",), runs: int = 1, seed: int = 0,
              threads: int | None = None, loss: str | None = None, progress: Any = None,
              **options: Any) -> CalibrationResult:
    """Identify the 14 sensor parameters from calibration points.

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
    fixed : parameter names held at their initial values. By default Su, the scale gauge
    runs : independent PSO runs (the best is kept) or, for "lm"/"lm-paper" with ``spread``,
        starts drawn by Eq. 22
    seed : random seed; results are identical for a seed whatever ``threads``
    threads : worker threads (default: all cores)
    loss : robust loss for LM, None, "huber" or "cauchy", with ``loss_scale`` in mm
    progress : None, True (a progress bar), a callable ``(done, total, best_fitness)`` that may
        return False to stop, or a tqdm-like bar. Counts PSO iterations (summed over runs),
        random-search evaluations or LM starts solved
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
    pso_o, lm_o, other = _split_options(options)
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
    if runs < 1:
        raise ValueError(f"runs must be >= 1, got {runs}")
    threads_n = (os.cpu_count() or 1) if threads is None else int(threads)
    if threads_n < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
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
    others = [n for n in fixed if n != "Su"]
    if others:
        notes.append("held fixed at their initial values: " + ", ".join(others))
    cb, close = _resolve_progress(progress)
    history = np.empty(0)
    run_fitness = np.empty(0)
    extra: dict[str, Any] = {}
    try:
        if method in ("pso", "pso+lm"):
            o = _core._PsoOptions()
            for k, v in pso_o.items():
                setattr(o, k, v)
            o.runs, o.threads, o.seed = int(runs), threads_n, int(seed)
            o.lower, o.upper = search.lower, search.upper
            if init_box is not None:
                o.init_lower, o.init_upper = init_box.lower, init_box.upper
            res = _core._run_pso(data, o, cb)
            best = res.runs[res.best_run]
            q = np.array(best.best)
            history = np.array(best.history)
            run_fitness = np.array([r.best_fitness for r in res.runs])
            run_params = np.array([r.best for r in res.runs])
            iterations, termination = int(best.iterations), str(best.termination)
            extra["pso_seconds"] = res.seconds
            extra["pso_histories"] = [np.array(r.history) for r in res.runs]
            if res.cancelled:
                termination = "cancelled"
            if method == "pso+lm" and not res.cancelled:
                lo = _lm_options("modern", fixed_mask, search, loss, lm_o)
                starts = np.array([r.best for r in res.runs])
                lms, errs = _core._run_lm_many(data, starts, lo, threads_n)
                costs = np.array([r.final_cost if not e else np.inf for r, e in zip(lms, errs)])
                k = int(np.argmin(costs))
                if np.isfinite(costs[k]) and costs[k] <= best.best_fitness:
                    q = np.array(lms[k].params)
                    iterations += int(lms[k].iterations)
                    termination = f"{termination}; LM: {lms[k].termination}"
                    # each run keeps the better of its swarm's best and the polished one
                    better = costs <= run_fitness
                    run_params = np.where(better[:, None],
                                          np.array([r.params for r in lms]), run_params)
                    run_fitness = np.where(better, costs, run_fitness)
                else:
                    notes.append("LM polishing did not improve the swarm's best")
            extra["run_params"] = run_params
        elif method in ("lm", "lm-paper"):
            mode = "modern" if method == "lm" else "paper"
            lo = _lm_options(mode, fixed_mask, search, loss, lm_o)
            if runs > 1 or spread is not None:
                if spread is None:
                    raise ValueError("several LM runs need spread=s to draw starts by Eq. 22")
                starts = np.random.default_rng(seed).uniform(init_box.lower, init_box.upper,
                                                             size=(runs, NUM_PARAMS))
                if mode == "modern" and lm_o["use_bounds"]:  # inside the bounds LM keeps
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
            iterations, termination = int(lms[k].iterations), str(lms[k].termination)
            if cancelled:
                termination = "cancelled"
            run_fitness = costs
            extra["lm_message"] = lms[k].message
            extra["lm_errors"] = [e for e in errs if e]
            extra["starts"] = starts
            extra["run_params"] = np.array([r.params if not e else np.full(NUM_PARAMS, np.nan)
                                            for r, e in zip(lms, errs)])
            extra["run_iterations"] = np.array([r.iterations if not e else 0
                                                for r, e in zip(lms, errs)])
            extra["run_termination"] = [r.termination if not e else
                                        ("cancelled" if e == "cancelled" else "error")
                                        for r, e in zip(lms, errs)]
        else:  # random search
            o = _core._RandomSearchOptions()
            o.evaluations = int(other["evaluations"])
            o.threads, o.seed = threads_n, int(seed)
            box = init_box if init_box is not None else search
            o.lower, o.upper = box.lower, box.upper
            res = _core._run_random_search(data, o, cb)
            q = np.array(res.best)
            iterations = int(res.evaluations)
            termination = "cancelled" if res.cancelled else "max_evaluations"
    finally:
        close()

    if not np.all(np.isfinite(q)) or not math.isfinite(data.evaluate(q)):
        raise ValueError(f"{method} found no parameter vector for which every pixel's ray meets "
                         "the laser plane; widen or check the bounds")
    fit_errors = np.array(data.point_errors(q))
    test_errors = None
    if test is not None:
        test_errors = np.array(_fitness_data(test).point_errors(q))
    result = CalibrationResult(
        params=Parameters.from_array(q), method=method, fixed=fixed,
        fit_rms=_rms(fit_errors), test_rms=None if test_errors is None else _rms(test_errors),
        fit_errors=fit_errors, test_errors=test_errors, cost=float(data.evaluate(q)),
        history=history, run_fitness=run_fitness, iterations=iterations,
        termination=termination, seconds=time.perf_counter() - start, seed=int(seed),
        threads=threads_n, bounds=bounds, notes=notes, extra=extra)
    # --- identifiability and uncertainty at the solution (issue 4) ---------------------------
    if not other["analyze"]:
        return result
    try:
        result.identifiability, result.uncertainty, data_warnings = diagnose(
            dataset, q, fixed, bounds, other["pixel_noise"], other["point_noise"], loss)
    except (ValueError, np.linalg.LinAlgError) as e:  # report, do not fail the calibration
        data_warnings = [f"identifiability and uncertainty not computed: {e}"]
    for w in data_warnings:
        warnings.warn(w, HmlvsDataWarning, stacklevel=2)
    result.warnings.extend(data_warnings)
    # --- end of issue 4 ------------------------------------------------------------------------
    return result
