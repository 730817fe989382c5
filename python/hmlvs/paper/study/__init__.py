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

``hmlvs.paper.study.study(...)`` runs it and returns a :class:`StudyResult`; ``hmlvs study`` is the
command line."""

from .report import COLORS, PLOT_DPI, StudyResult
from .results import (
    FULL,
    LABELS,
    LM_MAX_ITERATIONS,
    METHODS,
    PAPER_S,
    PAPER_TABLE1,
    PSO_ITERATIONS,
    QUICK,
    STATS,
    SUCCESS_THRESHOLD,
    SWARM_SIZE,
    VALLEY_PARAMS,
    HeldOut,
    MethodRuns,
    Stats,
    StudyProgress,
    StudySettings,
    paper_value,
)
from .run import run_seed, study

__all__ = [
    "COLORS", "FULL", "HeldOut", "LABELS", "LM_MAX_ITERATIONS", "METHODS", "MethodRuns",
    "PAPER_S", "PAPER_TABLE1", "PLOT_DPI", "PSO_ITERATIONS", "QUICK", "STATS",
    "SUCCESS_THRESHOLD", "SWARM_SIZE", "Stats", "StudyProgress", "StudyResult",
    "StudySettings", "VALLEY_PARAMS", "paper_value", "run_seed", "study"
]
