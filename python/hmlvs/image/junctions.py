"""Corners found at the predicted junctions of the board's squares, refined and extended over
the board."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import BoardNotFoundError
from .corner_base import CornerOptions, Corners, corner_spacing, refine_subpix, subpix_window
from .grid_place import place_grid, sample_image
from .saddle import saddle_refine


def on_grid(px: np.ndarray, idx: np.ndarray, bxy: np.ndarray, tol: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """The matched corners ``px`` (board indices ``idx``) that lie on one board homography
    within ``tol`` px. ``findChessboardCornersSB`` with ``CALIB_CB_LARGER`` can return a
    corner next to the image border 10-26 px off the grid (seen on close views of the
    independent renders): the corner farthest from the homography of the others is dropped,
    one at a time, up to a quarter of them and keeping at least 6. Raises ``ValueError`` if
    the rest still do not form a grid."""
    import cv2

    def res(keep: np.ndarray) -> np.ndarray:
        hmat, _ = cv2.findHomography(bxy[idx[keep]], px[keep], 0)
        if hmat is None:
            return np.full(int(keep.sum()), np.inf)
        return np.linalg.norm(cv2.perspectiveTransform(bxy[idx[keep]].reshape(-1, 1, 2), hmat)
                              .reshape(-1, 2) - px[keep], axis=1)

    keep = np.ones(len(idx), bool)
    worst = float(res(keep).max())
    if not np.isfinite(worst):
        raise ValueError("the matched corners fit no homography (they lie on a line or "
                         "repeat): the expected pixels are far off; check the board's geometry "
                         "and the pose they were predicted from")
    while worst > tol and keep.sum() > 6 and (~keep).sum() < len(idx) // 4:
        # each corner against the homography of the others, so that one far-off corner
        # cannot pull the fit towards itself and hide among the good ones
        left = []
        for i in np.flatnonzero(keep):
            others = keep.copy()
            others[i] = False
            hmat, _ = cv2.findHomography(bxy[idx[others]], px[others], 0)
            left.append(np.inf if hmat is None else float(np.linalg.norm(
                cv2.perspectiveTransform(bxy[idx[i]].reshape(1, 1, 2), hmat).ravel() - px[i])))
        keep[np.flatnonzero(keep)[int(np.argmax(left))]] = False
        worst = float(res(keep).max())
    if worst > tol:
        raise ValueError(f"the matched corners do not form a board grid (homography "
                         f"residual {worst:.1f} px): numbering is unreliable")
    return px[keep], idx[keep]


#: a numbering from predicted pixels is taken only when the next best placement on the board
#: is this many times farther from them: the prediction may be off by a quarter of a square
JUNCTION_RATIO = 3.0


def junction_corners(gray: np.ndarray, board: Any, expected: np.ndarray,
                      options: CornerOptions) -> Corners:
    """The corners of a board that ``findChessboardCornersSB`` does not find (a close view
    of its edge, fewer than 3 x 3 corners): X-junctions of the image (maxima of the negative
    Hessian determinant, refined with ``cornerSubPix``, two opposite quadrants dark and two
    light), put on a lattice by the homography of the ``expected`` pixels, fitted again
    to themselves and numbered on the board by :func:`place_grid`."""
    import cv2

    h, w = gray.shape
    bxy = board.board_coordinates()
    vis = np.isfinite(expected).all(axis=1)
    inside = vis & (expected[:, 0] > -0.5) & (expected[:, 0] < w - 0.5) & \
        (expected[:, 1] > -0.5) & (expected[:, 1] < h - 0.5)
    none = BoardNotFoundError("no checkerboard found in the image (findChessboardCornersSB "
                              "found no 3 x 3 grid of corners, nor X-junctions where the "
                              "prediction expects the board)")
    if vis.sum() < 4 or not inside.any():
        raise none
    h_exp, _ = cv2.findHomography(bxy[vis], expected[vis], 0)
    if h_exp is None:
        raise none
    spacing = corner_spacing(expected[vis])
    if not (np.isfinite(spacing) and 2.0 <= spacing <= max(h, w)):
        # a prediction whose squares are larger than the image (a board predicted at the
        # camera) or degenerate: no junction lattice to look for (and no kernel that size)
        raise none
    cand = _x_junctions(gray, spacing, h_exp, board, none)
    cand, lab = _on_lattice(cand, h_exp, board, spacing, none)
    if len(cand) < 4 or np.ptp(lab[:, 0]) == 0 or np.ptp(lab[:, 1]) == 0:
        raise BoardNotFoundError(
            f"no checkerboard found in the image (findChessboardCornersSB found no 3 x 3 "
            f"grid of corners, and only {len(cand)} X-junctions in one row lie on a board "
            "lattice)")
    spacing = corner_spacing(cand)
    idx = place_grid(cand, lab[:, 0] - lab[:, 0].min(), lab[:, 1] - lab[:, 1].min(), board,
                     expected, spacing, JUNCTION_RATIO, options.max_error,
                     f"the {len(cand)} X-junctions found")
    return refine_and_extend(gray, cand, idx, board, spacing, options.extend, "predicted",
                             x_check=True, refine=options.refine)


def _x_junctions(gray: np.ndarray, spacing: float, h_exp: np.ndarray, board: Any,
                 none: Exception) -> np.ndarray:
    """The image's X-junctions at the scale of squares ``spacing`` px wide (at most 400, at
    least 4, else ``none`` is raised): saddle maxima refined with ``cornerSubPix``, kept
    where the two quadrant pairs differ clearly (:func:`_x_gap`), one per corner."""
    import cv2

    h, w = gray.shape
    g = gray.astype(np.float32)
    sm = cv2.GaussianBlur(g, (0, 0), max(1.0, 0.05 * spacing))
    ixx = cv2.Sobel(sm, cv2.CV_32F, 2, 0, ksize=3)
    iyy = cv2.Sobel(sm, cv2.CV_32F, 0, 2, ksize=3)
    ixy = cv2.Sobel(sm, cv2.CV_32F, 1, 1, ksize=3)
    sad = ixy * ixy - ixx * iyy  # > 0 at a saddle: an X-junction
    k = 2 * int(max(2, 0.15 * spacing)) + 1
    peak = (sad == cv2.dilate(sad, np.ones((k, k), np.uint8))) & (sad > 0.05 * sad.max())
    win = subpix_window(spacing)
    m = win + 2
    v, u = np.nonzero(peak[m:h - m, m:w - m])
    if u.size < 4:
        raise none
    order = np.argsort(-sad[v + m, u + m])[:400]
    cand = refine_subpix(gray, np.stack([u[order] + m, v[order] + m], axis=1).astype(float), win)
    top = float(np.percentile(g, 99.5) - np.percentile(g, 0.5))
    inv = np.linalg.inv(h_exp)
    at_board = cv2.perspectiveTransform(cand.reshape(-1, 1, 2), inv).reshape(-1, 2)
    gap, _ = _x_gap(g, cand, at_board, h_exp, board.square)
    with np.errstate(invalid="ignore"):
        cand = cand[gap > max(0.3 * top, 8.0)]
    # one junction per corner: the refinement can bring two maxima to the same corner
    keep: list[np.ndarray] = []
    for c in cand:
        if all(np.linalg.norm(c - o) > 0.3 * spacing for o in keep):
            keep.append(c)
    if len(keep) < 4:
        raise none
    return np.array(keep)


def _on_lattice(cand: np.ndarray, h_exp: np.ndarray, board: Any, spacing: float,
                none: Exception) -> tuple[np.ndarray, np.ndarray]:
    """The junctions ``cand`` on the board's lattice: labelled by the nearest corner of the
    predicted board (homography ``h_exp``), then of the board fitted to the junctions
    themselves (a prediction off by a fraction of a square loses no junction); those off
    it dropped, one per lattice point. Returns (junctions, their lattice labels)."""
    import cv2

    inv = np.linalg.inv(h_exp)
    # the lattice: nearest corner of the predicted board, then of the board fitted to the
    # junctions themselves (a prediction off by a fraction of a square loses no junction)
    lab = np.rint(cv2.perspectiveTransform(cand.reshape(-1, 1, 2), inv).reshape(-1, 2)
                  / board.square)
    h_fit, inl = cv2.findHomography(lab * board.square, cand, cv2.RANSAC, 0.1 * spacing)
    if h_fit is None or inl is None or inl.sum() < 4:
        raise none
    f = cv2.perspectiveTransform(cand.reshape(-1, 1, 2), np.linalg.inv(h_fit)).reshape(-1, 2)
    lab = np.rint(f / board.square)
    near = np.linalg.norm(cv2.perspectiveTransform(
        (lab * board.square).reshape(-1, 1, 2), h_fit).reshape(-1, 2) - cand, axis=1)
    ok = near < 0.1 * spacing
    cand, lab = cand[ok], lab[ok].astype(int)
    _, first = np.unique(lab, axis=0, return_index=True)
    cand, lab = cand[np.sort(first)], lab[np.sort(first)]
    return cand, lab


def refine_and_extend(gray: np.ndarray, px: np.ndarray, idx: np.ndarray, board: Any,
                       spacing: float, extend: bool, rule: str,
                       x_check: bool = False, refine: str = "saddle") -> Corners:
    """Numbered corners (pixels ``px``, board indices ``idx``) refined with ``cornerSubPix``
    and, with ``extend``, completed by following the board's homography (see
    :func:`find_corners`); with ``x_check`` an added corner must be an X-junction. With
    ``refine="saddle"`` every corner is then moved to its saddle point
    (:func:`saddle_refine`)."""
    import cv2
    h, w = gray.shape
    n_board = board.rows * board.cols
    bxy = board.board_coordinates()
    win = subpix_window(spacing)
    # findChessboardCornersSB's own sub-pixel positions are less accurate on sharp images
    # than cornerSubPix (about 0.1 px against 0.05 px RMS on rendered boards, and off by
    # more than a pixel next to the image border): refine them, and drop the corners too
    # close to the border for the refinement window.
    fits = (px[:, 0] >= win + 2) & (px[:, 0] <= w - 3 - win) & (px[:, 1] >= win + 2) & \
        (px[:, 1] <= h - 3 - win)
    if not fits.any():
        raise ValueError("every corner found is too close to the image border to be refined")
    ref = refine_subpix(gray, px[fits], win)
    moved = np.linalg.norm(ref - px[fits], axis=1) < 0.1 * spacing
    px, idx = ref[moved], idx[fits][moved]
    anchor = np.ones(len(idx), bool)
    gray32 = gray.astype(np.float32)
    contrast = None
    if extend and x_check and len(idx) >= 4:
        hmat, _ = cv2.findHomography(bxy[idx], px, 0)
        if hmat is not None:
            contrast = float(np.nanmedian(np.abs(_x_gap(gray32, px, bxy[idx], hmat,
                                                         board.square)[1])))
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
            ref = refine_subpix(gray, pred[inside], win)
            keep = np.linalg.norm(ref - pred[inside], axis=1) < 0.15 * spacing
            if contrast is not None:
                # cornerSubPix can settle on an edge or a square's outer corner near a wrong
                # prediction (measured: 7.6 px off on a cropped real image): an added corner
                # must be an X-junction, two opposite quadrants dark and two light
                gap, _ = _x_gap(gray32, ref, bxy[todo[inside]], hmat, board.square)
                with np.errstate(invalid="ignore"):
                    keep &= gap > 0.5 * contrast
            if not keep.any():
                break
            idx = np.concatenate([idx, todo[inside][keep]])
            px = np.vstack([px, ref[keep]])
            anchor = np.concatenate([anchor, np.zeros(int(keep.sum()), bool)])
    if refine == "saddle":
        px = saddle_refine(gray, px, spacing, parity=idx // board.cols + idx % board.cols)
    order = np.argsort(idx)
    return Corners(px[order], idx[order], anchor[order], board, rule, (w, h))


def _x_gap(gray: np.ndarray, px: np.ndarray, board_xy: np.ndarray, hmat: np.ndarray,
           square: float) -> tuple[np.ndarray, np.ndarray]:
    """X-junction test of corners ``px`` (k, 2) at board coordinates ``board_xy`` (mm) on a
    float32 image: the four quadrant samples at a quarter of the board's row and column
    steps (from the homography ``hmat``) around each corner. Returns (gap, signed): gap is
    how far the darker of one diagonal pair stands out from the brighter of the other
    (about the board's contrast at an X-junction, <= 0 at an edge or an L-junction; NaN
    where a sample falls outside the image), signed the mean difference of the diagonal
    pairs."""
    import cv2

    def at(xy: np.ndarray) -> np.ndarray:
        return cv2.perspectiveTransform(np.asarray(xy, float).reshape(-1, 1, 2),
                                        hmat).reshape(-1, 2)

    base = at(board_xy)
    di = at(board_xy + [square, 0.0]) - base
    dj = at(board_xy + [0.0, square]) - base
    q = [sample_image(gray, px + a * di + b * dj) for a, b in
         ((0.25, 0.25), (-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25))]
    gap = np.maximum(np.minimum(q[0], q[1]) - np.maximum(q[2], q[3]),
                     np.minimum(q[2], q[3]) - np.maximum(q[0], q[1]))
    return gap, 0.5 * (q[0] + q[1] - q[2] - q[3])
