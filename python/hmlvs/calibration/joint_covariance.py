"""The exact chain's covariance with the robot's pose errors counted.

With the robot poses taken as exact, the solve weights each corner and stripe pixel by the RMS
of its kind's residuals, as if every residual were independent noise. A robot pose error is
not: it moves all of a view's corners and stripe points together, and the 54 corners of a view
that share one pose error, counted as independent, claim a precision the data do not have. On
renders with robot poses off by 0.3 mm and 0.1 degrees the claimed standard deviations were 7
times too small (z-scores' RMS 7.2 over 6 seeds); on the Blaser UR5e session at 640 x 480 the
two halves of the views disagreed by 11.5 times the uncertainty claimed.

The model here: each residual is its own white noise (as free board poses fit the corners) plus
``J_e e_i``, where ``e_i`` is view i's robot pose error (rotation vector and translation in the
hand frame, as :func:`hmlvs.calibration.joint_solve.solve_uncertain_poses` defines it),
``e_i ~ N(0, s^2 diag(sigma_r^2 I3, sigma_t^2 I3))`` independent over the views, and ``J_e``
the residuals' derivative with respect to it. ``sigma_r : sigma_t`` is the spread the views'
own board poses imply against the chain's; the scale ``s^2`` is estimated from the residuals by
the method of moments (their sum of squares against its expectation under the model). The
estimate is the exact chain's least squares, so its covariance is the sandwich

    A^-1 J^T C J A^-1,   A = J^T J (the weighted Jacobian with the solve's own weights),

with ``C`` the weighted residuals' covariance under the model.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, Sequence

import numpy as np

from .. import _core
from ..diagnostics.pose_errors import pose_error_part
from ..geometry.transforms import make_transform, rotation_from_vector
from .joint_solve import pose_sigmas

#: central-difference steps for J_e: rotation (rad) and translation (mm)
_STEP_R, _STEP_T = 1e-6, 1e-4


def inverse_normal(jac: np.ndarray) -> tuple[np.ndarray, int, float]:
    """(J^T J)^-1 of the weighted residuals' Jacobian via the column-scaled SVD; its numerical
    rank and condition number."""
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0] = 1.0
    js = jac / scale
    # QR first: the SVD of the small triangular factor has the same singular values and
    # right vectors, and costs nothing next to the SVD of the tall Jacobian.
    r = np.linalg.qr(np.asfortranarray(js), mode="r") if js.shape[0] > js.shape[1] else js
    _, s, vt = np.linalg.svd(r, full_matrices=False)
    tol = 1e-10 * s[0] if s.size else 0.0
    rank = int((s > tol).sum())
    inv = np.where(s > tol, 1.0 / np.where(s > tol, s, 1.0) ** 2, 0.0)
    cov_s = (vt.T * inv) @ vt
    cov = cov_s / np.outer(scale, scale)
    cond = float(s[0] / s[rank - 1]) if rank else float("inf")
    return cov, rank, cond


def white_part(jac: np.ndarray, cov: np.ndarray, share: np.ndarray) -> np.ndarray:
    """cov J^T diag(share) J cov: the covariance of white noise whose variance is ``share``
    times the weights' (per row), written as a sum of squares (B^T B, B = sqrt(share) J cov)
    so that no variance comes out negative however the rows' weights differ."""
    b = (jac @ cov) * np.sqrt(share)[:, None]
    return b.T @ b


class Residuals(NamedTuple):
    """The solve's residuals as the covariance needs them: per view its rows of the Jacobian
    (its corners x, y among every view's corners, then its stripe pixels among every view's
    stripe pixels), all of them weighted as the solve weighted them, and the number of corner
    rows (the stripe rows follow)."""

    rows: list[np.ndarray]
    weighted: np.ndarray
    n_corner_rows: int


def weighted_residuals(corners: Sequence[Any], laser: Sequence[Any], opts: Any) -> Residuals:
    """:class:`Residuals` of the per-view corner (px) and stripe residuals
    (``_core._evaluate_joint``'s), weighted by ``opts``' sigmas."""
    n_c = [np.asarray(c).size for c in corners]
    n_l = [len(x) for x in laser]
    c0, l0 = np.cumsum([0] + n_c), sum(n_c) + np.cumsum([0] + n_l)
    rows = [np.r_[np.arange(c0[i], c0[i + 1]), np.arange(l0[i], l0[i + 1])]
            for i in range(len(n_c))]
    weighted = np.r_[np.concatenate([np.asarray(c, float).ravel() for c in corners])
                     / opts.corner_sigma,
                     np.concatenate([np.asarray(x, float) for x in laser]) / opts.laser_sigma]
    return Residuals(rows, weighted, sum(n_c))


def _solve_weighted(jac: np.ndarray, res: Residuals, stripe_corr: float) -> np.ndarray:
    """``jac`` (its stripe rows divided by sqrt(stripe_corr)) with the solve's own weights."""
    jw = jac.copy()
    jw[res.n_corner_rows:] *= math.sqrt(stripe_corr)
    return jw


def _view_error_part(jw: np.ndarray, res: Residuals, share: np.ndarray,
                     effect: Sequence[np.ndarray]) -> tuple[np.ndarray, float] | None:
    """:func:`pose_error_part` for the solve-weighted Jacobian ``jw`` and per view the weighted
    derivative of its rows with respect to its own error (``effect``), with the white noise's
    expected sum of squares after the fit, tr(P diag(share)), P = I - jw A^-1 jw^T, and its
    chi-square spread."""
    a_inv = inverse_normal(jw)[0]
    expect = float(share.sum() - np.trace(a_inv @ (jw.T @ (jw * share[:, None]))))
    return pose_error_part(jw, a_inv, res.rows, effect, res.weighted, expect,
                           math.sqrt(2.0 * float(np.sum(share ** 2))))


def _perturbed(view: Any, k: int, h: float) -> Any:
    """``view`` with its robot pose moved by h along the k-th of (rx ry rz tx ty tz), in the
    hand frame (base_from_hand <- base_from_hand @ delta)."""
    delta = np.zeros(6)
    delta[k] = h
    d = make_transform(rotation_from_vector(delta[:3]), delta[3:])
    return _core._JointView(np.asarray(view.base_from_hand) @ d, view.corner_pixels,
                            view.corner_points, view.laser_pixels)


def pose_jacobian(view: Any, state: Any, opts: Any, anchor: Any) -> np.ndarray:
    """d(unweighted residuals of ``view``: its corners x, y, then its stripe pixels)/d(its
    robot pose error) (rows x 6), by central differences. ``anchor``: a view with corners
    (the solver evaluates no set of views without one; its residuals are not used)."""
    cols = []
    for k in range(6):
        h = _STEP_R if k < 3 else _STEP_T
        out = []
        for s in (h, -h):
            c, lz = _core._evaluate_joint([anchor, _perturbed(view, k, s)], state, opts)
            out.append(np.r_[np.asarray(c[1]).ravel(), np.asarray(lz[1])])
        cols.append((out[0] - out[1]) / (2 * h))
    return np.column_stack(cols)


def pose_spread(views: Sequence[Any], state: Any, opts: Any,
                own_poses: Sequence[np.ndarray | None]) -> tuple[float, float]:
    """The robot pose errors' spread (rotation rad, translation mm) that the views' own board
    poses (``own_poses``: camera_from_board from each view's corners, None for a laser-only
    view) imply against the exact chain's solution ``state``: their RMS per axis less the
    hand-eye and board poses' degrees of freedom (as :func:`solve_uncertain_poses` starts)."""
    idx = [i for i, p in enumerate(own_poses) if p is not None]
    saved = (opts.pose_sigma_r, opts.pose_sigma_t, list(state.camera_from_board))
    try:
        opts.pose_sigma_r, opts.pose_sigma_t = 1.0, 1.0
        state.camera_from_board = [own_poses[i] for i in idx]
        errors = _core._joint_pose_errors([views[i] for i in idx], state, opts)
    finally:
        opts.pose_sigma_r, opts.pose_sigma_t, state.camera_from_board = saved
    return pose_sigmas(errors)


def chain_covariance(views: Sequence[Any], state: Any, opts: Any, jac: np.ndarray,
                     cov: np.ndarray, stripe_corr: float, res: Residuals,
                     white: tuple[float, float], own_poses: Sequence[np.ndarray | None]
                     ) -> tuple[np.ndarray, tuple[float, float] | None]:
    """The exact chain's covariance with the robot pose errors counted (module doc), and the
    pose errors' spread the residuals show (mm, degrees; None when they show none).

    views, state, opts : the solve's (chain mode, poses exact); res : its residuals
        (:func:`weighted_residuals`)
    jac : the weighted Jacobian (corners of every view, then stripe pixels of every view),
        its stripe rows divided by sqrt(stripe_corr) (:func:`stripe_correlation`); cov :
        (J^T J)^-1 of it, the covariance of white noise alone
    white : the corners' (px per axis) and the stripe's (mm) own noise; each counts at most
        the solve's sigma (the residuals' RMS, which holds the pose errors' part too)
    own_poses : per view, camera_from_board from its own corners (None: laser-only)
    """
    n_rows = len(res.weighted)
    share = np.where(np.arange(n_rows) < res.n_corner_rows,
                     min(white[0] / opts.corner_sigma, 1.0) ** 2,
                     min(white[1] / opts.laser_sigma, 1.0) ** 2)
    sig_r, sig_t = pose_spread(views, state, opts, own_poses)
    shape = np.r_[np.full(3, sig_r), np.full(3, sig_t)]
    anchor = next(v for v in views if len(np.asarray(v.corner_pixels)))
    weight = np.where(np.arange(n_rows) < res.n_corner_rows, 1.0 / opts.corner_sigma,
                      1.0 / opts.laser_sigma)
    pose_jac = [pose_jacobian(v, state, opts, anchor) * weight[r][:, None] * shape
                for v, r in zip(views, res.rows)]
    part = _view_error_part(_solve_weighted(jac, res, stripe_corr), res, share, pose_jac)
    if part is None:
        return cov, None
    # white noise: the residuals' own part of the solve's sigmas
    return white_part(jac, cov, share) + part[0], (part[1] * sig_t, math.degrees(part[1] * sig_r))


#: the intrinsics that a view's own camera may differ in (the free ones of them are used)
_VIEW_INTRINSICS = ("fx", "fy", "cx", "cy")


def camera_mode_covariance(jac: np.ndarray, names: Sequence[str], cov: np.ndarray,
                           res: Residuals, stripe_corr: float
                           ) -> tuple[np.ndarray, dict[str, float] | None]:
    """Camera mode's covariance with the views' own cameras counted (the module doc's
    method, the views' differing intrinsics in place of robot pose errors), and the spread of
    those differences the residuals show (None when they show none).

    With free board poses a robot pose error cannot show; what does show on real sessions is
    that each view fits a camera of its own: at 640 x 480 on the Blaser bench frames the
    views' own focal lengths differ by 2.9 % RMS and their principal points by 6-7 px, 4-5
    times what their corners' noise explains (chi-square 269 on 13 and 530 on 26 degrees of
    freedom), and the two halves of the views disagreed by up to 8.3 standard deviations
    (at most 3.3, on k1, with the differences counted).
    The cause can be focus, heat, a lens that is not locked, or a lens model the views fit
    differently; counted as white noise, it makes the shared camera look far surer than it is.

    Model: view i's residuals are white noise plus ``G_i b_i``, ``G_i`` their derivative with
    respect to the camera's fx, fy, cx, cy and ``b_i ~ N(0, S)`` independent over the views.
    Each view's own deviation ``d_i`` (its rows fitted with its board pose and those
    intrinsics free, the rest held) estimates ``b_i`` plus noise; ``S``'s shape is their
    second moment less their noise's, and its scale the method of moments'
    (:func:`pose_error_part`). The white noise per row kind (corners, stripe) is what the
    views' own fits leave.

    jac : the weighted Jacobian (corners of every view, then stripe pixels of every view),
        its stripe rows divided by sqrt(stripe_corr); cov : (J^T J)^-1 of it
    res : the solve's residuals (:func:`weighted_residuals`; the i-th view owns the columns
        ``view{i}_*``)
    """
    rows, residuals = res.rows, res.weighted
    a = [names.index(n) for n in _VIEW_INTRINSICS if n in names]
    if not a or len(rows) < 3 or not np.all(np.isfinite(residuals)):
        return cov, None
    jw = _solve_weighted(jac, res, stripe_corr)
    fits = [_own_deviation(jw, names, a, i, r, residuals) for i, r in enumerate(rows)]
    n_rows, n_fit = len(residuals), jw.shape[1] + len(a) * len(rows)
    dof = max(1.0 - n_fit / n_rows, 1e-3)
    is_corner = np.arange(n_rows) < res.n_corner_rows
    left = np.concatenate([f[2] for f in fits])
    kinds = np.concatenate([is_corner[r] for r in rows])
    share = np.ones(n_rows)
    for k in (True, False):
        if np.any(kinds == k):
            share[is_corner == k] = min(float(np.mean(left[kinds == k] ** 2)) / dof, 1.0)
    dev = np.array([f[0] for f in fits])
    noise = np.mean([(f[1] * share[r]) @ f[1].T for f, r in zip(fits, rows)], axis=0)
    lam, vec = np.linalg.eigh(dev.T @ dev / len(dev) - noise)
    if lam.max() <= 0:
        return cov, None
    root = vec * np.sqrt(np.clip(lam, 0.0, None))
    part = _view_error_part(jw, res, share, [jw[r][:, a] @ root for r in rows])
    if part is None:
        return cov, None
    spread = part[1] ** 2 * (root @ root.T)
    sd = {names[c]: float(math.sqrt(spread[k, k])) for k, c in enumerate(a)}
    return white_part(jac, cov, share) + part[0], sd


def _own_deviation(jw: np.ndarray, names: Sequence[str], a: list[int], i: int,
                   rows: np.ndarray, residuals: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """View i's own deviation in the intrinsics ``a`` (its rows ``rows`` fitted with those and
    its board pose free), the map from its residuals to it and what its fit leaves."""
    own = a + [k for k, n in enumerate(names) if n.startswith(f"view{i}_")]
    j = jw[rows][:, own]
    solve = np.linalg.pinv(j)
    h = solve @ residuals[rows]
    return h[:len(a)], solve[:len(a)], residuals[rows] - j @ h
