"""Typed outcome of a solve: why it stopped, and what each stage (PSO, LM, random search) did.

:class:`hmlvs.calibration.result.CalibrationResult`, the paper model's calibration, holds these.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np

from ..models.params import NAMES, NUM_PARAMS, Bounds, Parameters

if TYPE_CHECKING:
    from ..diagnostics.identifiability import IdentifiabilityReport
    from ..diagnostics.uncertainty import Uncertainty


class Termination(str, Enum):
    """Why a solve stopped. A ``str`` enum: ``Termination.CANCELLED == "cancelled"``."""

    CONVERGED = "converged"              #: LM met a tolerance (Ceres CONVERGENCE)
    MAX_ITERATIONS = "max_iterations"    #: the PSO generations or LM iteration limit ran out
    TARGET_FITNESS = "target_fitness"    #: PSO reached ``target_fitness``
    MAX_EVALUATIONS = "max_evaluations"  #: random search drew all its candidates
    CANCELLED = "cancelled"              #: the progress callback asked to stop
    FAILED = "failed"                    #: the solver gave up (Ceres FAILURE)
    NOT_SOLVED = "not_solved"            #: no solve: parameters evaluated as given

    def __str__(self) -> str:
        return self.value

    @classmethod
    def from_ceres(cls, name: str) -> Termination:
        """Ceres' termination type name -> a Termination."""
        return {"CONVERGENCE": cls.CONVERGED, "NO_CONVERGENCE": cls.MAX_ITERATIONS,
                "USER_SUCCESS": cls.CONVERGED, "USER_FAILURE": cls.CANCELLED,
                "cancelled": cls.CANCELLED}.get(name, cls.FAILED)

    @classmethod
    def from_pso(cls, name: str) -> Termination:
        """The PSO core's termination string -> a Termination."""
        return {"max_iterations": cls.MAX_ITERATIONS, "target_fitness": cls.TARGET_FITNESS,
                "cancelled": cls.CANCELLED}.get(name, cls.FAILED)


@dataclass(frozen=True)
class PsoStage:
    """The particle swarm stage.

    termination, iterations, best_fitness : of the best run (F in mm^2)
    run_fitness : each run's best fitness F; run_params : (runs, 14) each run's best
    histories : best F after each iteration, per run; seconds : wall-clock time of the stage
    """

    termination: Termination
    iterations: int
    best_fitness: float
    best_run: int
    run_fitness: np.ndarray
    run_params: np.ndarray
    histories: list[np.ndarray]
    seconds: float

    @property
    def message(self) -> str:
        return f"PSO: {self.iterations} generations, {self.termination.value}"


@dataclass(frozen=True)
class LmStage:
    """The Levenberg-Marquardt stage (one or several starts).

    termination, iterations, initial_cost, final_cost, message : of the best start (costs
    F = 1/2 sum of squared residuals, mm^2; ``message`` is Ceres' own sentence)
    ceres_termination : Ceres' termination type name, e.g. "CONVERGENCE"
    improved : False when the polished result was not kept (PSO + LM, worse than the swarm)
    starts, run_params, run_costs, run_iterations, run_termination : per start (NaN / 0 /
    "error" / "cancelled" for starts that could not be solved); errors : their messages
    """

    termination: Termination
    ceres_termination: str
    message: str
    iterations: int
    initial_cost: float
    final_cost: float
    seconds: float
    best_start: int
    starts: np.ndarray
    run_params: np.ndarray
    run_costs: np.ndarray
    run_iterations: np.ndarray
    run_termination: list[str]
    errors: list[str] = field(default_factory=list)
    improved: bool = True


@dataclass(frozen=True)
class RandomSearchStage:
    """The random search stage: candidates drawn, the best fitness F (mm^2), time."""

    termination: Termination
    evaluations: int
    best_fitness: float
    seconds: float


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

    def determined_split(self) -> tuple[list[str], list[str]]:
        """The free parameters the data determine, and those they do not (from the
        uncertainty; all undetermined without it)."""
        u = self.uncertainty
        if u is None:
            return [], list(self.free)
        return ([n for n in self.free if u.determined.get(n, False)],
                [n for n in self.free if not u.determined.get(n, False)])

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values (the command line's --json): the
        parameters, what was held and what the data determine, the fit, the termination."""
        from ..models.paper import hand_eye_rotation_vector

        det, undet = self.determined_split()
        return {"model": "paper", "method": self.method,
                "parameters": self.params.to_dict(), "fixed": list(self.fixed),
                "determined": det, "not_determined": undet,
                "rotation_vector_rad": hand_eye_rotation_vector(self.params),
                "fit_rms_mm": self.fit_rms, "test_rms_mm": self.test_rms,
                "termination": str(self.termination), "seconds": self.seconds}

    def solve_figures(self) -> dict[str, Any]:
        """The solve's figures in the form both models share (``hmlvs calibrate --json``'s
        ``solve``, docs/file-formats.md): why and when it stopped, what the data determine,
        the hand-eye rotation."""
        from ..models.paper import hand_eye_rotation_vector

        det, undet = self.determined_split()
        return {"termination": str(self.termination), "iterations": int(self.iterations),
                "seconds": float(self.seconds), "unknowns": len(self.free), "rank": len(det),
                "determined": det, "not_determined": undet,
                "rotation_vector_rad": hand_eye_rotation_vector(self.params)}

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
