"""Typed outcome of a solve: why it stopped, and what each stage (PSO, LM, random search) did.

:class:`hmlvs.CalibrationResult` (in :mod:`hmlvs.calibration.solvers`) holds these.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np


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
