"""Checkerboard corners: OpenCV's detectors, numbered on the board."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from .._opencv import calibrate_camera
from ..errors import BoardNotFoundError, NumberingError  # noqa: F401 (re-exported)
from ..geometry.board import BoardSpec, Checkerboard
from ..models.paper import project
from .corner_base import (
    CornerOptions,
    Corners,
    corner_spacing,
    handedness,
    match_nearest,
    orientation,
    refine_subpix,
    subpix_window,
    to_8bit,
)
from .grid_place import place_grid
from .junctions import JUNCTION_RATIO, junction_corners, on_grid, refine_and_extend
from .stripe import as_gray


def find_corners(image: np.ndarray, board: Any = None, expected: np.ndarray | None = None,
                 extend: bool = True, max_error: float = 0.35,
                 options: CornerOptions | None = None) -> Corners:
    """Checkerboard corners of an image (laser off), numbered on the board.

    OpenCV's ``findChessboardCornersSB`` gives sub-pixel corners. Which board corners they
    are is ambiguous: a checkerboard looks the same turned by 180 degrees and, when only
    part of it is visible, shifted by whole squares. The numbering is fixed by

    - ``expected`` (rows*cols, 2): approximate pixels of every board corner in row-major
      order (NaN allowed), e.g. projected with approximate sensor parameters and the robot's
      pose (:func:`predicted_corners`). The detected corners (found with
      ``CALIB_CB_LARGER``, so a board larger than the view is found) are matched to them
      after removing their median offset, then through the board's homography; a corner is
      matched within ``max_error`` times the corner spacing. Where no 3 x 3 grid is found
      (a close view of the board's edge), the image's X-junctions near the predicted board
      are taken instead. Either way the numbering must be clearly the best placement of
      the corners on the board: the RMS distance from the expected pixels of the corners it
      assigns at least 3 times smaller than that of the next best placement. So the
      expected pixels may be off by up to about a quarter of a square; a view predicted
      about half a square off is refused (``NumberingError``) rather than numbered one
      square wrong. Required for a partly visible board.
    - otherwise, for a fully visible board only, a marker-free rule: among the orderings
      with the board's handedness (the camera sees the side ``board.normal`` points to), the
      one whose corner r0c0 is nearest the image's top-left (smallest u + v). It is right as
      long as the board appears rotated by less than about 90 degrees in the image.

    Every corner is refined with ``cornerSubPix`` (a window of about 0.2 times the corner
    spacing, at most 19 x 19 px); corners too close to the image border for the window are
    dropped. With ``extend`` the homography of the numbered corners predicts the board's
    remaining corners inside the image, which are refined the same way and kept when they
    move less than 15 % of the spacing (repeated as the set grows). Finally (the default
    ``refine="saddle"``) each corner moves to the saddle point of the smoothed image
    (:func:`saddle_refine`).

    ``options`` (a :class:`CornerOptions`) holds ``extend``, ``max_error``, ``fallback`` and
    ``refine`` instead of the keywords (which are then ignored).

    Raises ``ValueError`` if the image is not an 8- or 16-bit image or the corners cannot be
    numbered, and :class:`BoardNotFoundError` (a ``ValueError``) if no board is found.
    """
    if options is None:
        options = CornerOptions(extend=extend, max_error=max_error)
    elif not isinstance(options, CornerOptions):
        raise ValueError(f"options must be a CornerOptions, got {options!r}")
    board = Checkerboard() if board is None else board
    gray = to_8bit(as_gray(image, "the image", None))
    if expected is None:
        return _numbered_top_left(gray, board, options)
    expected = np.asarray(expected, dtype=float)
    n_board = board.rows * board.cols
    if expected.shape != (n_board, 2):
        raise ValueError(f"expected must hold the ({n_board}, 2) predicted pixels of the "
                         f"board's corners, got shape {expected.shape}")
    return _numbered_by_expected(gray, board, expected, options)


def _numbered_by_expected(gray: np.ndarray, board: Any, expected: np.ndarray,
                          options: CornerOptions) -> Corners:
    """:func:`find_corners` with the expected pixels of the board's corners.

    ``findChessboardCornersSB`` runs first without ``CALIB_CB_ACCURACY`` (its search on an
    upsampled image, about 5 times the cost: 190-320 ms against 30-60 ms a 640 x 480 view of
    the rendered sessions); its corners are refined by :func:`refine_and_extend` either way.
    The accurate search runs where the quick one finds no grid or one that cannot be
    numbered, so a view it numbered before is numbered still. On rendered sessions (paper
    model, seeds 3, 5, 11; the independent renderer, seeds 0-2) both give the same data sets
    to 1e-13 px, except one view where the quick search's grid grew to 3 more corners."""
    import cv2

    quick = _sb_grid(gray, cv2.CALIB_CB_LARGER)
    if quick is not None:
        try:
            return _number_grid(gray, quick, board, expected, options)
        except ValueError:
            pass  # NumberingError is a ValueError: the accurate search decides
    accurate = _sb_grid(gray, cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
                        | cv2.CALIB_CB_LARGER)
    if accurate is None:
        # a close view of the board's edge can show fewer than 3 x 3 corners, or corners
        # OpenCV does not follow: find its X-junctions where the prediction expects them
        return junction_corners(gray, board, expected, options)
    return _number_grid(gray, accurate, board, expected, options)


def _sb_grid(gray: np.ndarray, flags: int) -> np.ndarray | None:
    """``findChessboardCornersSB``'s grid from a 3 x 3 seed (``flags`` with
    ``CALIB_CB_LARGER``) as (k, 2) pixels, None when it finds fewer than 4 corners."""
    import cv2

    cv2.setRNGSeed(0)  # its random samples: the result depends on the image alone
    ok, found, _ = cv2.findChessboardCornersSBWithMeta(gray, (3, 3), flags)
    if not ok or found is None or len(found) < 4:
        return None
    return found.reshape(-1, 2).astype(float)


def _number_grid(gray: np.ndarray, det: np.ndarray, board: Any, expected: np.ndarray,
                 options: CornerOptions) -> Corners:
    """The corners ``det`` found by ``findChessboardCornersSB``, numbered by the expected
    pixels, refined and extended (:func:`find_corners`)."""
    import cv2

    max_error = options.max_error
    bxy = board.board_coordinates()
    spacing = corner_spacing(det)
    radius = max_error * spacing
    vis = np.isfinite(expected).all(axis=1)
    shift = np.median(det - expected[np.argmin(np.linalg.norm(
        det[:, None] - np.where(vis[:, None], expected, np.inf)[None], axis=2), axis=1)],
        axis=0) if vis.any() else np.zeros(2)
    i_det, idx = match_nearest(det, expected + shift, radius)
    if len(idx) >= 4:
        hmat, _ = cv2.findHomography(bxy[idx], det[i_det], 0)
        if hmat is not None:
            pred = cv2.perspectiveTransform(bxy.reshape(-1, 1, 2), hmat).reshape(-1, 2)
            i_det, idx = match_nearest(det, pred, radius)
    if len(idx) < 4:
        raise ValueError(f"the detected corners do not match the expected ones (fewer than "
                         f"4 within {radius:.0f} px after removing the median offset "
                         f"{np.round(shift, 1).tolist()} px): the approximate parameters "
                         "or pose are too far off")
    px, idx = on_grid(det[i_det], idx, bxy, 0.1 * spacing)
    # A mirror image of the board is a homography too, so a mirrored expectation can match
    # every corner with every label wrong (a small view of a symmetric grid): only the
    # board's handedness, as the camera sees it, tells.
    if orientation(px, idx, board) != handedness(board):
        raise ValueError("the expected corner pixels are a mirror image of the board as "
                         "the camera sees it (its rows and columns swapped or one of "
                         "them reversed): numbering them would label every corner wrong")
    # The median offset taken out above makes any common error of the prediction look
    # small: a prediction off by more than half a square would number every corner one
    # square off. Placed on the board without it, the numbering must be clearly the best.
    if np.ptp(idx // board.cols) > 0 and np.ptp(idx % board.cols) > 0:
        idx = place_grid(px, idx // board.cols, idx % board.cols, board, expected, spacing,
                         JUNCTION_RATIO, 1.0, f"the {len(idx)} corners found")
    return refine_and_extend(gray, px, idx, board, spacing, options.extend, "expected",
                             refine=options.refine)


def _numbered_top_left(gray: np.ndarray, board: Any, options: CornerOptions) -> Corners:
    """:func:`find_corners` of a whole board, numbered by the top-left rule."""
    n_board = board.rows * board.cols
    grid, by_sb = _whole_board(gray, board, options.fallback)
    spacing = corner_spacing(grid.reshape(-1, 2))
    base = np.arange(n_board).reshape(board.rows, board.cols)
    cands = [base, base[::-1, ::-1], base[::-1, :], base[:, ::-1]]
    if board.rows == board.cols:
        cands += [c.T for c in cands]
    sign = handedness(board)
    cands = [c for c in cands if orientation(grid, c, board) == sign]
    # placement c says grid point (i, j) is board corner c[i, j]; r0c0 sits where c == 0
    first = [grid.reshape(-1, 2)[int(np.argmin(c.ravel()))] for c in cands]
    c = cands[int(np.argmin([p.sum() for p in first]))]
    idx = c.ravel()
    px = grid.reshape(-1, 2)
    corners = refine_and_extend(gray, px, idx, board, spacing, options.extend, "top-left",
                                refine=options.refine)
    if not by_sb:
        return corners
    detected = np.full((n_board, 2), np.nan)
    detected[idx] = px
    return replace(corners, detected=detected)


def _whole_board(gray: np.ndarray, board: Any, fallback: bool) -> tuple[np.ndarray, bool]:
    """(rows, cols, 2) pixels of a fully visible board's corners in OpenCV's grid order:
    ``findChessboardCornersSB``, else (``fallback``) the classic ``findChessboardCorners``;
    and whether they are ``findChessboardCornersSB``'s own full-resolution positions.
    Raises :class:`BoardNotFoundError`.

    The search runs first on the image halved (``INTER_AREA``) with ``CALIB_CB_ACCURACY``
    (its search on an upsampled image): at a quarter of the pixels it costs about what the
    plain search costs at full size (OpenCV's samples: 36-112 ms against 109-545 ms for the
    full-size accurate search), and it finds boards the plain search misses or takes wrongly
    (left01.jpg: the plain search finds no 9 x 6 board but a 9 x 7 one; left05.jpg: the
    full-size accurate search finds none). Its corners are within a few pixels and are
    refined at full size (:func:`refine_and_extend`). The full-size accurate search runs only
    where the halved one finds nothing."""
    import cv2
    size = (board.cols, board.rows)
    accurate = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    n = board.rows * board.cols
    h, w = gray.shape
    win = None
    if min(h, w) >= 2 * _MIN_HALF_SIDE:
        half = cv2.resize(gray, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        # by keyword: the Python signature takes ``corners`` third; OpenCV's RNG (its random
        # samples; per thread) seeded, so that the result depends on the image alone
        cv2.setRNGSeed(0)
        ok, found = cv2.findChessboardCornersSB(half, size, flags=accurate)
        if ok and found is not None and found.size == 2 * n:
            # a halved pixel i covers full pixels 2i and 2i + 1: its centre is 2i + 0.5
            px = found.reshape(-1, 2).astype(float) * 2.0 + 0.5
            spacing = corner_spacing(px)
            win = subpix_window(spacing)
            m = win + 2
            fits = (px[:, 0] >= m) & (px[:, 0] <= w - 1 - m) & (px[:, 1] >= m) & \
                (px[:, 1] <= h - 1 - m)
            ref = px.copy()
            ref[fits] = refine_subpix(gray, px[fits], win)
            # the halved search is good to about a pixel of the halved image: a corner the
            # full-size refinement moves farther than that fell off its junction
            if (np.linalg.norm(ref - px, axis=1) < max(2.5, 0.15 * spacing)).all():
                return ref.reshape(board.rows, board.cols, 2), False
    cv2.setRNGSeed(0)
    ok, found = cv2.findChessboardCornersSB(gray, size, flags=accurate)
    tried = "findChessboardCornersSB"
    by_sb = bool(ok) and found is not None
    if not by_sb and fallback:
        ok, found = cv2.findChessboardCorners(
            gray, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        tried += " and findChessboardCorners"
    if not ok and fallback and _dark(gray):
        ok, found = _in_the_dark(gray, size)
        tried += " and findChessboardCorners on the dark frame's contrast equalised"
    if not ok or found is None or found.size != 2 * n:
        raise BoardNotFoundError(
            f"no fully visible {board.rows} x {board.cols} checkerboard found in the image "
            f"({tried} found none); for a partly visible board pass the expected corner "
            "pixels to find_corners")
    return found.reshape(board.rows, board.cols, 2).astype(float), by_sb


#: the halved image's shorter side must be at least this (px) for the halved search
_MIN_HALF_SIDE = 200

#: a frame is dark when its median lies below this fraction of the full scale
DARK_MEDIAN = 0.1


def _dark(gray: np.ndarray) -> bool:
    top = float(np.iinfo(gray.dtype).max) if gray.dtype.kind in "ui" else 1.0
    return float(np.median(gray)) < DARK_MEDIAN * top


def _in_the_dark(gray: np.ndarray, size: tuple[int, int]) -> tuple[bool, np.ndarray | None]:
    """The classic ``findChessboardCorners`` on a dark frame's contrast equalised (CLAHE,
    clip limit 3 on 8 x 8 tiles), where the board's squares differ by a few grey levels
    only: a public robot capture's frame of median 18 of 255 beside a saturated stripe,
    whose board neither detector finds as it is (nor ``findChessboardCornersSB`` equalised).
    With OpenCV's fast check, which turns frames without a board away first: the Blaser
    sessions' 11 laser-only frames taken in the dark cost 4-17 ms each at 640 x 480 and
    10-390 ms at 1280 x 960 (against 40-400 ms without it). The corners are refined on the
    frame itself."""
    import cv2

    eq = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(np.ascontiguousarray(gray))
    ok, found = cv2.findChessboardCorners(eq, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                          | cv2.CALIB_CB_NORMALIZE_IMAGE
                                          | cv2.CALIB_CB_FAST_CHECK)
    return bool(ok), found


def sb_positions(image: np.ndarray, corners: Corners) -> Corners:
    """``corners`` with ``detected`` set: ``findChessboardCornersSB``'s own positions from
    its full-size accurate search (``CALIB_CB_EXHAUSTIVE | CALIB_CB_ACCURACY``), matched to
    the numbered corners (each within a quarter of the corner spacing); ``corners``
    unchanged when that search finds no whole board. Costly (4-5x the halved search): for
    :func:`prefer_detected`, which asks only when the refined corners fit poorly."""
    import cv2

    board = corners.board
    gray = to_8bit(as_gray(image, "the image", None))
    cv2.setRNGSeed(0)
    ok, found = cv2.findChessboardCornersSB(
        gray, (board.cols, board.rows),
        flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not ok or found is None or len(corners) < 2:
        return corners
    det = found.reshape(-1, 2).astype(float)
    spacing = corner_spacing(np.asarray(corners.pixels, float))
    d = np.linalg.norm(det[:, None] - corners.pixels[None], axis=2)
    near = np.argmin(d, axis=1)
    close = d[np.arange(len(det)), near] < 0.25 * spacing
    detected = np.full((board.rows * board.cols, 2), np.nan)
    detected[corners.index[near[close]]] = det[close]
    return replace(corners, detected=detected)


def detect_board(image: np.ndarray, board: BoardSpec | Checkerboard,
                 options: CornerOptions | None = None) -> Corners:
    """The corners of a fully visible checkerboard, numbered without any prior model.

    ``findChessboardCornersSB`` (falling back to ``findChessboardCorners``, see
    :class:`CornerOptions`) finds the ``board.rows x board.cols`` inner corners, which are
    refined with ``cornerSubPix`` as in :func:`find_corners`.

    Numbering rule (``Corners.rule == "top-left"``): a checkerboard looks the same turned by
    180 degrees (and, if square, by 90), so the image alone cannot tell corner r0c0 from the
    opposite one. Of the numberings with the board's handedness (the camera sees the side
    ``board.normal`` points to; with the default board that is the side where the board
    frame's z = x (rows) x y (columns) axis points), the one whose r0c0 is nearest the
    image's top-left corner (smallest u + v) is returned. This is consistent between views
    only while the board appears rotated by less than about 90 degrees from one view to the
    next. A hand-mounted camera that rolls further sees some views numbered the other way
    round: those views need :func:`flip_board_numbering`, decided by the caller (e.g. from
    the robot poses).

    Returns
    -------
    Corners (all ``board.rows * board.cols`` corners unless some lie too close to the image
    border for the refinement window)

    Raises
    ------
    BoardNotFoundError (a ``ValueError``) when no whole board is found; ``ValueError`` for
    an image that is not 8- or 16-bit.
    """
    return find_corners(image, board, None, options=options)


def flip_board_numbering(corners: Corners) -> Corners:
    """The same corners numbered from the opposite board corner (a 180-degree turn of the
    board: (r, c) -> (rows - 1 - r, cols - 1 - c)). The handedness is kept; applying it
    twice gives the original numbering."""
    board = corners.board
    idx = board.rows * board.cols - 1 - np.asarray(corners.index)
    order = np.argsort(idx)
    rule = corners.rule[:-len(" flipped")] if corners.rule.endswith(" flipped") \
        else corners.rule + " flipped"
    detected = None if corners.detected is None else corners.detected[::-1].copy()
    return replace(corners, pixels=corners.pixels[order], index=idx[order],
                   anchor=corners.anchor[order], rule=rule, detected=detected)


def predicted_corners(params: Any, pose: np.ndarray, board: Any) -> np.ndarray:
    """Pixels (rows*cols, 2) where the board's corners appear at a base_from_hand pose
    (row-major corner order, NaN behind the camera); for identifying detected corners."""
    corners = board.corners()
    px, ok = project(params, corners, np.repeat(np.asarray(pose, float)[None], len(corners),
                                                axis=0))
    px[~ok] = np.nan
    return px


def _calibration_rms(views: list[Corners], image_size: tuple[int, int]) -> float:
    """OpenCV's calibration RMS (px) of one camera (5 distortion terms) over ``views``."""

    obj = [np.c_[c.board_xy, np.zeros(len(c))].astype(np.float32) for c in views]
    img = [np.ascontiguousarray(c.pixels, np.float32).reshape(-1, 1, 2) for c in views]
    return float(calibrate_camera(obj, img, tuple(int(x) for x in image_size), None,
                                     None)[0])


def prefer_detected(views: list[Corners], image_size: tuple[int, int],
                    images: dict[int, Any] | None = None
                    ) -> tuple[bool, float, float, list[Corners]]:
    """Whether a session's whole boards are better taken at ``findChessboardCornersSB``'s own
    positions than refined (:func:`find_corners`): (prefer, refined RMS, detected RMS, the
    views with the detector's positions where they were searched for).

    The refinement (``cornerSubPix``, then the saddle point) is the more accurate on sharp
    images (renders: 0.01 against 0.1 px per axis; OpenCV's real samples: calibration RMS
    0.17 against 0.18 px), but on a soft, chroma-blocked camera image it can be pulled off
    the junction (the Blaser 1280 x 960 session: 1.7 px against 0.32 px). The choice is the
    session's: the positions with which one camera fits all the views better (OpenCV's
    calibration RMS over the views that have both, at least 3), never one view's.

    Views without ``detected`` positions get them from ``images`` (``images[k]``: the image
    of ``views[k]``, :func:`sb_positions`), but only when the refined corners fit worse than
    :data:`SB_FLOOR_PX`: the detector's own positions fit no session better than that (renders
    about 0.1 px, OpenCV's samples 0.18, the Blaser sessions 0.28 and 0.32), so below it the
    costly search cannot pay."""
    views = list(views)
    usable = [k for k, c in enumerate(views) if len(c) >= 6]
    if len(usable) < 3:
        return False, float("nan"), float("nan"), views
    if images is not None and any(views[k].detected is None for k in usable):
        refined = _calibration_rms([views[k] for k in usable], image_size)
        if refined <= SB_FLOOR_PX:
            return False, refined, float("nan"), views
        for k in usable:
            if views[k].detected is None and images.get(k) is not None:
                views[k] = sb_positions(images[k], views[k])
    both = [c for c in views if c.detected is not None and len(c) >= 6]
    if len(both) < 3:
        return False, float("nan"), float("nan"), views
    refined = _calibration_rms(both, image_size)
    raw = _calibration_rms([c.as_detected() for c in both], image_size)
    return bool(raw < refined), refined, raw, views


#: calibration RMS (px) below which findChessboardCornersSB's own positions cannot improve
#: on the refined corners (see prefer_detected)
SB_FLOOR_PX = 0.15
