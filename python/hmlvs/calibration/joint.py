"""Joint calibration of the general sensor (``model="opencv"``) from board corners and stripes.

No guess is needed. The steps:

1. intrinsics and per-view board poses from the corners (Zhang's method, ``cv2.calibrateCamera``);
2. with robot poses: the corner numbering made consistent over the views (a checkerboard looks
   the same turned by 180 degrees; the robot's motion tells the two apart), the hand-eye
   transform in closed form (Park and Martin, C++ core) and the board's pose in the base as
   the mean over the views;
3. the laser plane fitted to the stripe points placed on each view's board plane;
4. one Levenberg-Marquardt solve (Ceres) of corner reprojection residuals (px) and laser
   residuals (mm from the laser plane), each divided by its noise, which is estimated from the
   residuals themselves; stripe pixels and corners far off (robust rule) are dropped and the
   solve is repeated.

With robot poses the board poses come from the chain ``inv(hand_from_camera) inv(base_from_hand)
base_from_board`` (``chain`` mode); without them each view's board pose is free (``camera``
mode: intrinsics and laser plane only).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import time
from typing import Any, Iterable, Sequence

import numpy as np

from .. import _core
from .._arrays import check_transform, robust_sigma
from ..data.views import ViewData
from ..geometry.board import BoardSpec, board_pose_from_corners
from ..geometry.transforms import (
    invert_transform,
)
from ..models.opencv import CLASSIC_DISTORTION, DISTORTION_NAMES, OpenCvSensor
from .joint_covariance import (
    camera_mode_covariance,
    chain_covariance,
    inverse_normal,
    weighted_residuals,
)
from .joint_result import JointCalibration
from .joint_setup import (  # noqa: F401 (initial_intrinsics, on_board: re-exported)
    board_plane_points,
    check_distortion,
    consistent_numbering,
    finite_rms,
    fit_plane,
    held_camera,
    initial_intrinsics,
    on_board,
    stripe_kept,
)
from .joint_solve import (
    POSE_DISAGREEMENT,
    ROBUST_K,
    robot_poses_uncertain,
    solve_uncertain_poses,
    solve_weighted,
)


def calibrate_joint(views: Sequence[ViewData], board: Any, image_size: tuple[int, int], *,
                    distortion: Iterable[str] = CLASSIC_DISTORTION,
                    base_from_board: np.ndarray | None = None,
                    use_robot: bool = True, robust: bool = True,
                    max_iterations: int = 100,
                    test: Sequence[ViewData] | None = None,
                    stripe_margin: float | None = None,
                    robot_poses: str = "exact",
                    camera: OpenCvSensor | None = None,
                    hold_hand_eye: bool = False) -> JointCalibration:
    """Calibrate the general sensor from per-view corners and stripe pixels (module doc).

    views : the views (:class:`ViewData`); each needs >= 6 corners, except laser-only views
        (no corners: the stripe on the board's plane, the board unseen, e.g. a frame taken
        with the lights off), which need robot poses (chain mode) and at least 3 views with
        corners beside them; their stripe meets the board plane the chain puts in the base
    board : the board (:class:`BoardSpec`, :class:`hmlvs.Checkerboard` or a mapping with rows,
        cols, square)
    image_size : (width, height)
    distortion : the distortion terms to estimate (others held at 0), e.g. ("k1", "k2")
    base_from_board : the board's pose in the base, when measured (held fixed)
    use_robot : use the views' robot poses (chain mode) when every view has one
    robust : drop corners and stripe pixels beyond 5 robust sigmas and solve again
    test : held-out views: their stripe points' RMS distance from the board plane is reported
        (``test_rms_mm``, see :func:`board_plane_errors`)
    stripe_margin : the stripe pixels used are those whose ray meets the board's plane within
        this many squares of the inner corners' rectangle; None (default): anywhere on the
        plane, as on the sheet a board is printed on (pixels off the plane, e.g. on the
        table beyond a raised board, go as outliers with ``robust``)
    robot_poses : chain mode: "exact" (the default: the views' board poses all follow from
        the robot poses, hand_from_camera and base_from_board) or "uncertain" (each view keeps
        its own board pose, tied to the chain's by the robot pose error it implies, whose
        spread in mm and degrees is estimated with the rest: :func:`solve_uncertain_poses`;
        on renders with robot poses off by 0.3 mm and 0.1 degrees it recovers the focal
        length the exact chain bends by 2 %, but on half of the Blaser sessions' views it
        can still run off to a meaningless hand-eye transform: check ``robot_pose_sigma``)
    camera : an :class:`OpenCvSensor` whose intrinsics, distortion and laser plane are held
        (e.g. a bench session's calibration, :func:`calibrate_views` of views without robot
        poses): only the hand-eye transform and the board's pose are estimated; needs robot
        poses and the same image size
    hold_hand_eye : with ``camera``, hold its hand-eye transform too, so that only the board's
        pose (or, without robot poses, each view's) is estimated: :func:`evaluate_sensor`
    """
    start = time.perf_counter()
    board = BoardSpec.of(board)
    terms = check_distortion(distortion)
    uncertain = robot_poses_uncertain(robot_poses)
    session_order = [v.id for v in views]  # per_view keeps it (laser-only views go last below)
    views, laser_only, chain, base_from_board = _split_views(views, use_robot, base_from_board)
    intr, cam_poses, cv_rms = (
        initial_intrinsics(views, board, image_size, terms) if camera is None else
        held_camera(camera, views, board, image_size, chain, evaluate=hold_hand_eye))
    su = _Setup(views=views, cam_poses=cam_poses, intr=intr, cv_rms=cv_rms, chain=chain,
                corner_index=[np.asarray(v.corner_index, int) for v in views], board=board)
    if chain:
        held = np.asarray(camera.hand_from_camera, float) if hold_hand_eye and camera \
            is not None else None
        _chain_setup(su, board, laser_only, base_from_board, held)
    _laser_setup(su, board, stripe_margin, camera, robust)
    state, opts = _initial_state(su, terms, base_from_board, camera, hold_hand_eye,
                                 max_iterations)
    keep_c = [np.ones(len(ci), bool) for ci in su.corner_index]
    keep_l = [np.ones(len(p), bool) for p in su.laser_px] if su.inlier is None else \
        list(su.inlier)
    result, state = solve_weighted(su.make_views, state, opts, keep_c, keep_l, robust)
    pose_sigma = None
    if uncertain and chain:
        # every view keeps its own board pose, tied to the chain's by the robot pose error it
        # implies
        state.camera_from_board = [
            p if len(su.corner_index[i]) else invert_transform(state.hand_from_camera)
            @ invert_transform(su.bfh[i]) @ state.base_from_board
            for i, p in enumerate(su.cam_poses)]
        result, state, pose_sigma = solve_uncertain_poses(su.make_views, state, opts, keep_c,
                                                           keep_l, robust)
    out = _assemble(su, board, image_size, state, opts, result, keep_c, keep_l, pose_sigma,
                    test)
    out.per_view = {k: out.per_view[k] for k in session_order if k in out.per_view}
    out.seconds = time.perf_counter() - start
    return out


@dataclass
class _Setup:
    """What :func:`calibrate_joint` builds before its solve: the views (laser-only views last),
    their robot poses, board poses, corner numbering and stripe pixels on the board, the
    initial intrinsics and laser plane, and what it has to say about them."""

    views: list[ViewData]
    cam_poses: list[np.ndarray]
    intr: np.ndarray
    cv_rms: float
    chain: bool
    corner_index: list[np.ndarray]
    board: BoardSpec
    bfh: list[np.ndarray] = field(default_factory=list)
    hand_eye: np.ndarray | None = None
    bfb0: np.ndarray | None = None
    flipped: list[str] = field(default_factory=list)
    rejected: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    laser_px: list[np.ndarray] = field(default_factory=list)
    plane_pts: list[np.ndarray] = field(default_factory=list)
    plane: np.ndarray | None = None
    plane_res: list[np.ndarray] = field(default_factory=list)
    sigma_l0: float = 0.0
    inlier: list[np.ndarray] | None = None

    def make_views(self, keep_c: list[np.ndarray], keep_l: list[np.ndarray]) -> list[Any]:
        """The solver's views with the corners and stripe pixels the masks keep."""
        out = []
        for i, v in enumerate(self.views):
            out.append(_core._JointView(
                self.bfh[i] if self.chain else np.eye(4),
                np.ascontiguousarray(np.asarray(v.corner_pixels, float).reshape(-1, 2)[
                    keep_c[i]]),
                np.ascontiguousarray(self.board.points(self.corner_index[i][keep_c[i]])),
                np.ascontiguousarray(self.laser_px[i][keep_l[i]])))
        return out


def _split_views(views: Sequence[ViewData], use_robot: bool,
                 base_from_board: np.ndarray | None
                 ) -> tuple[list[ViewData], list[ViewData], bool, np.ndarray | None]:
    """The views with corners, the laser-only views, whether the robot chain is used, and the
    checked base_from_board; ValueError naming what is missing."""
    laser_only = [v for v in views if len(v.corner_index) == 0]
    views = [v for v in views if len(v.corner_index) > 0]
    if len(views) < 3:
        raise ValueError(f"the joint calibration needs at least 3 views with a detected board, "
                         f"got {len(views)}")
    for v in views:
        if len(v.corner_index) < 6:
            raise ValueError(f"view {v.id}: {len(v.corner_index)} corners; each view needs at "
                             "least 6")
    chain = use_robot and all(v.base_from_hand is not None for v in views + laser_only)
    for v in laser_only:
        if not chain:
            raise ValueError(f"view {v.id} has no corners: a laser-only view needs the robot "
                             "poses of every view (chain mode)")
        if len(v.laser_pixels) == 0:
            raise ValueError(f"view {v.id} has neither corners nor stripe pixels")
    if base_from_board is not None:
        base_from_board = check_transform(base_from_board, "base_from_board")
        if not chain:
            raise ValueError("a given base_from_board needs robot poses for every view")
    return views, laser_only, chain, base_from_board


def _chain_setup(su: _Setup, board: BoardSpec, laser_only: list[ViewData],
                 base_from_board: np.ndarray | None, held_hand_eye: np.ndarray | None) -> None:
    """Chain mode: the corner numbering made consistent with the robot motion (views it cannot
    decide are left out), the hand-eye transform (Park-Martin, or the held one), the board's
    pose in the base, and the laser-only views appended with their board seen through the
    chain."""
    su.bfh = [check_transform(v.base_from_hand, f"view {v.id} base_from_hand")
              for v in su.views]
    flips = consistent_numbering(su.bfh, su.cam_poses, board)
    if any(fl is None for fl in flips):
        flips = _leave_out_undecided(su, flips)
    n_corners = board.rows * board.cols
    for i, fl in enumerate(flips):
        if fl:
            su.cam_poses[i] = su.cam_poses[i] @ board.flip()
            su.corner_index[i] = n_corners - 1 - su.corner_index[i]
            su.flipped.append(su.views[i].id)
    su.hand_eye = held_hand_eye if held_hand_eye is not None else \
        _core._hand_eye_park_martin(su.bfh, su.cam_poses)
    su.bfb0 = base_from_board if base_from_board is not None else _core._mean_transform(
        [su.bfh[i] @ su.hand_eye @ su.cam_poses[i] for i in range(len(su.views))])
    for v in laser_only:
        t = check_transform(v.base_from_hand, f"view {v.id} base_from_hand")
        su.views.append(v)
        su.bfh.append(t)
        su.cam_poses.append(invert_transform(su.hand_eye) @ invert_transform(t) @ su.bfb0)
        su.corner_index.append(np.zeros(0, int))


def _leave_out_undecided(su: _Setup, flips: list[bool | None]) -> list[bool | None]:
    """Drop the views whose numbering neither way agrees with the robot motion (each with its
    reason); ValueError when fewer than 3 are left. Returns the kept views' flips."""
    for i, fl in enumerate(flips):
        if fl is None:
            su.rejected[su.views[i].id] = (
                "its corner numbering cannot be decided: neither the board's numbering nor its "
                "180-degree turn agrees with the other views' robot motion (or both do)")
    keep = [i for i in range(len(su.views)) if flips[i] is not None]
    if len(keep) < 3:
        raise ValueError(
            f"the images disagree with their robot poses: the board's orientation fits the "
            f"robot motion in only {len(keep)} of {len(su.views)} views (left out: "
            f"{', '.join(su.rejected)}); check that the images belong to these poses (same "
            "session, same order), the poses' convention and that the board stayed put")
    su.warnings.append("views left out, their corner numbering undecided: "
                       + ", ".join(su.rejected))
    su.views, su.bfh = [su.views[i] for i in keep], [su.bfh[i] for i in keep]
    su.cam_poses = [su.cam_poses[i] for i in keep]
    su.corner_index = [su.corner_index[i] for i in keep]
    return [flips[i] for i in keep]


def _laser_setup(su: _Setup, board: BoardSpec, stripe_margin: float | None,
                 camera: OpenCvSensor | None, robust: bool) -> None:
    """The stripe pixels on each view's board plane and the initial laser plane through them
    (the held camera's, if any); with ``robust`` the pixels far off it (reflections, stray
    light) go before the first solve. One entry per view in every list (empty where a view
    has no stripe pixel on the board), so that the per-view masks stay in step."""
    for i, v in enumerate(su.views):
        px = np.asarray(v.laser_pixels, float).reshape(-1, 2)
        if len(px) == 0:
            su.laser_px.append(px)
            su.plane_pts.append(np.empty((0, 3)))
            continue
        pts, xy = board_plane_points(su.intr, su.cam_poses[i], px)
        keep = stripe_kept(board, xy, stripe_margin) & np.isfinite(pts).all(axis=1)
        su.laser_px.append(px[keep])
        su.plane_pts.append(pts[keep])
    all_pts = np.concatenate(su.plane_pts)
    if len(all_pts) < 10:
        raise ValueError(f"only {len(all_pts)} stripe pixels fall on the board over all views; "
                         "the laser plane needs stripe points on the board in several views")
    su.plane = fit_plane(all_pts) if camera is None else np.asarray(camera.laser_plane, float)
    su.plane_res = [p @ su.plane[:3] + su.plane[3] for p in su.plane_pts]
    su.sigma_l0 = robust_sigma(np.concatenate(su.plane_res))
    if robust and su.sigma_l0 > 0:
        su.inlier = [np.abs(r) <= ROBUST_K * su.sigma_l0 for r in su.plane_res]
        if camera is None:
            su.plane = fit_plane(np.concatenate(
                [p[k] for p, k in zip(su.plane_pts, su.inlier)]))


def _initial_state(su: _Setup, terms: tuple[str, ...], base_from_board: np.ndarray | None,
                   camera: OpenCvSensor | None, hold_hand_eye: bool, max_iterations: int
                   ) -> tuple[Any, Any]:
    """The solver's starting state and options. The noise levels (the residuals' weights)
    start at the set-up's residuals (OpenCV's RMS is per corner, over both axes) and are
    re-estimated from the solve's by :func:`solve_weighted`."""
    state = _core._JointState()
    state.intrinsics = su.intr
    state.laser_plane = su.plane
    if su.chain:
        state.hand_from_camera = su.hand_eye
        state.base_from_board = su.bfb0
    else:
        state.camera_from_board = su.cam_poses
    opts = _core._JointOptions()
    opts.chain = su.chain
    opts.board_pose_known = base_from_board is not None
    opts.fixed = [False] * 4 + [name not in terms for name in DISTORTION_NAMES]
    if camera is not None:
        opts.fixed = [True] * len(opts.fixed)
        opts.plane_known = True
        opts.hand_eye_known = bool(hold_hand_eye and su.chain)
    elif hold_hand_eye:
        raise ValueError("hold_hand_eye needs camera= (the calibration whose parts are held)")
    opts.max_iterations = int(max_iterations)
    opts.corner_sigma = max(su.cv_rms / math.sqrt(2), 1e-3)
    kept = np.concatenate(su.plane_res)
    if su.inlier is not None:
        kept = kept[np.concatenate([k for k in su.inlier if len(k)])]
    opts.laser_sigma = max(finite_rms(kept) if su.sigma_l0 > 0 else 0.1, 1e-4)
    return state, opts


def _assemble(su: _Setup, board: BoardSpec, image_size: tuple[int, int], state: Any, opts: Any,
              result: Any, keep_c: list[np.ndarray], keep_l: list[np.ndarray],
              pose_sigma: tuple[float, float] | None,
              test: Sequence[ViewData] | None) -> JointCalibration:
    """The solution with its covariance, per-view account, residuals and warnings."""
    jv = su.make_views(keep_c, keep_l)
    corners_r, laser_r = _core._evaluate_joint(jv, state, opts)
    pose_err = _core._joint_pose_errors(jv, state, opts) if pose_sigma else []
    jac, names = _core._joint_jacobian(jv, state, opts)
    # The Jacobian's rows: the corners (2 each), then the stripe pixels, then any pose prior.
    # Neighbouring stripe pixels' errors are correlated (speckle, the smoothing along the
    # stripe, the blur): counted as independent they would make the covariance claim a
    # precision the data do not have (renders: 7-15 pixels act as one; the two halves of a
    # session's views then disagreed by up to 4 times the uncertainty claimed).
    stripe_corr = stripe_correlation(laser_r)
    n_c = 2 * int(sum(int(k.sum()) for k in keep_c))
    n_l = int(sum(len(r) for r in laser_r))
    jac = np.array(jac, float)
    jac[n_c:n_c + n_l] /= math.sqrt(stripe_corr)
    cov, rank, cond = inverse_normal(jac)
    counted = view_cameras = None
    if su.chain and not pose_sigma:
        cov, counted = chain_covariance(jv, state, opts, jac, cov, stripe_corr,
                                        weighted_residuals(corners_r, laser_r, opts),
                                        (su.cv_rms / math.sqrt(2), su.sigma_l0),
                                        _own_poses(su, board, state, keep_c))
    if not su.chain:
        cov, view_cameras = camera_mode_covariance(
            jac, list(names), cov, weighted_residuals(corners_r, laser_r, opts), stripe_corr)
        _warn_view_cameras(su, view_cameras, np.asarray(state.intrinsics, float))
    std = {n: float(math.sqrt(max(cov[k, k], 0.0))) for k, n in enumerate(names)}
    if rank < len(names):
        su.warnings.append(f"the data determine {rank} of the {len(names)} unknowns; add views "
                           "with the board at other angles")
    _warn_pose_disagreement(su, corners_r, pose_sigma, held=bool(opts.hand_eye_known))
    sensor = _sensor_of(state, image_size, su.chain)
    c_all = np.concatenate([c.ravel() for c in corners_r])
    test_rms = None
    if test:
        errs = board_plane_errors(sensor, test, board, use_robot=su.chain)
        e = np.concatenate(list(errs.values())) if errs else np.empty(0)
        test_rms = finite_rms(e) if e.size else None
    return JointCalibration(
        sensor=sensor, std=std, names=list(names), covariance=cov,
        corner_rms_px=finite_rms(c_all) * math.sqrt(2),
        laser_rms_mm=finite_rms(np.concatenate(laser_r)),
        corner_sigma_px=float(opts.corner_sigma), laser_sigma_mm=float(opts.laser_sigma),
        per_view=_per_view(su, keep_c, keep_l, corners_r, laser_r, pose_err),
        dropped={"corners": int(sum((~k).sum() for k in keep_c)),
                 "laser_pixels": int(sum((~k).sum() for k in keep_l))},
        mode="chain" if su.chain else "camera", rank=rank, num_unknowns=len(names),
        condition=cond, termination=result.termination, iterations=int(result.iterations),
        seconds=0.0, flipped=su.flipped,
        camera_from_board={} if su.chain else {v.id: state.camera_from_board[i]
                                               for i, v in enumerate(su.views)},
        warnings=su.warnings, test_rms_mm=test_rms, test_views=len(test or ()),
        robot_pose_sigma=pose_sigma, pose_errors_counted=counted,
        view_cameras_counted=view_cameras,
        stripe_correlation=stripe_corr,
        free_rms_px=float(su.cv_rms),
        residuals={v.id: {"corner_pixels": np.asarray(v.corner_pixels, float)[keep_c[i]],
                          "corner_residuals": np.asarray(corners_r[i]),
                          "laser_pixels": su.laser_px[i][keep_l[i]],
                          "laser_residuals": np.asarray(laser_r[i])}
                   for i, v in enumerate(su.views)}, rejected=su.rejected)


def _warn_view_cameras(su: _Setup, spread: dict[str, float] | None,
                       intrinsics: np.ndarray) -> None:
    """Say so when the views fit cameras of their own (their spread counted in camera mode)."""
    if spread is None:
        return
    focal = [spread[n] / intrinsics[k] for k, n in enumerate(("fx", "fy")) if n in spread]
    size = f"focal lengths about {100 * max(focal):.2g} % apart" if focal else "cameras apart"
    su.warnings.append(f"the views fit cameras of their own ({size} from view to view, more "
                       "than the corners' noise explains): is the focus locked (autofocus "
                       "off) and the lens fixed, and did the camera warm up first? (A lens "
                       "that the 5-term distortion model does not fit shows the same.) The "
                       "differences are counted in the uncertainties")


def _own_poses(su: _Setup, board: BoardSpec, state: Any, keep_c: list[np.ndarray]
               ) -> list[np.ndarray | None]:
    """Per view, camera_from_board from its own kept corners with the solved camera
    (``cv2.solvePnP``); None for a laser-only view."""
    st = np.asarray(state.intrinsics, float)
    k = np.array([[st[0], 0, st[2]], [0, st[1], st[3]], [0, 0, 1.0]])
    out: list[np.ndarray | None] = []
    for i, v in enumerate(su.views):
        idx = su.corner_index[i][keep_c[i]]
        out.append(board_pose_from_corners(
            board.points(idx), np.asarray(v.corner_pixels, float).reshape(-1, 2)[keep_c[i]],
            k, st[4:]) if len(idx) else None)
    return out


def _warn_pose_disagreement(su: _Setup, corners_r: Sequence[np.ndarray],
                            pose_sigma: tuple[float, float] | None, held: bool) -> None:
    """A warning when the exact chain fits the corners far worse than free board poses
    (``held``: a calibration evaluated, its camera and hand-eye held)."""
    where = ("the calibration's camera and hand-eye are held, so the difference stays in the "
             "residuals" if held else "the camera and hand-eye absorb the difference")
    chain_rms = finite_rms(np.concatenate([c.ravel() for c in corners_r])) * math.sqrt(2)
    if su.chain and not pose_sigma and chain_rms > POSE_DISAGREEMENT * max(su.cv_rms, 0.05):
        su.warnings.append(
            f"the robot poses disagree with the images: through the robot chain the corners "
            f"lie {chain_rms:.2f} px RMS from their detections, against {su.cv_rms:.2f} px with "
            f"each view's board pose free; {where} (check the poses' timing and convention, "
            "that the board did not move, and the robot's accuracy)")


def _per_view(su: _Setup, keep_c: list[np.ndarray], keep_l: list[np.ndarray],
              corners_r: Sequence[np.ndarray], laser_r: Sequence[np.ndarray],
              pose_err: Sequence[np.ndarray]) -> dict[str, dict[str, float]]:
    """Per view: corners and stripe pixels used, their RMS, and (uncertain robot poses) the
    robot pose error the solve found."""
    per_view = {}
    for i, v in enumerate(su.views):
        per_view[v.id] = {"corners": int(keep_c[i].sum()), "laser_pixels": int(keep_l[i].sum()),
                          "corner_rms_px": finite_rms(corners_r[i].ravel()) * math.sqrt(2),
                          "laser_rms_mm": finite_rms(laser_r[i])}
        if len(pose_err):
            per_view[v.id]["robot_pose_error_mm"] = float(np.linalg.norm(pose_err[i][3:]))
            per_view[v.id]["robot_pose_error_deg"] = math.degrees(
                float(np.linalg.norm(pose_err[i][:3])))
    return per_view


def _sensor_of(state: Any, image_size: tuple[int, int], chain: bool) -> OpenCvSensor:
    """The solver's state as an :class:`OpenCvSensor`."""
    st = state.intrinsics
    return OpenCvSensor(
        camera_matrix=np.array([[st[0], 0, st[2]], [0, st[1], st[3]], [0, 0, 1.0]]),
        dist_coeffs=st[4:], image_size=tuple(image_size), laser_plane=state.laser_plane,
        hand_from_camera=state.hand_from_camera if chain else np.eye(4),
        base_from_board=state.base_from_board if chain else None)


def stripe_correlation(residuals: Sequence[np.ndarray], max_lag: int = 60) -> float:
    """How many neighbouring stripe pixels act as one independent one: per view, the
    residuals' (in their order along the stripe) effective correlation length 1 + 2 sum rho_k
    (their autocorrelation, summed until it first drops to 0, at most ``max_lag`` lags); the
    median over the views with at least 20 residuals, at least 1."""
    lengths = []
    for r in residuals:
        r = np.asarray(r, float)
        r = r[np.isfinite(r)]
        if len(r) < 20:
            continue
        r = r - r.mean()
        v = float(r @ r)
        if v <= 0:
            continue
        total = 1.0
        for k in range(1, min(max_lag, len(r) // 2)):
            rho = float(r[:-k] @ r[k:]) / v
            if rho <= 0:
                break
            total += 2.0 * rho
        lengths.append(total)
    return max(1.0, float(np.median(lengths))) if lengths else 1.0


def board_plane_errors(sensor: OpenCvSensor, views: Sequence[ViewData], board: Any,
                       use_robot: bool = True) -> dict[str, np.ndarray]:
    """Per view, the signed distance (mm) of its stripe points on the board from the board's
    plane: a check of the whole calibration on views it was not fitted to.

    With robot poses (and the sensor's ``base_from_board``) the stripe points are mapped to the
    base and compared with the one static board plane; without them, with the board plane of
    the view's own corners (``solvePnP`` with the calibrated intrinsics)."""

    board = BoardSpec.of(board)
    out: dict[str, np.ndarray] = {}
    intr = sensor.intrinsics_vector()
    for v in views:
        px = np.asarray(v.laser_pixels, float).reshape(-1, 2)
        chain = use_robot and v.base_from_hand is not None and sensor.base_from_board is not None
        if chain:
            cb = (invert_transform(sensor.hand_from_camera)
                  @ invert_transform(v.base_from_hand) @ sensor.base_from_board)
        else:
            cb = board_pose_from_corners(board.points(v.corner_index), v.corner_pixels,
                                         sensor.camera_matrix, sensor.dist_coeffs)
            if cb is None:
                continue
        _, xy = board_plane_points(intr, cb, px) if len(px) else (None, np.empty((0, 2)))
        keep = on_board(board, xy) if len(px) else np.zeros(0, bool)
        pts, valid = sensor.points_in_camera(px[keep], on_invalid="mask") if keep.any() else (
            np.empty((0, 3)), np.zeros(0, bool))
        n, t = cb[:3, 2], cb[:3, 3]
        out[v.id] = (pts[valid] - t) @ n
    return out


def evaluate_sensor(sensor: OpenCvSensor, views: Sequence[ViewData], board: Any,
                    image_size: tuple[int, int], std: dict[str, float] | None = None
                    ) -> JointCalibration:
    """An opencv-model calibration (``sensor``) on a session's views: its camera, laser plane
    and hand-eye transform held, only the board's pose in the base estimated (each view's,
    without robot poses). The result's residuals are the calibration's on these views;
    ``std`` (e.g. the calibration file's) is shown for the held quantities."""
    from dataclasses import replace

    result = calibrate_joint(views, board, image_size, camera=sensor, hold_hand_eye=True)
    return replace(result, std={**(std or {}), **result.std}, evaluated=True)
