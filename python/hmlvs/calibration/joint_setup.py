"""The joint calibration's set-up (:func:`hmlvs.calibration.joint.calibrate_joint`, steps 1 to 3
of its module doc): initial intrinsics and board poses from the corners, a held camera's
board poses, the corner numbering made consistent with the robot motion, and the stripe
pixels placed on each view's board plane with the initial laser plane through them."""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from .. import _core
from .._opencv import calibrate_camera
from ..data.views import ViewData
from ..geometry.board import BoardSpec, board_pose_from_corners
from ..geometry.transforms import (
    invert_transform,
    make_transform,
    rotation_angle,
    rotation_from_vector,
)
from ..models.opencv import CLASSIC_DISTORTION, DISTORTION_NAMES, OpenCvSensor


def _cv_flags(distortion: Sequence[str]) -> int:
    import cv2

    flags = 0
    if "k3" not in distortion:
        flags |= cv2.CALIB_FIX_K3
    if "k2" not in distortion:
        flags |= cv2.CALIB_FIX_K2
    if "k1" not in distortion:
        flags |= cv2.CALIB_FIX_K1
    if "p1" not in distortion and "p2" not in distortion:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    if {"k4", "k5", "k6"} & set(distortion):
        flags |= cv2.CALIB_RATIONAL_MODEL
        for name, fix in (("k4", cv2.CALIB_FIX_K4), ("k5", cv2.CALIB_FIX_K5),
                          ("k6", cv2.CALIB_FIX_K6)):
            if name not in distortion:
                flags |= fix
    if "s1" in distortion:
        flags |= cv2.CALIB_THIN_PRISM_MODEL
    return flags


#: the tilted (Scheimpflug) sensor's angles. Zhang's start leaves them at 0 and
#: :func:`corner_fit` frees them: OpenCV's CALIB_TILTED_MODEL took 1.14 s against 0.03 s for 20
#: synthetic views (the fit here about 0.05 s), to the same corner RMS.
TILT = ("taux", "tauy")


def corner_fit(views: Sequence[ViewData], board: BoardSpec, intrinsics: np.ndarray,
               camera_from_board: Sequence[np.ndarray], terms: Sequence[str]
               ) -> tuple[np.ndarray, list[np.ndarray], float]:
    """The corners alone, every view's board pose free (as ``cv2.calibrateCamera``), refined
    by the C++ joint solve from ``intrinsics`` (the core's 18) and the views' poses with fx,
    fy, cx, cy and the distortion ``terms`` free: the intrinsics, poses and RMS reprojection
    error (px, per corner over both axes, as OpenCV's)."""
    jv = [_core._JointView(np.eye(4), np.ascontiguousarray(np.asarray(
        v.corner_pixels, float).reshape(-1, 2)), np.ascontiguousarray(board.points(
            v.corner_index)), np.zeros((0, 2))) for v in views]
    state = _core._JointState()
    state.intrinsics = np.asarray(intrinsics, float)
    state.camera_from_board = [np.asarray(p, float) for p in camera_from_board]
    opts = _core._JointOptions()
    opts.chain = False
    opts.laser = False
    # the tilt's valley is long: exact corners of a sensor tilted 14 degrees took 174-185 steps
    opts.max_iterations = 500
    opts.fixed = [False] * 4 + [name not in terms for name in DISTORTION_NAMES]
    state = _core._solve_joint(jv, state, opts).state
    corners = np.concatenate([c.reshape(-1, 2) for c in _core._evaluate_joint(jv, state,
                                                                              opts)[0]])
    rms = float(np.sqrt(np.mean(np.sum(corners ** 2, axis=1))))
    return np.array(state.intrinsics), [np.array(p) for p in state.camera_from_board], rms


def check_distortion(distortion: Iterable[str]) -> tuple[str, ...]:
    terms = tuple(distortion)
    bad = [t for t in terms if t not in DISTORTION_NAMES]
    if bad:
        raise ValueError(f"unknown distortion term {bad[0]!r}; choose among "
                         f"{', '.join(DISTORTION_NAMES)}")
    if ("p1" in terms) != ("p2" in terms):
        raise ValueError("the tangential terms p1 and p2 go together: give both or neither")
    prism = [t for t in ("s1", "s2", "s3", "s4") if t in terms]
    if prism and len(prism) < 4:
        raise ValueError("the thin prism's terms s1, s2, s3 and s4 go together (as in OpenCV): "
                         "give all four or none")
    if ("taux" in terms) != ("tauy" in terms):
        raise ValueError("the tilted sensor's angles taux and tauy go together (as in OpenCV): "
                         "give both or neither")
    return terms


def initial_intrinsics(views: Sequence[ViewData], board: BoardSpec, image_size: tuple[int, int],
                       distortion: Sequence[str] = CLASSIC_DISTORTION
                       ) -> tuple[np.ndarray, list[np.ndarray], float]:
    """Zhang's method (``cv2.calibrateCamera``, with the rational and thin-prism models when
    ``distortion`` names their terms; the tilted sensor's angles by :func:`corner_fit` from
    there): the 18 intrinsics of the C++ core, each view's camera_from_board and the RMS
    reprojection error (px)."""
    if not set(TILT) & set(distortion):
        return _zhang(views, board, image_size, _cv_flags(distortion))
    # Zhang's distortion terms cannot follow a strong tilt and may run off with it (fx 5,516
    # px against 1,100 on one of 60 synthetic sessions tilted 14 degrees): the tilt's fit
    # starts from there and from a pinhole alone, and keeps the better
    fits = [corner_fit(views, board, *_zhang(views, board, image_size, flags)[:2], distortion)
            for flags in (_cv_flags(distortion), _cv_flags(()))]  # the latter: a pinhole
    return min(fits, key=lambda f: f[2])


def _zhang(views: Sequence[ViewData], board: BoardSpec, image_size: tuple[int, int],
           flags: int) -> tuple[np.ndarray, list[np.ndarray], float]:
    """``cv2.calibrateCamera`` with ``flags``: the core's 18 intrinsics, the views' poses and
    the RMS (px)."""
    obj = [board.points(v.corner_index).astype(np.float32) for v in views]
    img = [np.asarray(v.corner_pixels, np.float32).reshape(-1, 1, 2) for v in views]
    rms, k, dist, rvecs, tvecs = calibrate_camera(obj, img, tuple(int(s) for s in image_size),
                                                     None, None, flags=flags)
    d = np.zeros(len(DISTORTION_NAMES))
    n = min(d.size, dist.size)
    d[:n] = dist.ravel()[:n]
    intr = np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2], *d])
    poses = [make_transform(rotation_from_vector(r), t) for r, t in zip(rvecs, tvecs)]
    return intr, poses, float(rms)


def consistent_numbering(base_from_hand: Sequence[np.ndarray],
                         camera_from_board: Sequence[np.ndarray], board: BoardSpec,
                         margin: float = math.radians(2.0)) -> list[bool | None]:
    """Which views' corner numbering to turn by 180 degrees so that all views agree.

    A turned numbering turns the view's board pose by 180 degrees about the board's normal.
    Hand-eye calibration needs one board frame in every view. The test needs no hand-eye
    estimate: for any two views the robot's relative rotation and the camera's relative
    rotation have the same angle (A X = X B), so each view takes the numbering under which
    these angles agree best with the other views (repeated until no view changes).

    Returns per view True (turn it), False (keep it) or None: the numbering cannot be decided,
    because neither numbering agrees with the other views within ``margin`` (rad, median
    angle disagreement; e.g. a wrong robot pose) or both do (a motion that cannot tell them
    apart). Such a view must be left out, never guessed. A board whose ids number it
    (``board.unambiguous``, ChArUco) is never turned: all False."""
    n = len(camera_from_board)
    if board.unambiguous:
        return [False] * n
    f = board.flip()
    a_angle = np.array([[rotation_angle((invert_transform(base_from_hand[i])
                                         @ base_from_hand[j])[:3, :3])
                         for j in range(n)] for i in range(n)])
    flips = [False] * n

    def pose(i: int, flipped: bool) -> np.ndarray:
        return camera_from_board[i] @ f if flipped else camera_from_board[i]

    def score(j: int, flipped: bool) -> float:
        cj = pose(j, flipped)
        d = [abs(rotation_angle((pose(i, flips[i]) @ invert_transform(cj))[:3, :3])
                 - a_angle[i, j])
             for i in range(n) if i != j]
        return float(np.median(d)) if d else 0.0

    for _ in range(3):
        changed = False
        for j in range(n):
            keep, turn = score(j, flips[j]), score(j, not flips[j])
            if turn < 0.5 * keep:
                flips[j] = not flips[j]
                changed = True
        if not changed:
            break
    # Both labellings are valid board frames; keep the majority's.
    if sum(flips) > n / 2:
        flips = [not x for x in flips]
    agree = [(score(j, flips[j]) <= margin, score(j, not flips[j]) <= margin) for j in range(n)]
    return [fl if ok and not other else None for fl, (ok, other) in zip(flips, agree)]


def board_plane_points(intr: np.ndarray, camera_from_board: np.ndarray, pixels: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points where the pixels' rays meet the board plane, and their board-frame
    (x, y) coordinates; NaN where a ray does not meet it in front of the camera."""
    und = _core._general_undistort(intr, np.ascontiguousarray(pixels, float)).pixels
    rays = np.c_[und, np.ones(len(und))]
    n = camera_from_board[:3, 2]
    t = camera_from_board[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = (n @ t) / (rays @ n)
    depth[~(depth > 0)] = np.nan
    pts = rays * depth[:, None]
    board_xy = ((pts - t) @ camera_from_board[:3, :3])[:, :2]
    return pts, board_xy


def on_board(board: BoardSpec, board_xy: np.ndarray, margin: float = 0.5) -> np.ndarray:
    """Which board-frame points lie on the board: within ``margin`` squares of the inner
    corners' rectangle (the printed board extends one square beyond them)."""
    m = margin * board.square
    x, y = board_xy[:, 0], board_xy[:, 1]
    return ((x >= -m) & (x <= (board.rows - 1) * board.square + m)
            & (y >= -m) & (y <= (board.cols - 1) * board.square + m))


def stripe_kept(board: BoardSpec, board_xy: np.ndarray, margin: float | None) -> np.ndarray:
    """The stripe points a calibration uses: on the board's plane within ``margin`` squares
    of the inner corners, or anywhere on the plane when ``margin`` is None."""
    if margin is None:
        return np.isfinite(board_xy).all(axis=1)
    return on_board(board, board_xy, margin)


def fit_plane(points: np.ndarray) -> np.ndarray:
    """Least-squares plane (a, b, c, d) through 3D points, unit normal, d < 0 (the origin on
    the negative side)."""
    c = points.mean(axis=0)
    _, s, vt = np.linalg.svd(points - c, full_matrices=False)
    if s.size < 3 or not s[1] > 1e-9 * max(s[0], 1e-300):
        raise ValueError("the stripe points lie on a line, not a plane: the laser plane needs "
                         "stripe points from views with the board at different angles")
    n = vt[2]
    plane = np.r_[n, -n @ c]
    return -plane if plane[3] > 0 else plane


def finite_rms(r: np.ndarray) -> float:
    r = r[np.isfinite(r)]
    return float(np.sqrt(np.mean(r**2))) if r.size else float("nan")


def held_camera(camera: OpenCvSensor, views: Sequence[ViewData], board: BoardSpec,
                 image_size: tuple[int, int], chain: bool, evaluate: bool = False
                 ) -> tuple[np.ndarray, list[np.ndarray], float]:
    """``calibrate_joint``'s set-up with a given camera (``camera``): its intrinsics, each
    view's board pose from its corners (``solvePnP``) and their RMS reprojection (px).
    ``evaluate``: the hand-eye transform is held too (nothing of the sensor is calibrated),
    so views without robot poses are fine."""
    if not isinstance(camera, OpenCvSensor):
        raise ValueError(f"camera must be an OpenCvSensor (an opencv-model calibration's "
                         f"sensor), got {type(camera).__name__}")
    if tuple(camera.image_size) != tuple(int(x) for x in image_size):
        raise ValueError(f"the held camera was calibrated on {camera.image_size[0]} x "
                         f"{camera.image_size[1]} images, these are {image_size[0]} x "
                         f"{image_size[1]}")
    if evaluate and chain and camera.base_from_board is None \
            and np.allclose(camera.hand_from_camera, np.eye(4)):
        raise ValueError("the calibration has no hand-eye transform (a bench session's): it "
                         "cannot be evaluated through robot poses")
    if not (chain or evaluate):
        raise ValueError("a held camera and laser plane leave only the hand-eye transform to "
                         "calibrate, which needs the robot pose of every view")
    poses, res = [], []
    for v in views:
        obj = board.points(v.corner_index)
        px = np.asarray(v.corner_pixels, float)
        pose = board_pose_from_corners(obj, px, camera.camera_matrix, camera.dist_coeffs)
        if pose is None:
            raise ValueError(f"view {v.id}: its board pose cannot be found with the held camera")
        proj, _ = camera.project(obj @ pose[:3, :3].T + pose[:3, 3])
        res.append(proj - px)
        poses.append(pose)
    rms = float(np.sqrt(np.mean(np.sum(np.concatenate(res) ** 2, axis=1))))
    return camera.intrinsics_vector(), poses, rms
