"""Partly visible plain checkerboards: a grid of corners found without knowing which part of
the board it is (:func:`detect_grid`), then numbered (:func:`number_grid`,
:func:`number_grid_by_pose`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import BoardNotFoundError
from .corner_base import (
    CornerOptions,
    Corners,
    corner_spacing,
    refine_subpix,
    subpix_window,
    to_8bit,
)
from .grid_place import place_by_pose, place_grid, sample_image
from .junctions import refine_and_extend
from .stripe import as_gray


@dataclass(frozen=True)
class CornerGrid:
    """A regular grid of checkerboard corners found in an image but not numbered on the
    board: a partly visible plain checkerboard shows the same pattern wherever it is cut, so
    which rows and columns of the board the grid covers needs a prediction
    (:func:`number_grid`).

    Attributes
    ----------
    pixels : (m, n, 2) corner pixels in the detector's grid order
    spacing : median distance between neighbouring corners (px)
    image_size : (width, height) of the image
    """

    pixels: np.ndarray
    spacing: float
    image_size: tuple[int, int]

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.pixels.shape[0]), int(self.pixels.shape[1])


# pattern sizes tried with CALIB_CB_LARGER, smallest first: a larger request fails on a
# small view; the grid returned can skip rows or repeat corners (measured on rendered partial
# views), so only its regular cells seed the grid, which is then grown row by row
_GRID_SIZES = ((3, 3), (4, 4), (5, 5))


_GRID_SEEDS = (0, 1, 2)  # seeds of OpenCV's RNG for findChessboardCornersSB, tried in turn


def _grid_stats(gray: np.ndarray, grid: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For an (m, n, 2) corner grid on a float32 image: per cell the mean and spread (max -
    min) of 9 samples at 1/4, 1/2 and 3/4 of its sides; per corner the X-junction gap (how
    far the two diagonally opposite quadrant samples, at 0.35 of the grid steps, stand out
    from the other two: about the board's contrast at a corner where four squares meet,
    about 0 or less at the L-junction where an edge square meets the white border) and its
    four quadrant samples."""
    f = np.array([0.25, 0.5, 0.75])
    s, t = (a.ravel()[:, None] for a in np.meshgrid(f, f, indexing="ij"))
    p00, p10 = grid[:-1, :-1, None], grid[1:, :-1, None]
    p01, p11 = grid[:-1, 1:, None], grid[1:, 1:, None]
    vals = sample_image(gray, (1 - s) * (1 - t) * p00 + s * (1 - t) * p10 + (1 - s) * t * p01
                   + s * t * p11)
    mean = vals.mean(axis=2)
    spread = vals.max(axis=2) - vals.min(axis=2)
    di = np.concatenate([grid[1:] - grid[:-1], grid[-1:] - grid[-2:-1]], axis=0)
    dj = np.concatenate([grid[:, 1:] - grid[:, :-1], grid[:, -1:] - grid[:, -2:-1]], axis=1)
    q = np.stack([sample_image(gray, grid + a * di + b * dj) for a, b in
                  ((0.35, 0.35), (-0.35, -0.35), (0.35, -0.35), (-0.35, 0.35))])
    gap = np.maximum(np.minimum(q[0], q[1]) - np.maximum(q[2], q[3]),
                     np.minimum(q[2], q[3]) - np.maximum(q[0], q[1]))
    return mean, spread, gap, q


def _regular_cells(stats: tuple, contrast: float, mid: float, sign: float) -> np.ndarray:
    """(m-1, n-1) bool: cells that are one uniform square, dark or light as a checkerboard
    puts them (cell (0, 0) light when ``sign`` > 0), with an X-junction at each corner."""
    mean, spread, gap, _ = stats
    parity = np.add.outer(np.arange(mean.shape[0]), np.arange(mean.shape[1])) % 2
    side = np.where(parity == 0, 1.0, -1.0) * sign * (mean - mid)
    with np.errstate(invalid="ignore"):
        x = gap > 0.5 * contrast
        return ((side > 0.25 * contrast) & (spread < 0.5 * contrast) & x[:-1, :-1]
                & x[1:, :-1] & x[:-1, 1:] & x[1:, 1:])


def _largest_block(ok: np.ndarray) -> tuple[int, int, int, int] | None:
    """The rectangle (i0, i1, j0, j1), inclusive, of True cells with the most corners; None
    if no cell is True."""
    best, found = 0, None
    m, n = ok.shape
    for i0 in range(m):
        for i1 in range(i0, m):
            rows = ok[i0:i1 + 1].all(axis=0)
            j = 0
            while j < n:
                if not rows[j]:
                    j += 1
                    continue
                j1 = j
                while j1 + 1 < n and rows[j1 + 1]:
                    j1 += 1
                area = (i1 - i0 + 2) * (j1 - j + 2)
                if area > best:
                    best, found = area, (i0, i1, j, j1)
                j = j1 + 1
    return found


def _fits(shape: tuple[int, ...], board: Any) -> bool:
    m, n = shape[0], shape[1]
    return (m <= board.rows and n <= board.cols) or (m <= board.cols and n <= board.rows)


def _grow(gray8: np.ndarray, gray: np.ndarray, grid: np.ndarray, board: Any, contrast: float,
          mid: float, sign: float) -> np.ndarray:
    """Grow a regular corner grid by whole rows and columns: each new row is predicted by the
    grid's homography, refined with ``cornerSubPix`` and kept when every corner moved less
    than a quarter of the spacing and every new cell is regular (:func:`_regular_cells`)."""
    import cv2
    h, w = gray.shape
    blocked = set()
    while len(blocked) < 4:
        for side in range(4):
            if side in blocked:
                continue
            axis, front = divmod(side, 2)
            g = grid if axis == 0 else grid.transpose(1, 0, 2)
            m, n = g.shape[:2]
            if not _fits((m + 1, n) if axis == 0 else (n, m + 1), board):
                blocked.add(side)
                continue
            i, j = np.meshgrid(np.arange(m), np.arange(n), indexing="ij")
            src = np.stack([i.ravel(), j.ravel()], axis=1).astype(np.float64)
            hmat, _ = cv2.findHomography(src, g.reshape(-1, 2), 0)
            if hmat is None:
                blocked.add(side)
                continue
            row = -1.0 if front else float(m)
            new_ij = np.stack([np.full(n, row), np.arange(n, dtype=float)], axis=1)
            pred = cv2.perspectiveTransform(new_ij.reshape(-1, 1, 2), hmat).reshape(-1, 2)
            spacing = corner_spacing(g.reshape(-1, 2))
            win = subpix_window(spacing)
            if not ((pred >= win + 2).all() and (pred[:, 0] <= w - 3 - win).all()
                    and (pred[:, 1] <= h - 3 - win).all()):
                blocked.add(side)
                continue
            ref = refine_subpix(gray8, pred, win)
            cand = np.concatenate([ref[None], g] if front else [g, ref[None]], axis=0)
            s = -sign if front else sign  # prepending a row shifts the cells' parity
            cand = cand if axis == 0 else cand.transpose(1, 0, 2)
            cells = _regular_cells(_grid_stats(gray, cand), contrast, mid, s)
            new = cells[0] if (front and axis == 0) else cells[-1] if axis == 0 else \
                cells[:, 0] if front else cells[:, -1]
            if np.linalg.norm(ref - pred, axis=1).max() > 0.25 * spacing or not new.all():
                blocked.add(side)
                continue
            grid, sign = cand, s
            blocked.clear()
    return grid


def detect_grid(image: np.ndarray, board: Any = None) -> CornerGrid:
    """The corners of a (possibly partly visible) plain checkerboard as an unnumbered grid.

    ``findChessboardCornersSB`` with ``CALIB_CB_LARGER`` (which returns the whole grid it
    can follow, starting from a requested 3 x 3, 4 x 4 or 5 x 5) gives the candidates. Its
    grid can skip rows, repeat corners or take the outer corners of the edge squares for a
    row of corners, so only its largest block of regular cells is kept (each cell one
    uniform square, dark and light alternating, every corner an X-junction) and grown by
    whole rows and columns while the new cells are regular. The first grid of at least 6
    corners that fits on the board is returned; number it with :func:`number_grid`.
    ``findChessboardCornersSB`` samples at random: OpenCV's RNG is seeded (``cv2.setRNGSeed``
    0, then 1 and 2 if nothing is found), so the result depends on the image alone.

    Raises :class:`BoardNotFoundError` when no such grid is found."""
    import cv2

    from ..geometry.board import Checkerboard
    board = Checkerboard() if board is None else board
    gray8 = to_8bit(as_gray(image, "the image", None))
    gray = gray8.astype(np.float32)
    h, w = gray.shape
    top = float(np.percentile(gray, 99.5) - np.percentile(gray, 0.5))
    flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_LARGER
    seen = []
    tries = [(seed, size) for seed in _GRID_SEEDS for size in _GRID_SIZES
             if min(size) <= min(board.rows, board.cols)]
    for seed, size in tries:
        # findChessboardCornersSB draws random samples from OpenCV's RNG: seeded, the result
        # depends on the image alone; another seed may find a grid where one did not
        cv2.setRNGSeed(seed)
        ok, found, meta = cv2.findChessboardCornersSBWithMeta(gray8, size, flags)
        if not ok or found is None or meta is None or found.shape[0] != meta.size:
            continue
        grid = found.reshape(meta.shape[0], meta.shape[1], 2).astype(float)
        if min(grid.shape[:2]) < 2:
            continue
        stats = _grid_stats(gray, grid)
        q = stats[3]
        contrast = float(np.nanmedian(np.abs(q[0] + q[1] - q[2] - q[3]) / 2))
        mid = 0.5 * float(np.nanpercentile(q, 25) + np.nanpercentile(q, 75))
        if not contrast > max(0.15 * top, 8.0):
            seen.append(f"{grid.shape[0]} x {grid.shape[1]} (too little contrast)")
            continue
        blocks = [(b, sg) for sg in (1.0, -1.0)
                  if (b := _largest_block(_regular_cells(stats, contrast, mid, sg)))]
        if not blocks:
            seen.append(f"{grid.shape[0]} x {grid.shape[1]} (no regular cell)")
            continue
        (i0, i1, j0, j1), sign = max(blocks, key=lambda b: (b[0][1] - b[0][0] + 2)
                                     * (b[0][3] - b[0][2] + 2))
        # cell (i0, j0) becomes the seed's cell (0, 0): its colour sign follows the parity
        sign = sign if (i0 + j0) % 2 == 0 else -sign
        start = grid[i0:i1 + 2, j0:j1 + 2]
        if not _fits(start.shape, board):
            seen.append(f"{start.shape[0]} x {start.shape[1]} (larger than the board)")
            continue
        grown = _grow(gray8, gray, start, board, contrast, mid, sign)
        if grown.shape[0] * grown.shape[1] < 6:
            seen.append(f"{grown.shape[0]} x {grown.shape[1]} (too few regular corners)")
            continue
        return CornerGrid(grown, corner_spacing(grown.reshape(-1, 2)), (w, h))
    extra = f"; rejected: {', '.join(dict.fromkeys(seen))}" if seen else ""
    raise BoardNotFoundError("no checkerboard found in the image (findChessboardCornersSB "
                             f"found no regular grid of at least 6 corners{extra})")


def number_grid(image: np.ndarray, grid: CornerGrid, board: Any, expected: np.ndarray,
                ratio: float = 3.0, options: CornerOptions | None = None) -> Corners:
    """Number a partly visible board's corners (:func:`detect_grid`) from predicted pixels.

    ``expected`` (rows*cols, 2) holds where every board corner should appear (row-major,
    NaN allowed), e.g. projected from the robot pose with a first calibration. Every
    placement of the grid on the board (each offset, and each orientation with the board's
    handedness) is scored by the RMS distance of the found corners from the predicted pixels
    of the corners it assigns. The best is taken only when it lies within ``max_error``
    corner spacings (:class:`CornerOptions`) and the second best is at least ``ratio`` times
    farther; otherwise :class:`NumberingError` says why and nothing is numbered (with the
    default ratio 3 the prediction may be off by up to a quarter of a square). The corners
    are then refined and extended over the board as in :func:`find_corners`
    (``Corners.rule == "predicted"``)."""
    options = CornerOptions() if options is None else options
    gray = to_8bit(as_gray(image, "the image", None))
    exp = np.asarray(expected, dtype=float)
    n_board = board.rows * board.cols
    if exp.shape != (n_board, 2):
        raise ValueError(f"expected must hold the ({n_board}, 2) predicted pixels of the "
                         f"board's corners, got shape {exp.shape}")
    m, n = grid.shape
    px = grid.pixels.reshape(-1, 2)
    spacing = grid.spacing
    i, j = (a.ravel() for a in np.meshgrid(np.arange(m), np.arange(n), indexing="ij"))
    idx = place_grid(px, i, j, board, exp, spacing, ratio, options.max_error,
                 f"the {m} x {n} corners found")
    return refine_and_extend(gray, px, idx, board, spacing, options.extend, "predicted",
                              x_check=True, refine=options.refine)


def number_grid_by_pose(image: np.ndarray, grid: CornerGrid, board: Any,
                        camera_matrix: np.ndarray, dist_coeffs: np.ndarray,
                        base_from_camera: np.ndarray, base_from_board: np.ndarray,
                        ratio: float = 3.0, options: CornerOptions | None = None) -> Corners:
    """:func:`number_grid` with the numbering from the robot chain (:func:`place_by_pose`)
    instead of predicted pixels; then refined and extended the same way
    (``Corners.rule == "pose"``)."""
    options = CornerOptions() if options is None else options
    gray = to_8bit(as_gray(image, "the image", None))
    m, n = grid.shape
    px = grid.pixels.reshape(-1, 2)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(m), np.arange(n), indexing="ij"))
    idx = place_by_pose(px, i, j, board, camera_matrix, dist_coeffs, base_from_camera,
                        base_from_board, ratio, f"the {m} x {n} corners found")
    return refine_and_extend(gray, px, idx, board, grid.spacing, options.extend, "pose",
                              x_check=True, refine=options.refine)
