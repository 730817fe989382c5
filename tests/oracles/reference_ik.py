"""The look-at inverse kinematics of the session simulator in NumPy: the reference the C++
solve (``hmlvs._core._solve_look_at``) must equal bit for bit (``test_simulate.py``) and is
timed against (``bench/run_bench.py``). The solve itself is ``hmlvs.sim.sessions``'
``_damped_solve``, the generic one the stripe snap uses; the forward kinematics is hmlvs'
(the C++ core's), so that both sides start from the same poses."""

from __future__ import annotations

import numpy as np


def look_at_residual(robot, hfc: np.ndarray, pos: np.ndarray, axis: np.ndarray,
                     cam_x: np.ndarray | None):
    """Residual (m, 6 or 9) of joint readings (m, n): camera position - pos, 300 (z axis -
    axis), 100 (x axis - cam_x); base_from_camera in elementwise operations (no BLAS), summed
    over the inner index in order, as the C++ solve sums it."""
    def res(j: np.ndarray) -> np.ndarray:
        t = robot.poses(j)
        cam = t[:, :, 0, None] * hfc[0]
        for i in range(1, 4):
            cam = cam + t[:, :, i, None] * hfc[i]
        r = [cam[:, :3, 3] - pos, 300.0 * (cam[:, :3, 2] - axis)]
        if cam_x is not None:
            r.append(100.0 * (cam[:, :3, 0] - cam_x))
        return np.concatenate(r, axis=1)
    return res


def solve_look_at(robot, hfc, pos, axis, cam_x, start, lower, upper, max_step=0.2,
                  iterations=200):
    """The NumPy solve with the C++ one's arguments: (joints, residual norm)."""
    from hmlvs.sim.sessions import _damped_solve

    return _damped_solve(look_at_residual(robot, hfc, pos, axis, cam_x), start, lower, upper,
                         max_step, iterations)
