"""The joint calibration's solve (step 4 of :mod:`hmlvs.calibration.joint`): Levenberg-Marquardt
with the noise levels re-estimated from the residuals and outliers dropped, with the robot
poses exact or uncertain."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import _core
from .._arrays import robust_sigma
from .joint_setup import finite_rms

#: residuals beyond this many robust sigmas are dropped (Gaussian: 6e-7)
ROBUST_K = 5.0


#: warn when the exact chain's corner RMS exceeds this many times the free-pose camera
#: calibration's (on renders with exact poses the two agree within 10 %; the Blaser UR5e
#: sessions: 1.9 px against 0.35 px at 640 x 480)
POSE_DISAGREEMENT = 2.0


def solve_weighted(make_views: Any, state: Any, opts: Any, keep_c: list[np.ndarray],
                    keep_l: list[np.ndarray], robust: bool) -> tuple[Any, Any]:
    """Solve, re-estimate the corner and laser noise from the residuals and (``robust``) drop
    the points beyond 5 robust sigmas, until neither moves (at most 4 solves). The noise
    levels start at the set-up's; only their ratio moves the solution, so a solve is
    repeated only when it changes by > 20 % or points are dropped. ``keep_c``/``keep_l`` (the
    per-view masks) are updated in place; returns the last result and state."""
    all_c = [np.ones(len(k), bool) for k in keep_c]
    all_l = [np.ones(len(k), bool) for k in keep_l]
    result = None
    for _ in range(4):
        jv = make_views(keep_c, keep_l)
        result = _core._solve_joint(jv, state, opts)
        state = result.state
        corners_r, laser_r = _core._evaluate_joint(jv, state, opts)
        c_all = np.concatenate([c.ravel() for c in corners_r])
        l_all = np.concatenate(laser_r) if laser_r else np.empty(0)
        sc, sl = finite_rms(c_all), finite_rms(l_all)
        changed = l_all.size > 0 and abs((sc / sl) / (opts.corner_sigma / opts.laser_sigma)
                                         - 1) > 0.2
        opts.corner_sigma, opts.laser_sigma = max(sc, 1e-6), max(sl if l_all.size else 1.0, 1e-6)
        dropped_any = False
        if robust:
            full_c, full_l = _core._evaluate_joint(make_views(all_c, all_l), state, opts)
            limit_c = ROBUST_K * max(robust_sigma(c_all) * math.sqrt(2), 1e-9)
            limit_l = ROBUST_K * max(robust_sigma(l_all), 1e-9)
            for i in range(len(keep_c)):
                new_c = np.hypot(full_c[i][:, 0], full_c[i][:, 1]) <= limit_c
                new_l = np.isfinite(full_l[i]) & (np.abs(full_l[i]) <= limit_l)
                if new_c.sum() < 6:
                    new_c = keep_c[i]
                if not np.array_equal(new_c, keep_c[i]) or not np.array_equal(new_l, keep_l[i]):
                    dropped_any = True
                keep_c[i], keep_l[i] = new_c, new_l
        if not changed and not dropped_any:
            break
    assert result is not None
    return result, state


def robot_poses_uncertain(mode: str) -> bool:
    """Whether to solve with uncertain robot poses (``calibrate_joint``'s ``robot_poses``)."""
    if mode not in ("exact", "uncertain"):
        raise ValueError(f"robot_poses must be exact or uncertain, got {mode!r}")
    return mode == "uncertain"


def pose_sigmas(errors: list[np.ndarray]) -> tuple[float, float]:
    """The robot pose errors' RMS per axis (rad, mm), less the 6 + 6 degrees of freedom the
    hand-eye and board poses take out of the 6 n components."""
    e = np.asarray(errors, float).reshape(-1, 6)
    dof = max(3 * len(e) - 6, 1)
    return (max(float(np.sqrt(np.sum(e[:, :3] ** 2) / dof)), 1e-7),
            max(float(np.sqrt(np.sum(e[:, 3:] ** 2) / dof)), 1e-4))


def solve_uncertain_poses(make_views: Any, state: Any, opts: Any, keep_c: list[np.ndarray],
                           keep_l: list[np.ndarray], robust: bool
                           ) -> tuple[Any, Any, tuple[float, float]]:
    """Chain mode with uncertain robot poses (``JointOptions.pose_sigma_t``): the poses'
    spread starts at the errors that the views' own board poses (from their corners) imply
    against the exact chain's solution, and is estimated again from each solve's until it
    moves by less than 10 % (at most 8 rounds), never above its start: with a spread free to
    grow, the views' poses would take ever more of the data's misfit and the hand-eye
    transform ever less (seen on half of the Blaser 640 session: 2.6 mm -> 21 mm and a
    meaningless hand-eye). Returns the result, the state and the spread (mm, deg) per
    axis."""
    opts.pose_sigma_r, opts.pose_sigma_t = 1.0, 1.0
    top_r, top_t = pose_sigmas(_core._joint_pose_errors(make_views(keep_c, keep_l), state,
                                                         opts))
    sig_r, sig_t = top_r, top_t
    result = None
    for _ in range(8):
        opts.pose_sigma_r, opts.pose_sigma_t = sig_r, sig_t
        result, state = solve_weighted(make_views, state, opts, keep_c, keep_l, robust)
        sig_r, sig_t = pose_sigmas(_core._joint_pose_errors(make_views(keep_c, keep_l), state,
                                                             opts))
        sig_r, sig_t = min(sig_r, top_r), min(sig_t, top_t)
        if abs(sig_r / opts.pose_sigma_r - 1) < 0.1 and abs(sig_t / opts.pose_sigma_t - 1) < 0.1:
            break
    opts.pose_sigma_r, opts.pose_sigma_t = sig_r, sig_t
    return result, state, (sig_t, math.degrees(sig_r))
