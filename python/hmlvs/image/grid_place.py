"""Placing a grid of corners on the board: every placement a grid could have, scored against
the corners predicted for it."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..errors import NumberingError
from .corner_base import handedness, orientation_rc


def sample_image(gray: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear grey values of the float32 image at pixels ``pts`` (..., 2); NaN outside."""
    import cv2
    xy = np.ascontiguousarray(pts, np.float32).reshape(-1, 2)
    v = cv2.remap(gray, xy[:, :1].copy(), xy[:, 1:].copy(), cv2.INTER_LINEAR,
                  borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    return v.reshape(pts.shape[:-1])


def grid_placements(i: np.ndarray, j: np.ndarray, board: Any, px: np.ndarray
                ) -> list[tuple[np.ndarray, str]]:
    """Every way corners at grid positions (``i``, ``j``) (integers, one row or column apart
    per square) can lie on the board with the board's handedness: (board indices of the
    corners in their order, a description)."""
    sign = handedness(board)
    out = []
    for swap in (False, True):
        for si in (1, -1):
            for sj in (1, -1):
                r0, c0 = (sj * j, si * i) if swap else (si * i, sj * j)
                if orientation_rc(px, np.stack([r0, c0], axis=1)) != sign:
                    continue
                r0, c0 = r0 - r0.min(), c0 - c0.min()
                for dr in range(board.rows - int(r0.max())):
                    for dc in range(board.cols - int(c0.max())):
                        r, c = r0 + dr, c0 + dc
                        out.append((r * board.cols + c,
                                    f"rows {dr}-{dr + int(r0.max())}, columns "
                                    f"{dc}-{dc + int(c0.max())}, first corner r{r[0]}c{c[0]}"))
    return out


def _two_best(scored: list[tuple[float, str, np.ndarray]]
              ) -> tuple[tuple[float, str, np.ndarray], tuple[float, str]]:
    """The best-scored placement (score, description, indices) and the second best's score
    and description (inf, "" when there is none)."""
    scored = sorted(scored, key=lambda x: x[0])
    second = (scored[1][0], scored[1][1]) if len(scored) > 1 else (np.inf, "")
    return scored[0], second


def place_grid(px: np.ndarray, i: np.ndarray, j: np.ndarray, board: Any, expected: np.ndarray,
           spacing: float, ratio: float, max_error: float, what: str) -> np.ndarray:
    """Board indices of corners ``px`` found at grid positions (``i``, ``j``) whose place on
    the board is not known: every placement (:func:`grid_placements`) is scored by the RMS
    distance of the corners from the ``expected`` pixels of the board corners it assigns.
    The best is taken only within ``max_error`` corner spacings and when the second best is
    at least ``ratio`` times farther; otherwise :class:`NumberingError` says why. ``what``
    names the corners in the messages (e.g. "the 2 x 4 corners found")."""
    scored = []
    for idx, desc in grid_placements(i, j, board, px):
        e = expected[idx]
        if not np.isfinite(e).all():
            continue
        scored.append((float(np.sqrt(np.mean(np.sum((px - e) ** 2, axis=1)))), desc, idx))
    if not scored:
        raise NumberingError(f"{what} cannot be placed on the {board.rows} x {board.cols} "
                             "board where the prediction sees it")
    (best, desc, idx), (second, second_desc) = _two_best(scored)
    if best > max_error * spacing:
        raise NumberingError(
            f"partly visible board: {what} lie {best:.1f} px RMS from the nearest placement "
            f"of the predicted board ({desc}), more than {max_error:g} of the corner spacing "
            f"({spacing:.0f} px): the prediction (robot pose, approximate parameters) is too "
            "far off to number them")
    if second < ratio * best:
        raise NumberingError(
            f"partly visible board: its numbering is ambiguous: {what} lie {best:.1f} px "
            f"RMS from the predicted board as {desc} and {second:.1f} px as {second_desc} "
            f"(the best must be {ratio:g} x closer)")
    return idx


def board_apart(px: np.ndarray, board: Any, camera_matrix: np.ndarray,
                dist_coeffs: np.ndarray, base_from_camera: np.ndarray,
                base_from_board: np.ndarray) -> Callable[[np.ndarray], float]:
    """``apart(index)``: how far (RMS over the board's corners, mm) the board lies from
    ``base_from_board`` when the corners ``px`` are numbered ``index``: their board pose
    (``solvePnP`` with the camera) carried to the base by ``base_from_camera``; inf when no
    pose fits them."""
    from ..geometry.board import board_pose_from_corners

    bxy = board.board_coordinates()
    pts = np.c_[bxy, np.zeros(len(bxy))]
    ref = pts @ base_from_board[:3, :3].T + base_from_board[:3, 3]
    k = np.asarray(camera_matrix, float)
    d = np.asarray(dist_coeffs, float)

    def apart(index: np.ndarray) -> float:
        cfb = board_pose_from_corners(pts[index], px, k, d)
        if cfb is None:
            return float("inf")
        est = base_from_camera @ cfb
        moved = pts @ est[:3, :3].T + est[:3, 3]
        return float(np.sqrt(np.mean(np.sum((moved - ref) ** 2, axis=1))))

    return apart


def place_by_pose(px: np.ndarray, i: np.ndarray, j: np.ndarray, board: Any,
                  camera_matrix: np.ndarray, dist_coeffs: np.ndarray,
                  base_from_camera: np.ndarray, base_from_board: np.ndarray,
                  ratio: float = 3.0, what: str = "the corners found") -> np.ndarray:
    """Board indices of corners ``px`` found at grid positions (``i``, ``j``), from the robot
    chain rather than from predicted pixels.

    A partly visible board's numbering is fixed only up to whole-square shifts and a half
    turn (:func:`grid_placements`). Under each placement the corners give the view's board pose
    (``solvePnP`` with the camera), and with the view's ``base_from_camera`` (robot pose times
    hand-eye) the board's pose in the base, which every view must agree on: the placement
    whose board lies nearest ``base_from_board`` (the RMS distance of the board's corners
    under the two poses, mm) is taken when the second nearest is at least ``ratio`` times
    farther and the nearest within half a square; otherwise :class:`NumberingError` says
    why. A placement one square off moves the board by a square, far more than a robot's
    and a calibration's errors, so this holds where a pixel prediction from approximate
    parameters (off by a third of a square) does not."""
    apart = board_apart(px, board, camera_matrix, dist_coeffs, base_from_camera,
                        base_from_board)
    scored = [(d, desc, idx) for idx, desc in grid_placements(i, j, board, px)
              if np.isfinite(d := apart(idx))]
    if not scored:
        raise NumberingError(f"{what} cannot be placed on the {board.rows} x {board.cols} "
                             "board")
    (best, desc, idx), (second, second_desc) = _two_best(scored)
    if best > 0.5 * board.square:
        raise NumberingError(
            f"partly visible board: under its best numbering ({desc}) the board would lie "
            f"{best:.1f} mm from where the other views put it, more than half a square: the "
            "board moved, or the robot pose does not belong to this image")
    if second < ratio * best:
        raise NumberingError(
            f"partly visible board: its numbering is ambiguous: as {desc} the board lies "
            f"{best:.2f} mm from where the other views put it, as {second_desc} "
            f"{second:.2f} mm (the best must be {ratio:g} x closer)")
    return idx
