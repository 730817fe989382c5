"""OpenCV's classic chessboard detector, the peer the real-image tests compare against."""

from __future__ import annotations

import cv2
import numpy as np

#: cornerSubPix's customary stopping rule
CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)


def classic_corners(gray: np.ndarray, window: int | None, pattern: tuple[int, int] = (9, 6)
                    ) -> tuple[np.ndarray, np.ndarray, int]:
    """findChessboardCorners, then cornerSubPix with a half-window of ``window`` px, or (None)
    one that fits inside a square: round(0.2 x the median distance between neighbouring
    corners), 2..9 px. Returns (the corners refined with ``window``, those refined with the
    in-square window, the window used)."""
    ok, c = cv2.findChessboardCorners(gray, pattern)
    assert ok, "OpenCV's classic detector found no board"
    raw = c.reshape(-1, 2)
    d = np.linalg.norm(raw[:, None] - raw[None], axis=2)
    np.fill_diagonal(d, np.inf)
    inside = int(np.clip(round(0.2 * np.median(d.min(axis=1))), 2, 9))
    small = cv2.cornerSubPix(gray, c.copy(), (inside, inside), (-1, -1), CRIT).reshape(-1, 2)
    if window is None:
        return small, small, inside
    big = cv2.cornerSubPix(gray, c.copy(), (window, window), (-1, -1), CRIT).reshape(-1, 2)
    return big, small, window
