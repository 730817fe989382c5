"""The corner and robot-chain checks of a calibration's verdict, for either sensor model.

A :class:`Chain` is what these checks need of a calibration with robot poses: the views'
numbered corners and poses, the hand-eye transform, the board's pose in the base, each
view's own board pose from its corners (``pose_of``: the calibrated camera's PnP) and the
corners' RMS through the chain against that of free board poses. :func:`chain_of_joint`
builds it from the general model's joint calibration, :func:`chain_of_paper` from a
paper-model calibration from images (its board pose measured, in the manifest); the checks
are written once over it.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Callable, Sequence

import numpy as np

from ..calibration.joint import POSE_DISAGREEMENT
from ..geometry.board import BoardSpec, board_pose_from_corners
from ..geometry.transforms import invert_transform, rotation_angle
from .checks import (
    BOARD_SPREAD_DEG,
    BOARD_SPREAD_MM,
    CORNER_RMS_LIMIT_PX,
    HAND_EYE_DEG,
    HAND_EYE_MM,
    Check,
    camera_from_board_of,
    coverage_checks,
    laser_check,
    lens_check,
    make_check,
    unknowns_check,
    variety_check,
)


@dataclass
class Chain:
    """A calibration's robot chain as the checks see it.

    views : the views with corners (:class:`~hmlvs.data.views.ViewData`), their corners
        numbered as the calibration numbers the board
    board : the board (rows, cols, square)
    hand_from_camera, base_from_board : the calibration's (4 x 4, mm)
    pose_of : (board points (k, 3), pixels (k, 2)) -> camera_from_board (4 x 4) from one
        view's corners with the calibrated camera, or None
    corner_rms_px : the corners' RMS through the chain (px)
    free_rms_px : the corners' RMS with every view's board pose free (Zhang's), or None
    rejected : views left out, with the reason
    """

    views: list[Any]
    board: BoardSpec
    hand_from_camera: np.ndarray
    base_from_board: np.ndarray
    pose_of: Callable[[np.ndarray, np.ndarray], np.ndarray | None]
    corner_rms_px: float
    free_rms_px: float | None
    rejected: dict[str, str]


def chain_of_joint(result: Any, views: Sequence[Any], board: Any) -> Chain | None:
    """The chain of a general-model calibration (``calibrate_joint``'s result) on the views
    it was given; None in camera mode (no robot poses)."""
    from dataclasses import replace

    if result.mode != "chain":
        return None
    board = BoardSpec.of(board)
    s = result.sensor
    n = board.rows * board.cols
    used = []
    for v in views:
        if v.id not in result.per_view or len(v.corner_index) < 6 or v.base_from_hand is None:
            continue
        idx = np.asarray(v.corner_index, int)
        used.append(replace(v, corner_index=n - 1 - idx if v.id in result.flipped else idx))

    def pose_of(obj: np.ndarray, px: np.ndarray) -> np.ndarray | None:
        return board_pose_from_corners(obj, px, s.camera_matrix, s.dist_coeffs)

    return Chain(used, board, s.hand_from_camera, s.base_from_board, pose_of,
                 result.corner_rms_px, getattr(result, "free_rms_px", None),
                 dict(result.rejected))


def chain_of_paper(result: Any, views: Sequence[Any], board: BoardSpec,
                   base_from_board: np.ndarray, image_size: tuple[int, int] | None
                   ) -> Chain | None:
    """The chain of a paper-model calibration from images (:class:`CalibrationResult`): the
    used pairs' corners (numbered in the manifest's board, whose pose in the base is
    measured) projected with the paper's camera through their robot poses; each view's own
    board pose by PnP on its corners' undistorted rays. None with fewer than 3 views."""
    from ..calibration.joint import initial_intrinsics
    from ..models.paper import hand_from_camera, project, rays_in_camera

    views = [v for v in views if len(v.corner_index) >= 6 and v.base_from_hand is not None]
    if len(views) < 3:
        return None
    q = result.params
    err = []
    for v in views:
        pts = board.points(v.corner_index) @ base_from_board[:3, :3].T + base_from_board[:3, 3]
        px, ok = project(q, pts, np.repeat(np.asarray(v.base_from_hand, float)[None],
                                           len(pts), axis=0))
        err.append(np.where(ok[:, None], px - np.asarray(v.corner_pixels, float), np.nan))
    e = np.concatenate(err)
    rms = float(np.sqrt(np.nanmean(np.sum(e**2, axis=1)))) if np.isfinite(e).any() else \
        float("inf")
    free = None
    if image_size is not None:
        try:
            free = float(initial_intrinsics(views, board, image_size)[2])
        except ValueError:
            free = None

    def pose_of(obj: np.ndarray, px: np.ndarray) -> np.ndarray | None:
        rays = rays_in_camera(q, px)
        return board_pose_from_corners(obj, rays[:, :2] / rays[:, 2:3], np.eye(3),
                                       np.zeros(5))

    return Chain(views, board, hand_from_camera(q), np.asarray(base_from_board, float),
                 pose_of, rms, free, {})


def board_spread(chain: Chain) -> dict[str, tuple[float, float]]:
    """Per view: how far its own board-in-base estimate (its corners' board pose carried
    through its robot pose and the hand-eye transform) lies from the calibration's one
    board pose: (mm at the board's centre, degrees)."""
    b = chain.board
    centre = np.array([(b.rows - 1) * b.square / 2, (b.cols - 1) * b.square / 2, 0.0, 1.0])
    bfb = chain.base_from_board
    out = {}
    for v in chain.views:
        cb = chain.pose_of(b.points(v.corner_index), np.asarray(v.corner_pixels, float))
        if cb is None:
            continue
        bib = np.asarray(v.base_from_hand, float) @ chain.hand_from_camera @ cb
        dt = float(np.linalg.norm((bib @ centre - bfb @ centre)[:3]))
        da = math.degrees(rotation_angle(bib[:3, :3] @ bfb[:3, :3].T))
        out[v.id] = (dt, da)
    return out


def pose_error_mm(chain: Chain) -> float:
    """The robot's pose error as it reaches measured points (mm RMS, 3D): the RMS distance
    at the board's centre between each view's own board pose carried to the base and the
    calibration's one board (:func:`board_spread`). A view's robot pose error moves its
    board estimate there as it moves the points it measures at that range (the stripe
    crosses the board); the views' own pose error (from their corners, a few hundredths of
    a mm on renders) is counted in, so it errs on the safe side. NaN without views."""
    spread = board_spread(chain)
    if not spread:
        return float("nan")
    return float(np.sqrt(np.mean([d**2 for d, _ in spread.values()])))


def hand_eye_residuals(chain: Chain) -> tuple[float, float, int]:
    """The hand-eye equation A X = X B over every pair of views: A the hand's motion (robot
    poses), B the camera's (each view's board pose from its corners), X the calibrated
    hand_from_camera. The RMS of the residual transform (A X)(X B)^-1: its translation
    (mm, at the flange) and rotation (degrees), and the number of pairs."""
    x = chain.hand_from_camera
    cams, hands = [], []
    for v in chain.views:
        cb = chain.pose_of(chain.board.points(v.corner_index),
                           np.asarray(v.corner_pixels, float))
        if cb is not None:
            cams.append(cb)
            hands.append(np.asarray(v.base_from_hand, float))
    dt, da = [], []
    for i in range(len(cams)):
        for j in range(i + 1, len(cams)):
            a = invert_transform(hands[i]) @ hands[j]
            b = cams[i] @ invert_transform(cams[j])
            e = a @ x @ invert_transform(x @ b)
            dt.append(float(np.linalg.norm(e[:3, 3])))
            da.append(math.degrees(rotation_angle(e[:3, :3])))
    if not dt:
        return float("nan"), float("nan"), 0
    return (float(np.sqrt(np.mean(np.square(dt)))), float(np.sqrt(np.mean(np.square(da)))),
            len(dt))


def corner_checks(corner_rms: float, free_rms: float | None, through_chain: bool
                  ) -> list[Check]:
    """The corners' reprojection against the detector's noise, and (through the robot
    chain) against each view's own board pose."""
    where = "through the robot chain" if through_chain else "with each view's board pose free"
    checks = [make_check(
        "corner_rms", corner_rms, CORNER_RMS_LIMIT_PX, "px",
        "corner detectors locate corners to a few hundredths to a few tenths of a pixel; "
        "beyond 1 px the poses, the board or the camera model do not fit the images",
        f"the board corners lie {corner_rms:.2f} px RMS from their detections {where}, more "
        f"than the {CORNER_RMS_LIMIT_PX:g} px a correct calibration leaves")]
    if through_chain and free_rms is not None and math.isfinite(free_rms):
        ratio = corner_rms / max(free_rms, 0.05)
        checks.append(make_check(
            "chain_vs_free_corner_rms", ratio, POSE_DISAGREEMENT, "",
            "with correct robot poses the chain fits the corners about as well as Zhang's "
            "calibration with every view's board pose free (renders: within 10 %)",
            f"the robot chain fits the corners {ratio:.1f} times worse than each view's own "
            f"board pose ({corner_rms:.2f} against {free_rms:.2f} px): the robot poses "
            "disagree with the images"))
    return checks


def chain_checks(chain: Chain) -> list[Check]:
    """The robot chain's consistency: the corners through it, the spread of the views'
    board-in-base estimates, the hand-eye equation A X = X B over pairs of views, and the
    views left out."""
    checks = corner_checks(chain.corner_rms_px, chain.free_rms_px, True)
    spread = board_spread(chain)
    if spread:
        dt = np.array([a for a, _ in spread.values()])
        da = np.array([b for _, b in spread.values()])
        rt, ra = float(np.sqrt(np.mean(dt**2))), float(np.sqrt(np.mean(da**2)))
        worst = sorted(spread, key=lambda k: -spread[k][0])[:3]
        checks.append(make_check(
            "board_spread_mm", rt, BOARD_SPREAD_MM, "mm",
            "each view's board pose carried to the base must land on the one board: a "
            "robot's absolute accuracy (0.1-1 mm) plus one view's pose error",
            f"the views put the board {rt:.2f} mm RMS apart in the robot base (most: "
            f"{', '.join(worst)}): the board moved or the poses do not match the images"))
        checks.append(make_check(
            "board_spread_deg", ra, BOARD_SPREAD_DEG, "deg",
            "as board_spread_mm, for the board's orientation (a robot's orientation "
            "accuracy is a few hundredths of a degree)",
            f"the views turn the board {ra:.2f} degrees RMS apart in the robot base"))
    checks += _hand_eye_checks(chain)
    n_rej = len(chain.rejected)
    checks.append(make_check(
        "views_rejected", n_rej, 0, "views",
        "a view is rejected when its board's orientation fits its robot pose under neither "
        "corner numbering: its image and its pose disagree",
        f"{n_rej} view(s) were left out because their images disagree with their robot "
        f"poses ({', '.join(chain.rejected)})"))
    return checks


def _hand_eye_checks(chain: Chain) -> list[Check]:
    ht, ha, pairs = hand_eye_residuals(chain)
    if not pairs:
        return []
    return [make_check(
        "hand_eye_axxb_mm", ht, HAND_EYE_MM, "mm",
        "the hand's motion between two views and the camera's (from their corners) must "
        "agree through the hand-eye transform (A X = X B); each pair's residual carries "
        "two views' pose errors: sqrt(2) times board_spread_mm's limit",
        f"the hand-eye equation A X = X B leaves {ht:.2f} mm RMS over {pairs} pairs of "
        "views: the robot's motions do not match the camera's"), make_check(
        "hand_eye_axxb_deg", ha, HAND_EYE_DEG, "deg",
        "as hand_eye_axxb_mm, for the rotation: sqrt(2) times board_spread_deg's limit",
        f"the hand-eye equation A X = X B leaves {ha:.2f} degrees RMS over {pairs} "
        "pairs of views")]


def joint_checks(result: Any, views: Sequence[Any], board: Any) -> list[Check]:
    """The checks of a general-model calibration (:class:`JointCalibration`) on the views it
    was given (rejected ones included, to count them)."""
    board = BoardSpec.of(board)
    used = [v for v in views if v.id in result.per_view]
    laser_sets = [result.residuals[v.id]["laser_pixels"] for v in used
                  if v.id in result.residuals]
    corner_sets = [result.residuals[v.id]["corner_pixels"] for v in used
                   if v.id in result.residuals]
    chain = chain_of_joint(result, views, board)
    # a lens the distortion terms cannot follow spoils every fit after it: its check comes
    # first, so that the verdict's first reason is the cure
    checks = lens_check(result, used, board)
    checks += (chain_checks(chain) if chain is not None else
               corner_checks(result.corner_rms_px, None, False))
    checks += laser_check(result, used, laser_sets)
    checks += coverage_checks(corner_sets, laser_sets, tuple(result.sensor.image_size))
    rots = [cb[:3, :3] for cb in (camera_from_board_of(result, v) for v in used)
            if cb is not None]
    checks.append(variety_check(rots))
    checks.append(unknowns_check(result.rank, result.num_unknowns))
    return checks
