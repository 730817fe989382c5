"""Which ingredient of the paper's NLSO makes it stall? A check with MINPACK, the paper's solver.

Runs SciPy's MINPACK Levenberg-Marquardt (``least_squares(method="lm")``, MINPACK's
tolerances 1.49012e-8 as in hmlvs' paper mode, at most 4200 function evaluations) from the
first N starts that ``hmlvs study`` gives both LM modes at s = 0.2, on the same data, with
  1. the paper's scalar residual ||E_i|| per point, forward differences, Euler angles;
  2. the 3 components of E_i, forward differences, Euler angles;
  3. the 3 components of E_i, exact Jacobian (hmlvs.models.paper.residual_jacobian), Euler angles,
and prints the held-out RMS over the 50 test points (success: < 0.01 mm, as in the study).

With hmlvs installed (``pip install .``; ``make test`` does it):

    python docs/study/minpack_check.py [N]     # N = 100 by default
"""

from __future__ import annotations

import sys
import time
import warnings

import hmlvs
from hmlvs.calibration.solvers import fitness_data
from hmlvs.models.paper import least_squares_functions
from hmlvs.paper.study import SUCCESS_THRESHOLD, run_seed
import numpy as np
from scipy.optimize import least_squares


def main(n: int) -> None:
    sim = hmlvs.simulate(seed=0)
    fit = sim.fit
    test = fitness_data(sim.test)
    s = 0.2
    starts = hmlvs.calibration.solvers.initial_candidates(sim.truth, s, n, seed=run_seed(0, s, 1))

    # a ray that misses the laser plane: a large residual, MINPACK backs off
    components, jacobian = least_squares_functions(fit)

    def norms(q: np.ndarray) -> np.ndarray:
        return np.linalg.norm(components(q).reshape(-1, 3), axis=1)

    def held_out(q: np.ndarray) -> float:
        e = np.asarray(test.point_errors(q))
        return float(np.sqrt(np.mean(e**2))) if np.all(np.isfinite(e)) else float("inf")

    print(f"MINPACK LM from the study's first {n} starts at s = {s} (seed 0)")
    for name, fun, jac in (("scalar ||E_i||, forward differences", norms, "2-point"),
                           ("3 components, forward differences", components, "2-point"),
                           ("3 components, exact Jacobian", components, jacobian)):
        t = time.perf_counter()
        rms, capped = [], 0
        for q0 in starts:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = least_squares(fun, q0, jac=jac, method="lm", max_nfev=4200,
                                  xtol=1.49012e-8, ftol=1.49012e-8, gtol=1e-15)
            rms.append(held_out(r.x))
            capped += r.status == 0  # stopped by max_nfev
        v = np.array(rms)
        print(f"  {name}: {np.sum(v < SUCCESS_THRESHOLD)}/{n} below {SUCCESS_THRESHOLD} mm, "
              f"held-out RMS median {np.median(v):.2g}, worst {v.max():.2g} mm, "
              f"{capped} stopped at 4200 evaluations ({time.perf_counter() - t:.0f} s)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100)
