"""Checkerboard corners: OpenCV's detectors, numbered on the board."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..models.paper import project
from .stripe import _as_gray

# ------------------------------------------------------------------------------------------
# Checkerboard corners


@dataclass(frozen=True)
class Corners:
    """Checkerboard corners found in an image, each numbered on the board.

    Attributes
    ----------
    pixels : (k, 2) sub-pixel corner positions (u, v)
    index : (k,) row-major board corner index ``r * board.cols + c`` (0-based inner corners)
    anchor : (k,) True for corners found by ``findChessboardCornersSB``, False for corners
        added by following the board's homography into the rest of the image
    board : the :class:`~hmlvs.Checkerboard` the indices refer to
    rule : how the ordering was fixed: "expected" (nearest to predicted pixels) or
        "top-left" (the marker-free rule for a fully visible board)
    """

    pixels: np.ndarray
    index: np.ndarray
    anchor: np.ndarray
    board: Any
    rule: str = "expected"
    image_size: tuple[int, int] | None = None  # (width, height) of the image

    def __len__(self) -> int:
        return int(self.index.shape[0])

    @property
    def rc(self) -> np.ndarray:
        """(k, 2) board (row, column) of each corner."""
        return np.stack([self.index // self.board.cols, self.index % self.board.cols], axis=1)

    @property
    def ids(self) -> list[str]:
        """Corner ids as :meth:`Checkerboard.corner_ids` spells them (``"r2c4"``)."""
        return [f"r{r}c{c}" for r, c in self.rc]

    @property
    def board_xy(self) -> np.ndarray:
        """(k, 2) board coordinates (mm) along the board's row and column directions."""
        return self.rc.astype(float) * self.board.square

    @property
    def points(self) -> np.ndarray:
        """(k, 3) corner positions in the robot base frame (mm)."""
        return self.board.corners()[self.index]


def _handedness(board: Any) -> float:
    """Sign of the image cross product (row step x column step) of a board seen from the
    side its ``normal`` points to: the camera's z axis looks into the scene, so a board frame
    whose row x col points towards the camera appears clockwise (negative) in (u, v)."""
    n = np.cross(board.row_direction, board.col_direction)
    return -1.0 if float(n @ board.normal) > 0 else 1.0


def _orientation(px: np.ndarray, idx: np.ndarray, board: Any) -> float:
    """Image cross product sign of the board's row and column steps under a numbering."""
    rc = np.stack([idx // board.cols, idx % board.cols], axis=-1).reshape(-1, 2).astype(float)
    # affine fit px = [r, c, 1] A: its 2x2 part holds the row and column steps
    a, *_ = np.linalg.lstsq(np.hstack([rc, np.ones((len(rc), 1))]), px.reshape(-1, 2),
                            rcond=None)
    return float(np.sign(a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]))


def _spacing(px: np.ndarray) -> float:
    """Median distance from each point to its nearest neighbour (px)."""
    d = np.linalg.norm(px[:, None, :] - px[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def _refine(gray: np.ndarray, pts: np.ndarray, win: int) -> np.ndarray:
    import cv2
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    p = np.ascontiguousarray(pts, dtype=np.float32).reshape(-1, 1, 2)
    return cv2.cornerSubPix(gray, p, (win, win), (-1, -1), crit).reshape(-1, 2).astype(float)


def _match(px: np.ndarray, pred: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest neighbours between detected px and predicted board corners within
    radius: (indices into px, board indices)."""
    d = np.linalg.norm(px[:, None, :] - pred[None, :, :], axis=2)
    d[:, ~np.isfinite(pred).all(axis=1)] = np.inf
    j = np.argmin(d, axis=1)
    i_back = np.argmin(d, axis=0)
    ok = (d[np.arange(len(px)), j] < radius) & (i_back[j] == np.arange(len(px)))
    return np.nonzero(ok)[0], j[ok]


def find_corners(image: np.ndarray, board: Any = None, expected: np.ndarray | None = None,
                 extend: bool = True, max_error: float = 0.35) -> Corners:
    """Checkerboard corners of an image (laser off), numbered on the board.

    OpenCV's ``findChessboardCornersSB`` gives sub-pixel corners. Which board corners they
    are is ambiguous: a checkerboard looks the same turned by 180 degrees and, when only
    part of it is visible, shifted by whole squares. The numbering is fixed by

    - ``expected`` (rows*cols, 2): approximate pixels of every board corner in row-major
      order (NaN allowed), e.g. projected with approximate sensor parameters and the robot's
      pose (:func:`predicted_corners`). The detected corners (found with
      ``CALIB_CB_LARGER``, so a board larger than the view is found) are matched to them
      after removing their median offset, then through the board's homography; a corner is
      matched within ``max_error`` times the corner spacing. So the expected pixels may be
      off by a common shift of up to about half a square plus ``max_error`` of a square of
      scatter. Required for a partly visible board.
    - otherwise, for a fully visible board only, a marker-free rule: among the orderings
      with the board's handedness (the camera sees the side ``board.normal`` points to), the
      one whose corner r0c0 is nearest the image's top-left (smallest u + v). It is right as
      long as the board appears rotated by less than about 90 degrees in the image.

    Every corner is refined with ``cornerSubPix`` (a window of about 0.2 times the corner
    spacing, at most 19 x 19 px); corners too close to the image border for the window are
    dropped. With ``extend`` the homography of the numbered corners predicts the board's
    remaining corners inside the image, which are refined the same way and kept when they
    move less than 15 % of the spacing (repeated as the set grows).

    Raises ``ValueError`` if the image is not an 8- or 16-bit image, no board is found, or
    the corners cannot be numbered.
    """
    import cv2

    from ..geometry.board import Checkerboard
    board = Checkerboard() if board is None else board
    gray = _as_gray(image, "the image", None)
    if gray.dtype == np.uint16:
        gray = (gray >> 8).astype(np.uint8)
    gray = np.ascontiguousarray(gray)
    h, w = gray.shape
    n_board = board.rows * board.cols
    bxy = board.board_coordinates()
    flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    if expected is not None:
        expected = np.asarray(expected, dtype=float)
        if expected.shape != (n_board, 2):
            raise ValueError(f"expected must hold the ({n_board}, 2) predicted pixels of the "
                             f"board's corners, got shape {expected.shape}")
        ok, found, _ = cv2.findChessboardCornersSBWithMeta(gray, (3, 3),
                                                           flags | cv2.CALIB_CB_LARGER)
        if not ok or found is None or len(found) < 4:
            raise ValueError("no checkerboard found in the image (findChessboardCornersSB "
                             "found no 3 x 3 grid of corners)")
        det = found.reshape(-1, 2).astype(float)
        spacing = _spacing(det)
        radius = max_error * spacing
        vis = np.isfinite(expected).all(axis=1)
        shift = np.median(det - expected[np.argmin(np.linalg.norm(
            det[:, None] - np.where(vis[:, None], expected, np.inf)[None], axis=2), axis=1)],
            axis=0) if vis.any() else np.zeros(2)
        i_det, idx = _match(det, expected + shift, radius)
        if len(idx) >= 4:
            hmat, _ = cv2.findHomography(bxy[idx], det[i_det], 0)
            if hmat is not None:
                pred = cv2.perspectiveTransform(bxy.reshape(-1, 1, 2), hmat).reshape(-1, 2)
                i_det, idx = _match(det, pred, radius)
        if len(idx) < 4:
            raise ValueError(f"the detected corners do not match the expected ones (fewer than "
                             f"4 within {radius:.0f} px after removing the median offset "
                             f"{np.round(shift, 1).tolist()} px): the approximate parameters "
                             "or pose are too far off")
        px = det[i_det]
        hmat, _ = cv2.findHomography(bxy[idx], px, 0)
        res = np.linalg.norm(cv2.perspectiveTransform(bxy[idx].reshape(-1, 1, 2), hmat)
                             .reshape(-1, 2) - px, axis=1)
        if res.max() > 0.1 * spacing:
            raise ValueError(f"the matched corners do not form a board grid (homography "
                             f"residual {res.max():.1f} px): numbering is unreliable")
        # A mirror image of the board is a homography too, so a mirrored expectation can match
        # every corner with every label wrong (a small view of a symmetric grid): only the
        # board's handedness, as the camera sees it, tells.
        if _orientation(px, idx, board) != _handedness(board):
            raise ValueError("the expected corner pixels are a mirror image of the board as "
                             "the camera sees it (its rows and columns swapped or one of "
                             "them reversed): numbering them would label every corner wrong")
        rule = "expected"
    else:
        # by keyword: the Python signature takes ``corners`` third
        ok, found = cv2.findChessboardCornersSB(gray, (board.cols, board.rows), flags=flags)
        if not ok or found is None:
            raise ValueError(f"no fully visible {board.rows} x {board.cols} checkerboard found "
                             "in the image; for a partly visible board pass the expected "
                             "corner pixels")
        grid = found.reshape(board.rows, board.cols, 2).astype(float)
        spacing = _spacing(grid.reshape(-1, 2))
        base = np.arange(n_board).reshape(board.rows, board.cols)
        cands = [base, base[::-1, ::-1], base[::-1, :], base[:, ::-1]]
        if board.rows == board.cols:
            cands += [c.T for c in cands]
        sign = _handedness(board)
        cands = [c for c in cands if _orientation(grid, c, board) == sign]
        # placement c says grid point (i, j) is board corner c[i, j]; r0c0 sits where c == 0
        first = [grid.reshape(-1, 2)[int(np.argmin(c.ravel()))] for c in cands]
        c = cands[int(np.argmin([p.sum() for p in first]))]
        idx = c.ravel()
        px = grid.reshape(-1, 2)
        rule = "top-left"
    win = int(np.clip(round(0.2 * spacing), 2, 9))
    # findChessboardCornersSB's own sub-pixel positions are less accurate on sharp images
    # than cornerSubPix (about 0.1 px against 0.05 px RMS on rendered boards, and off by
    # more than a pixel next to the image border): refine them, and drop the corners too
    # close to the border for the refinement window.
    fits = (px[:, 0] >= win + 2) & (px[:, 0] <= w - 3 - win) & (px[:, 1] >= win + 2) & \
        (px[:, 1] <= h - 3 - win)
    if not fits.any():
        raise ValueError("every corner found is too close to the image border to be refined")
    ref = _refine(gray, px[fits], win)
    moved = np.linalg.norm(ref - px[fits], axis=1) < 0.1 * spacing
    px, idx = ref[moved], idx[fits][moved]
    anchor = np.ones(len(idx), bool)
    if extend:
        for _ in range(4):
            todo = np.setdiff1d(np.arange(n_board), idx)
            if todo.size == 0:
                break
            hmat, _ = cv2.findHomography(bxy[idx], px, 0)
            if hmat is None:
                break
            pred = cv2.perspectiveTransform(bxy[todo].reshape(-1, 1, 2), hmat).reshape(-1, 2)
            m = win + 2
            inside = (pred[:, 0] >= m) & (pred[:, 0] <= w - 1 - m) & (pred[:, 1] >= m) & \
                (pred[:, 1] <= h - 1 - m)
            if not inside.any():
                break
            ref = _refine(gray, pred[inside], win)
            keep = np.linalg.norm(ref - pred[inside], axis=1) < 0.15 * spacing
            if not keep.any():
                break
            idx = np.concatenate([idx, todo[inside][keep]])
            px = np.vstack([px, ref[keep]])
            anchor = np.concatenate([anchor, np.zeros(int(keep.sum()), bool)])
    order = np.argsort(idx)
    return Corners(px[order], idx[order], anchor[order], board, rule, (w, h))


def predicted_corners(params: Any, pose: np.ndarray, board: Any) -> np.ndarray:
    """Pixels (rows*cols, 2) where the board's corners appear at a base_from_hand pose
    (row-major corner order, NaN behind the camera); for identifying detected corners."""
    corners = board.corners()
    px, ok = project(params, corners, np.repeat(np.asarray(pose, float)[None], len(corners),
                                                axis=0))
    px[~ok] = np.nan
    return px
