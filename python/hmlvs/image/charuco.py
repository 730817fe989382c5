"""ChArUco boards: corners numbered by their markers' ids (:func:`detect_charuco`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import BoardNotFoundError
from .corner_base import Corners, corner_spacing, refine_subpix, to_8bit
from .stripe import as_gray


def detect_charuco(image: np.ndarray, board: Any, min_corners: int = 4) -> Corners:
    """The chessboard corners of a ChArUco board (:class:`hmlvs.geometry.board.CharucoSpec`),
    numbered by the board's own marker ids: whole or partly visible, at any rotation.

    ``cv2.aruco.CharucoDetector`` finds the ArUco markers and interpolates the chessboard
    corners between them; a corner's ChArUco id is its board index ``r * cols + c``
    (``Corners.rule == "charuco ids"``). Each corner is then refined with ``cornerSubPix``
    (a window of 0.2 corner spacings as in :func:`find_corners`, but kept inside the white
    gap between the corner and the markers of its two white squares: at most 0.8 x
    (square - marker) / 2 of a spacing, or the markers' edges pull it); corners too close
    to the image border for the window, or that the refinement moves by more than 10 % of
    the spacing, are dropped.

    Raises :class:`BoardNotFoundError` when fewer than ``min_corners`` corners are found and
    ``ValueError`` for an image that is not 8- or 16-bit.
    """
    import cv2

    if not getattr(board, "unambiguous", False) or not hasattr(board, "cv_board"):
        raise ValueError(f"detect_charuco needs a CharucoSpec board, got {board!r}")
    gray = to_8bit(as_gray(image, "the image", None))
    h, w = gray.shape
    found, ids, markers, _ = cv2.aruco.CharucoDetector(board.cv_board()).detectBoard(gray)
    n = 0 if ids is None else len(ids)
    if n < min_corners:
        n_markers = 0 if markers is None else len(markers)
        raise BoardNotFoundError(
            f"no ChArUco board found in the image: {n} chessboard corners (at least "
            f"{min_corners} needed) from {n_markers} {board.dictionary} markers")
    px = found.reshape(-1, 2).astype(float)
    idx = ids.ravel().astype(int)
    spacing = _charuco_spacing(px, idx, board)
    # the window must stay inside the white gap between the corner and the markers of its two
    # white squares ((square - marker) / 2 on either axis), or their edges pull the corner
    # (by up to 1 px with a window of 0.2 spacings on a 20 mm / 15 mm board)
    gap = 0.5 * (1.0 - board.marker / board.square)
    win = int(np.clip(round(min(0.2, 0.8 * gap) * spacing), 2, 9))
    fits = (px[:, 0] >= win + 2) & (px[:, 0] <= w - 3 - win) & (px[:, 1] >= win + 2) & \
        (px[:, 1] <= h - 3 - win)
    px, idx = px[fits], idx[fits]
    if len(idx):
        ref = refine_subpix(gray, px, win)
        moved = np.linalg.norm(ref - px, axis=1) < 0.1 * spacing
        px, idx = ref[moved], idx[moved]
    if len(idx) < min_corners:
        raise BoardNotFoundError(
            f"no ChArUco board found in the image: only {len(idx)} of its {n} chessboard "
            f"corners lie far enough from the border and refine cleanly (at least "
            f"{min_corners} needed)")
    order = np.argsort(idx)
    return Corners(px[order], idx[order], np.ones(len(idx), bool), board, "charuco ids",
                   (w, h))


def _charuco_spacing(px: np.ndarray, idx: np.ndarray, board: Any) -> float:
    """Median image distance between detected corners that are board neighbours (px); the
    nearest-neighbour distance when no two are."""
    rc = np.stack([idx // board.cols, idx % board.cols], axis=1)
    d = np.abs(rc[:, None] - rc[None]).sum(axis=2)
    i, j = np.nonzero(np.triu(d == 1))
    if len(i):
        return float(np.median(np.linalg.norm(px[i] - px[j], axis=1)))
    return corner_spacing(px) if len(px) > 1 else 20.0
