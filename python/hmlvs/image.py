"""The image pipeline: laser on/off images -> stripe centres, board corners, calibration points.

The pixel work (difference image, sub-pixel stripe centres) runs in C++ (``hmlvs._core``) on
the numpy buffers in place; corners come from OpenCV's ``findChessboardCornersSB``. Pixels
are (u = column, v = row), 0-based, pixel centres at integers.

Typical use::

    d = hmlvs.difference_image(on, off)             # paper Eq. 23
    stripe = hmlvs.extract_stripe(d)                 # one centre per image column
    corners = hmlvs.find_corners(off, board, expected=predicted_corner_pixels)
    pts = hmlvs.calibration_points(stripe, corners, board, mode="corners")
"""

from __future__ import annotations

from dataclasses import dataclass, field
import enum
from pathlib import Path
from typing import Any, Literal

import numpy as np

from . import _core

Direction = Literal["columns", "rows"]
Method = Literal["centroid", "gaussian", "steger"]


class StripeStatus(enum.IntEnum):
    """Outcome of one scan line (image column or row) of :func:`extract_stripe`."""

    FOUND = 0       #: one stripe peak, centre measured
    NONE = 1        #: nothing above the threshold
    MULTIPLE = 2    #: two or more plausible peaks (reflections): no centre is guessed
    TOO_NARROW = 3  #: only peaks narrower than ``min_width`` (noise, hot pixels)
    TOO_WIDE = 4    #: only peaks wider than ``max_width`` (glare, blobs)
    FIT_FAILED = 5  #: a peak, but the method could not fit it (e.g. saturated flat top)


# ------------------------------------------------------------------------------------------
# Input checks


def _as_gray(image: Any, name: str, channel: int | None) -> np.ndarray:
    """A 2D uint8/uint16 view of ``image``; colour is converted (or one channel taken)."""
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array (an image), got {type(image).__name__}")
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{name} must be an 8- or 16-bit image (uint8 or uint16), got dtype "
                         f"{image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3:
        nch = image.shape[2]
        if nch not in (3, 4):
            raise ValueError(f"{name} has {nch} channels; expected 1 (gray), 3 (BGR) or 4 (BGRA)")
        if channel is not None:
            if not 0 <= channel < nch:
                raise ValueError(f"channel must be in 0..{nch - 1} for {name} with {nch} "
                                 f"channels, got {channel}")
            return image[:, :, channel]  # a strided view; the core reads it in place
        import cv2
        code = cv2.COLOR_BGR2GRAY if nch == 3 else cv2.COLOR_BGRA2GRAY
        return cv2.cvtColor(np.ascontiguousarray(image), code)
    if image.ndim != 2:
        raise ValueError(f"{name} must be a 2D grayscale or 3D colour array, got shape "
                         f"{image.shape}")
    if channel is not None:
        raise ValueError(f"channel={channel} was given but {name} is grayscale")
    if image.size == 0:
        raise ValueError(f"{name} is empty (shape {image.shape})")
    return image


def difference_image(on: np.ndarray, off: np.ndarray, channel: int | None = None,
                     normalize: bool = False, scale: float | None = None,
                     floor: float | None = None) -> np.ndarray:
    """Laser-on minus laser-off, clipped at zero (paper Eq. 23), optionally albedo-normalised.

    Parameters
    ----------
    on, off : 8- or 16-bit images of the same size and depth, grayscale (rows x cols) or
        colour (rows x cols x 3 BGR / 4 BGRA as OpenCV reads them).
    channel : for colour images, the channel to use (e.g. 2 for the red channel of a red
        laser in BGR); None converts colour to gray.

    Returns
    -------
    (rows, cols) array of the input's dtype: ``on - off`` where ``on > off``, else 0.
    """
    a = _as_gray(on, "the laser-on image", channel)
    b = _as_gray(off, "the laser-off image", channel)
    if a.shape != b.shape:
        raise ValueError(f"the laser-on image is {a.shape[1]} x {a.shape[0]} pixels but the "
                         f"laser-off image is {b.shape[1]} x {b.shape[0]}")
    return _core._difference_image(a, b, bool(normalize),
                                   -1.0 if scale is None else _positive(scale, "scale"),
                                   -1.0 if floor is None else _positive(floor, "floor"))


# ------------------------------------------------------------------------------------------
# Stripe centres


@dataclass(frozen=True)
class StripeResult:
    """Sub-pixel stripe centres, one entry per scan line.

    For ``direction="columns"`` (a roughly horizontal stripe) the scan lines are image
    columns: ``position`` is the column u and ``centre`` the sub-pixel row v. For
    ``direction="rows"`` they are image rows: ``position`` is v and ``centre`` is u.

    Attributes
    ----------
    position : (n,) scan line index (u for columns, v for rows)
    centre : (n,) sub-pixel centre across the scan line (px), NaN unless found
    intensity : (n,) peak pixel value of the chosen (or strongest) peak, NaN if none
    width : (n,) full width at half maximum of that peak (px), NaN if none
    sigma : (n,) 1-sigma uncertainty of ``centre`` from pixel noise alone (px), NaN unless
        found. It does not include biases (blur, albedo edges, model error).
    status : (n,) :class:`StripeStatus` codes (uint8)
    num_peaks : (n,) number of peaks of plausible or too large width on the scan line
    direction, method : the options used
    threshold, noise : intensity threshold and per-pixel noise level used
    """

    position: np.ndarray
    centre: np.ndarray
    intensity: np.ndarray
    width: np.ndarray
    sigma: np.ndarray
    status: np.ndarray
    num_peaks: np.ndarray
    direction: str
    method: str
    threshold: float
    noise: float

    @property
    def found(self) -> np.ndarray:
        """(n,) bool: scan lines with a measured centre."""
        return self.status == StripeStatus.FOUND

    @property
    def pixels(self) -> np.ndarray:
        """(k, 2) pixels (u, v) of the found centres."""
        f = self.found
        if self.direction == "columns":
            return np.stack([self.position[f].astype(float), self.centre[f]], axis=1)
        return np.stack([self.centre[f], self.position[f].astype(float)], axis=1)

    def counts(self) -> dict[str, int]:
        """Number of scan lines per status, by name (``{"FOUND": 612, "NONE": 28, ...}``)."""
        return {s.name: int(np.count_nonzero(self.status == s)) for s in StripeStatus}


_DIRECTIONS = {"columns": _core._StripeDirection.columns, "rows": _core._StripeDirection.rows}
_METHODS = {"centroid": _core._StripeMethod.centroid, "gaussian": _core._StripeMethod.gaussian,
            "steger": _core._StripeMethod.steger}


def extract_stripe(image: np.ndarray, direction: Direction = "columns",
                   method: Method = "centroid", threshold: float | None = None,
                   min_width: float = 2.0, max_width: float = 20.0,
                   noise: float | None = None, steger_sigma: float = 1.5,
                   dominance: float = 0.0, channel: int | None = None) -> StripeResult:
    """Sub-pixel laser stripe centres, one per image column (or row), computed in C++.

    Parameters
    ----------
    image : difference image (see :func:`difference_image`), 8- or 16-bit, grayscale or
        colour (converted, or ``channel`` taken). It is read in place, without a copy.
    direction : "columns" for a roughly horizontal stripe (one row coordinate per column),
        "rows" for a roughly vertical one (one column coordinate per row).
    method : "centroid" (gray centroid of ``I - threshold`` over the run of pixels above the
        threshold), "gaussian" (three-point Gaussian fit through the peak pixel) or "steger"
        (Hessian line detector at scale ``steger_sigma``; for curved or steep stripes).
    threshold : a pixel belongs to a peak when its value exceeds this. Default: automatic,
        ``max(5 * noise, 0.15 * image maximum)``.
    min_width, max_width : accepted full width at half maximum of a peak (px). Narrower
        peaks are noise and ignored; wider ones (glare) compete with the stripe.
    noise : per-pixel noise standard deviation (intensity units) for ``sigma``. Default:
        estimated from the image's background as a zero-clipped difference of two noisy
        frames, plus the quantisation noise of two rounded frames.
    dominance : 0 (default) reports a scan line with two plausible peaks as MULTIPLE. A
        ratio d >= 1 instead accepts the strongest peak if it is d times brighter than any
        other.

    Returns
    -------
    StripeResult
    """
    if direction not in _DIRECTIONS:
        raise ValueError(f"direction must be 'columns' or 'rows', got {direction!r}")
    if method not in _METHODS:
        raise ValueError(f"method must be 'centroid', 'gaussian' or 'steger', got {method!r}")
    img = _as_gray(image, "the image", channel)
    o = _core._StripeOptions()
    o.direction = _DIRECTIONS[direction]
    o.method = _METHODS[method]
    o.threshold = -1.0 if threshold is None else _nonneg(threshold, "threshold")
    o.noise = -1.0 if noise is None else _nonneg(noise, "noise")
    o.min_width = float(min_width)
    o.max_width = float(max_width)
    o.steger_sigma = float(steger_sigma)
    o.dominance = float(dominance)
    r = _core._extract_stripe(img, o)
    n = r.centre.shape[0]
    return StripeResult(
        position=np.arange(n), centre=np.asarray(r.centre), intensity=np.asarray(r.intensity),
        width=np.asarray(r.width), sigma=np.asarray(r.sigma),
        status=np.asarray(r.status, dtype=np.uint8), num_peaks=np.asarray(r.num_peaks),
        direction=direction, method=method, threshold=float(r.threshold), noise=float(r.noise))


def _positive(x: Any, name: str) -> float:
    x = float(x)
    if not (np.isfinite(x) and x > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {x}")
    return x


def _nonneg(x: Any, name: str) -> float:
    x = float(x)
    if not (np.isfinite(x) and x >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {x}")
    return x


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
      pose (:func:`hmlvs.render.predicted_corners`). The detected corners (found with
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

    from .board import Checkerboard
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


# ------------------------------------------------------------------------------------------
# Calibration points

Mode = Literal["corners", "homography"]


@dataclass(frozen=True)
class CalibrationPoints:
    """Stripe pixels paired with reference points of one image.

    Attributes
    ----------
    pixels : (m, 2) stripe pixels (u, v)
    points : (m, 3) reference points in the robot base frame (mm)
    board_xy : (m, 2) the same points in board coordinates (mm)
    ids : (m,) point ids within the image: the corner id (``"r2c4"``) in "corners" mode,
        ``"u312"`` / ``"v87"`` (the scan line) in "homography" mode
    sigma : (m,) 1-sigma uncertainty (px) of the stripe pixel across the stripe, from noise
    distance : (m,) signed distance (px) from the corner to the stripe centre line
        ("corners" mode; 0 in "homography" mode)
    mode : "corners" or "homography"
    rejected : reasons why candidate corners near the stripe (or stripe pixels) were not
        used, e.g. ``{"r1c3": "stripe not found on both sides of the corner"}``
    """

    pixels: np.ndarray
    points: np.ndarray
    board_xy: np.ndarray
    ids: np.ndarray
    sigma: np.ndarray
    distance: np.ndarray
    mode: str
    rejected: dict[str, str] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.pixels.shape[0])


def _to_base(board: Any, xy: np.ndarray) -> np.ndarray:
    t = board.base_from_board()
    return xy @ t[:3, :2].T + t[:3, 3]


def _scan_coords(stripe: StripeResult, pts: np.ndarray) -> np.ndarray:
    """(u, v) pixels -> (scan position, across) coordinates of the stripe's scan lines."""
    return pts if stripe.direction == "columns" else pts[:, ::-1]


def calibration_points(stripe: StripeResult, corners: Corners, board: Any = None,
                       mode: Mode = "corners", tolerance: float = 0.5, window: int = 4,
                       step: int = 8) -> CalibrationPoints:
    """Pair the stripe's pixels with reference points on the board.

    Parameters
    ----------
    stripe : stripe centres of the image (:func:`extract_stripe`)
    corners : numbered corners of the same image (:func:`find_corners`)
    board : the board (default: ``corners.board``)
    mode :
        "corners" (the paper's procedure): a corner is on the stripe when the stripe's
        centre line passes within ``tolerance`` px of it. The centre line near the corner is
        a weighted straight-line fit to the found centres within ``window`` scan lines on
        either side (both sides required, which also cancels the opposite biases the
        stripe picks up on the two sides of a corner); the pixel is the foot of the
        perpendicular from the corner onto that line and the reference point is the
        corner. A corner within ``tolerance`` that is not exactly on the laser plane
        gives an error of up to ``tolerance`` px, so keep it small.
        "homography" (beyond the paper): every ``step``-th found stripe centre on the board
        is mapped to board coordinates by the homography of the four corners of the square
        it lies in (all four must have been found), then to the base frame; the reference
        points are points of the board plane where the stripe is, many per image. Radial
        distortion is taken out first: the division model of MODEL.md about the image
        centre, its coefficient fitted so that all corners obey one homography.
    """
    if mode not in ("corners", "homography"):
        raise ValueError(f"mode must be 'corners' or 'homography', got {mode!r}")
    if not isinstance(stripe, StripeResult):
        raise ValueError("stripe must be the StripeResult of extract_stripe")
    if not isinstance(corners, Corners):
        raise ValueError("corners must be the Corners of find_corners")
    board = corners.board if board is None else board
    if (board.rows, board.cols) != (corners.board.rows, corners.board.cols):
        raise ValueError(f"the corners were numbered on a {corners.board.rows} x "
                         f"{corners.board.cols} board, not this {board.rows} x {board.cols} one")
    if not tolerance > 0:
        raise ValueError(f"tolerance must be > 0 px, got {tolerance}")
    if int(window) < 1 or int(step) < 1:
        raise ValueError(f"window and step must be >= 1, got {window} and {step}")
    found = stripe.found
    pos = stripe.position[found].astype(float)
    cen = stripe.centre[found]
    sig = stripe.sigma[found]
    rejected: dict[str, str] = {}
    if mode == "corners":
        rows = []
        cs = _scan_coords(stripe, corners.pixels)
        all_lines = stripe.position.astype(float)
        for k, cid in enumerate(corners.ids):
            s0, a0 = cs[k]
            near = np.abs(pos - s0) <= window
            # is the stripe near this corner at all? use any line within the window
            lines = np.abs(all_lines - s0) <= window
            if not lines.any():
                continue
            if near.sum() < 3 or not ((pos[near] < s0).any() and (pos[near] > s0).any()):
                c_near = stripe.centre[lines & found] if (lines & found).any() else None
                if c_near is not None and np.nanmin(np.abs(c_near - a0)) <= tolerance + 2:
                    rejected[cid] = "stripe not found on both sides of the corner"
                continue
            x = pos[near] - s0
            wts = 1.0 / np.maximum(sig[near], 1e-3) ** 2
            A = np.stack([np.ones_like(x), x], axis=1)
            cov = np.linalg.inv(A.T @ (A * wts[:, None]))
            a, b = cov @ (A.T @ (wts * cen[near]))
            dist = (a0 - a) / np.hypot(1.0, b)
            if abs(dist) > tolerance:
                if abs(dist) <= 3 * tolerance:
                    rejected[cid] = f"stripe passes {dist:+.2f} px from the corner (tolerance " \
                                    f"{tolerance:g})"
                continue
            foot_s = s0 + (a0 - a) * b / (1.0 + b * b)
            foot_a = a + b * (foot_s - s0)
            rows.append((k, cid, foot_s, foot_a, float(np.sqrt(cov[0, 0])), dist))
        if not rows:
            return _empty_points(mode, rejected)
        k_idx = np.array([r[0] for r in rows])
        sa = np.array([[r[2], r[3]] for r in rows])
        px = sa if stripe.direction == "columns" else sa[:, ::-1]
        xy = corners.board_xy[k_idx]
        return CalibrationPoints(px, corners.points[k_idx], xy, np.array([r[1] for r in rows]),
                                 np.array([r[4] for r in rows]), np.array([r[5] for r in rows]),
                                 mode, rejected)

    import cv2
    if len(corners) < 4:
        return _empty_points(mode, {"board": "fewer than 4 corners"})
    sel = np.arange(0, pos.size, int(step))
    spx = np.stack([pos[sel], cen[sel]], axis=1) if stripe.direction == "columns" else \
        np.stack([cen[sel], pos[sel]], axis=1)
    ssig = sig[sel]
    sq = board.square
    # Radial distortion bends the board's lines, which a homography cannot follow. Fit the
    # model's division distortion p_u = c + (p - c) / (1 + k |p - c|^2) about the image
    # centre so that the corners best fit one homography, and map undistorted pixels.
    centre, k_px = _fit_division_distortion(corners)
    cpx = _undistort(corners.pixels, centre, k_px)
    spx_u = _undistort(spx, centre, k_px)
    lookup = {int(i): cpx[j] for j, i in enumerate(corners.index)}
    hmat, _ = cv2.findHomography(cpx, corners.board_xy, 0)
    if hmat is None:
        return _empty_points(mode, {"board": "no homography from the corners"})
    rough = cv2.perspectiveTransform(spx_u.reshape(-1, 1, 2), hmat).reshape(-1, 2)
    out_px, out_xy, out_ids, out_sig = [], [], [], []
    cache: dict[tuple[int, int], np.ndarray | None] = {}

    def cell_h(i: int, j: int) -> np.ndarray | None:
        if (i, j) not in cache:
            ids4 = [(i + di) * board.cols + (j + dj) for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1))]
            ok = 0 <= i < board.rows - 1 and 0 <= j < board.cols - 1 and \
                all(k in lookup for k in ids4)
            cache[(i, j)] = cv2.getPerspectiveTransform(
                np.array([lookup[k] for k in ids4], np.float32),
                (np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32) +
                 np.array([i, j], np.float32)) * np.float32(sq)) if ok else None
        return cache[(i, j)]

    n_outside = n_missing = 0
    for p, pu, rxy, sg in zip(spx, spx_u, rough, ssig):
        i, j = int(np.floor(rxy[0] / sq)), int(np.floor(rxy[1] / sq))
        placed = None
        for _ in range(2):  # the rough (global) homography may pick a neighbouring square
            hm = cell_h(i, j)
            if hm is None:
                break
            xy = cv2.perspectiveTransform(pu.reshape(1, 1, 2), hm).reshape(2)
            ii, jj = int(np.floor(xy[0] / sq)), int(np.floor(xy[1] / sq))
            if (ii, jj) == (i, j):
                placed = xy
                break
            i, j = ii, jj
        if placed is None:
            if 0 <= i < board.rows - 1 and 0 <= j < board.cols - 1:
                n_missing += 1
            else:
                n_outside += 1
            continue
        out_px.append(p)
        out_xy.append(placed)
        out_ids.append(f"u{int(round(p[0]))}" if stripe.direction == "columns"
                       else f"v{int(round(p[1]))}")
        out_sig.append(sg)
    if n_missing:
        rejected["squares"] = f"{n_missing} stripe pixels in squares without all four corners"
    if n_outside:
        rejected["outside"] = f"{n_outside} stripe pixels outside the inner corners' area"
    if not out_px:
        return _empty_points(mode, rejected)
    xy = np.array(out_xy)
    return CalibrationPoints(np.array(out_px), _to_base(board, xy), xy, np.array(out_ids),
                             np.array(out_sig), np.zeros(len(out_px)), mode, rejected)


def _undistort(px: np.ndarray, centre: np.ndarray, k: float) -> np.ndarray:
    d = px - centre
    return centre + d / (1.0 + k * np.sum(d * d, axis=1, keepdims=True))


def _fit_division_distortion(corners: Corners) -> tuple[np.ndarray, float]:
    """(centre, k) of the division model (MODEL.md step 2, in pixels: k_px = k Su^2) that
    makes the corners fit one homography best; k = 0 with fewer than 9 corners."""
    import cv2
    from scipy.optimize import minimize_scalar
    if corners.image_size is not None:
        w, h = corners.image_size
        centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    else:
        centre = corners.pixels.mean(axis=0)
    if len(corners) < 9:
        return centre, 0.0
    r2max = float(np.max(np.sum((corners.pixels - centre) ** 2, axis=1)))
    xy = corners.board_xy

    def cost(kn: float) -> float:
        u = _undistort(corners.pixels, centre, kn / r2max)
        hm, _ = cv2.findHomography(xy, u, 0)
        if hm is None:
            return np.inf
        return float(np.sum((cv2.perspectiveTransform(xy.reshape(-1, 1, 2), hm).reshape(-1, 2)
                             - u) ** 2))

    # |k r^2| up to 10 % at the farthest corner
    res = minimize_scalar(cost, bounds=(-0.1, 0.1), method="bounded",
                          options={"xatol": 1e-7})
    return centre, float(res.x) / r2max


def _empty_points(mode: str, rejected: dict[str, str]) -> CalibrationPoints:
    return CalibrationPoints(np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 2)),
                             np.array([], dtype=str), np.zeros(0), np.zeros(0), mode, rejected)


# ------------------------------------------------------------------------------------------
# A session of images -> a calibration data set


@dataclass(frozen=True)
class ImageReport:
    """What :func:`dataset_from_images` found in one image pair, and what it rejected.

    Attributes
    ----------
    id : the pose id (``"p003"``)
    index : position of the pair in the session (the data set's ``pose_index``)
    on, off : the image files (or ``"<array>"``)
    ok : True when the pair gave at least one calibration point
    reason : why the whole pair was rejected ("" when ok)
    stripe : scan lines per stripe status (``{"FOUND": 612, "MULTIPLE": 3, ...}``)
    corners : corners found and numbered
    points : calibration points contributed
    rejected : candidate points not used, with the reason for each
    """

    id: str
    index: int
    on: str
    off: str
    ok: bool
    reason: str = ""
    stripe: dict[str, int] = field(default_factory=dict)
    corners: int = 0
    points: int = 0
    rejected: dict[str, str] = field(default_factory=dict)

    def __str__(self) -> str:
        if not self.ok:
            return f"{self.id}: rejected: {self.reason}"
        extra = f"; not used: {len(self.rejected)}" if self.rejected else ""
        return (f"{self.id}: {self.points} points, {self.corners} corners, stripe in "
                f"{self.stripe.get('FOUND', 0)} scan lines{extra}")


class _Reject(Exception):
    """A whole image pair is unusable (the message says why)."""


def _load(item: Any, folder: Any, what: str) -> tuple[np.ndarray, str]:
    import cv2
    from pathlib import Path
    if isinstance(item, np.ndarray):
        return item, "<array>"
    if not isinstance(item, (str, Path)):
        raise _Reject(f"the {what} image must be a file name or an array, got "
                      f"{type(item).__name__}")
    path = Path(item)
    if folder is not None and not path.is_absolute():
        path = Path(folder) / path
    if not path.is_file():
        raise _Reject(f"the {what} image file {path} does not exist")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise _Reject(f"the {what} image file {path.name} cannot be read as an image")
    return img, path.name


def _read_manifest(source: Any) -> tuple[list[dict[str, Any]], dict[str, Any], Any]:
    from .manifest import read_manifest

    return read_manifest(source)


def dataset_from_images(source: Any, *, robot: Any = None, board: Any = None,
                        params: Any = None, mode: Mode = "corners", normalize: bool = True,
                        channel: int | None = None, tolerance: float = 0.5, step: int = 8,
                        min_stripe: int = 20, joint_unit: str | None = None,
                        **stripe_options: Any) -> tuple[Any, list[ImageReport]]:
    """Laser on/off image pairs + joint readings -> a calibration :class:`~hmlvs.Dataset`.

    For every pair: difference image (albedo-normalised unless ``normalize=False``), stripe
    centres (:func:`extract_stripe` with ``stripe_options``), corners of the laser-off image
    numbered with the corners predicted from ``params`` and the pose
    (:func:`find_corners`), then :func:`calibration_points` in ``mode``. A pair that fails
    is reported and skipped; the rest of the session goes through.

    Parameters
    ----------
    source : a folder (or its ``manifest.json``) written by
        :func:`hmlvs.simulate.render_session` or in that format, or a list of records
        ``{"id": "p000", "on": file or array, "off": file or array, "joints": [...]}``
    robot : the arm (default: SCORBOT ER-VII); poses are ``robot.poses(joints)``
    board : the board (default: the manifest's, else the paper's)
    params : approximate sensor parameters, to predict where the corners are (default: the
        nominal Table 2 values). They need to place the corners within about a third of a
        square.
    mode : "corners" or "homography", see :func:`calibration_points`
    tolerance, step : passed to :func:`calibration_points`
    min_stripe : fewest scan lines with a stripe for a usable pair
    joint_unit : "rad" or "deg" for records (a manifest says its unit)

    Returns
    -------
    (dataset, report) : the data set (ids ``"<pose id>:<point id>"``, ``pose_index`` = pair
        index, joints in rad) and one :class:`ImageReport` per pair.
    """
    from .board import Checkerboard
    from .dataset import Dataset
    from .params import Parameters
    from .render import predicted_corners
    from .robot import Robot

    folder = None
    unit = joint_unit
    size = None
    if isinstance(source, (list, tuple)):
        records = list(source)
        if unit is None:
            unit = "rad"
    else:
        records, doc, folder = _read_manifest(source)
        unit = doc.get("joint_unit", "rad") if unit is None else unit
        if board is None and isinstance(doc.get("board"), dict):
            b = doc["board"]
            board = Checkerboard(**{k: tuple(v) if isinstance(v, list) else v
                                    for k, v in b.items()})
        if robot is None and doc.get("robot") not in (None, Robot.scorbot_er7().name):
            raise ValueError(f"the images were taken with robot {doc.get('robot')!r}; pass "
                             "robot=hmlvs.Robot(...) with its DH table")
        if isinstance(doc.get("image_size"), list) and len(doc["image_size"]) == 2:
            size = (int(doc["image_size"][0]), int(doc["image_size"][1]))
    if unit not in ("rad", "deg"):
        raise ValueError(f"joint_unit must be 'rad' or 'deg', got {unit!r}")
    if not records:
        raise ValueError("the session has no image pairs")
    robot = Robot.scorbot_er7() if robot is None else robot
    board = Checkerboard() if board is None else board
    approx = Parameters.nominal() if params is None else params
    # Check the stripe options once, up front: a typo is the caller's error, not the image's.
    extract_stripe(np.zeros((4, 4), np.uint8), **stripe_options)

    reports: list[ImageReport] = []
    px_all, pt_all, ids_all, joints_all, pidx_all, poses_all = [], [], [], [], [], []
    for index, rec in enumerate(records):
        pid = _record_id(rec, index)
        on_name, off_name = _record_names(rec)
        info: dict[str, Any] = {}
        try:
            pair = _read_pair(rec, index, folder, unit, robot, size, channel, normalize,
                              stripe_options, min_stripe)
            on_name, off_name, size, joints = pair.on_name, pair.off_name, pair.size, pair.joints
            stripe, off_g, pose = pair.stripe, pair.off, pair.pose
            info["stripe"] = stripe.counts()
            try:
                corners = find_corners(off_g, board, expected=predicted_corners(approx, pose,
                                                                                board))
            except ValueError as e:
                raise _Reject(f"checkerboard: {e}") from None
            info["corners"] = len(corners)
            cp = calibration_points(stripe, corners, board, mode=mode, tolerance=tolerance,
                                    step=step)
            info["rejected"] = dict(cp.rejected)
            if len(cp) == 0:
                raise _Reject("no calibration points: " + (
                    "; ".join(f"{k}: {v}" for k, v in cp.rejected.items()) or
                    ("no corner lies on the stripe" if mode == "corners" else
                     "the stripe does not cross a square with four found corners")))
        except _Reject as e:
            reports.append(ImageReport(pid, index, str(on_name), str(off_name), False, str(e),
                                       info.get("stripe", {}), info.get("corners", 0), 0,
                                       info.get("rejected", {})))
            continue
        reports.append(ImageReport(pid, index, str(on_name), str(off_name), True, "",
                                   info["stripe"], info["corners"], len(cp), info["rejected"]))
        px_all.append(cp.pixels)
        pt_all.append(cp.points)
        ids_all += [f"{pid}:{k}" for k in cp.ids]
        joints_all.append(None if joints is None else np.repeat(joints[None], len(cp), axis=0))
        poses_all.append(np.repeat(pose[None], len(cp), axis=0))
        pidx_all.append(np.full(len(cp), index, dtype=np.int64))
    if not px_all:
        raise ValueError("no image pair gave a calibration point:\n" +
                         "\n".join(str(r) for r in reports))
    joints_arr = None if any(j is None for j in joints_all) else np.vstack(joints_all)
    ds = Dataset(np.vstack(px_all), np.concatenate(poses_all), np.vstack(pt_all),
                 ids=np.array(ids_all), joints=joints_arr, pose_index=np.concatenate(pidx_all),
                 meta={"source": "images", "mode": mode, "normalize": normalize,
                       "pairs": len(records), "pairs_used": sum(r.ok for r in reports),
                       "image_size": list(size) if size else None})
    return ds, reports


def _record_id(rec: Any, index: int) -> str:
    return str(rec.get("id", f"p{index:03d}")) if isinstance(rec, dict) else f"p{index:03d}"


def _record_names(rec: Any) -> tuple[str, str]:
    if not isinstance(rec, dict):
        return "?", "?"
    return tuple(str(rec.get(k, "?")) if not isinstance(rec.get(k), np.ndarray) else "<array>"
                 for k in ("on", "off"))  # type: ignore[return-value]


def stripes_from_images(source: Any, *, robot: Any = None, joint_unit: str | None = None,
                        channel: int | None = None, normalize: bool = True,
                        min_stripe: int = 20, **stripe_options: Any
                        ) -> tuple[list[str], list[Any], np.ndarray, list[ImageReport]]:
    """Laser on/off pairs + joint readings (a manifest or a list of records) -> stripes.

    The measurement counterpart of :func:`dataset_from_images` (no checkerboard needed): for
    each pair the same checks, difference image and stripe extraction. A pair that fails is
    reported and skipped. Entries may give a stripe list (``stripe``: CSV of u, v[, intensity])
    instead of an image pair, and a ``pose`` instead of joint readings. Returns (ids, stripes,
    base_from_hand poses (n, 4, 4), reports).
    """
    from .robot import Robot

    folder = None
    unit = joint_unit
    if isinstance(source, (list, tuple)):
        records = list(source)
        unit = "rad" if unit is None else unit
    else:
        records, doc, folder = _read_manifest(source)
        unit = doc.get("joint_unit", "rad") if unit is None else unit
        if robot is None and doc.get("robot") not in (None, Robot.scorbot_er7().name):
            raise ValueError(f"the images were taken with robot {doc.get('robot')!r}; pass "
                             "robot=hmlvs.Robot(...) with its DH table")
    if unit not in ("rad", "deg"):
        raise ValueError(f"joint_unit must be 'rad' or 'deg', got {unit!r}")
    if not records:
        raise ValueError("the scan has no image pairs")
    robot = Robot.scorbot_er7() if robot is None else robot
    extract_stripe(np.zeros((4, 4), np.uint8), **stripe_options)  # option typos fail here
    from .manifest import read_stripe_list

    ids, stripes, poses, reports = [], [], [], []
    size = None
    for index, rec in enumerate(records):
        pid = _record_id(rec, index)
        on_name, off_name = _record_names(rec)
        try:
            if isinstance(rec, dict) and "stripe" in rec:
                _, pose = _record_pose(rec, robot, unit)
                path = Path(rec["stripe"])
                path = path if folder is None or path.is_absolute() else Path(folder) / path
                if not path.is_file():
                    raise _Reject(f"the stripe list {path} does not exist")
                try:
                    px, inten = read_stripe_list(path)
                except ValueError as e:
                    raise _Reject(str(e)) from None
                item: Any = StripeList(px, inten)
                on_name = off_name = path.name
                found = len(px)
            else:
                pair = _read_pair(rec, index, folder, unit, robot, size, channel, normalize,
                                  stripe_options, min_stripe)
                size, pose, item = pair.size, pair.pose, pair.stripe
                on_name, off_name = pair.on_name, pair.off_name
                found = int(pair.stripe.found.sum())
        except _Reject as e:
            reports.append(ImageReport(pid, index, on_name, off_name, False, str(e), {}, 0, 0,
                                       {}))
            continue
        ids.append(pid)
        stripes.append(item)
        poses.append(pose)
        reports.append(ImageReport(pid, index, on_name, off_name, True, "",
                                   getattr(item, "counts", lambda: {})(), 0, found, {}))
    return ids, stripes, np.array(poses).reshape(-1, 4, 4), reports


@dataclass
class _Pair:
    """One laser on/off pair after the checks shared by calibration and measurement."""

    on_name: str
    off_name: str
    joints: np.ndarray | None  # rad; None when the entry gives a pose
    pose: np.ndarray  # base_from_hand (4, 4)
    on: np.ndarray
    off: np.ndarray
    stripe: StripeResult
    size: tuple[int, int]


def _read_pair(rec: Any, index: int, folder: Any, unit: str, robot: Any,
               size: tuple[int, int] | None, channel: int | None, normalize: bool,
               stripe_options: dict[str, Any], min_stripe: int) -> _Pair:
    """Load, check and extract the stripe of one manifest record; raises _Reject."""
    if not isinstance(rec, dict):
        raise _Reject(f"record {index} is not a mapping with on, off and joints")
    for key in ("on", "off"):
        if key not in rec:
            raise _Reject(f"the record lacks '{key}'")
    joints, pose = _record_pose(rec, robot, unit)
    on, on_name = _load(rec["on"], folder, "laser-on")
    off, off_name = _load(rec["off"], folder, "laser-off")
    try:
        on_g = _as_gray(on, "the laser-on image", channel)
        off_g = _as_gray(off, "the laser-off image", channel)
    except ValueError as e:
        raise _Reject(str(e)) from None
    if on_g.shape != off_g.shape or on_g.dtype != off_g.dtype:
        raise _Reject(f"the laser-on image ({on_g.shape[1]} x {on_g.shape[0]}, "
                      f"{on_g.dtype}) and the laser-off image ({off_g.shape[1]} x "
                      f"{off_g.shape[0]}, {off_g.dtype}) differ in size or depth")
    if size is None:
        size = (on_g.shape[1], on_g.shape[0])
    if (on_g.shape[1], on_g.shape[0]) != size:
        raise _Reject(f"the images are {on_g.shape[1]} x {on_g.shape[0]} pixels but the "
                      f"session's are {size[0]} x {size[1]}")
    top = float(np.iinfo(off_g.dtype).max)
    if int(off_g.max()) == 0:
        raise _Reject("the laser-off image is all black")
    if int(on_g.max()) == 0:
        raise _Reject("the laser-on image is all black")
    diff_big = np.abs(on_g.astype(np.int32) - off_g.astype(np.int32)) > 0.1 * top
    if diff_big.mean() > 0.05:
        raise _Reject(f"the laser-on and laser-off images differ in "
                      f"{100 * diff_big.mean():.0f}% of the pixels, far more than a "
                      "stripe: they are not a pair taken at the same pose")
    stripe = stripe_from_pair(on_g, off_g, normalize=normalize, **stripe_options)
    if stripe.found.sum() < min_stripe:
        raise _Reject(f"no laser stripe found: only {int(stripe.found.sum())} scan lines "
                      f"have one ({_counts_text(stripe.counts())})")
    return _Pair(str(on_name), str(off_name), joints, pose, on_g, off_g, stripe, size)


def stripe_from_pair(on: np.ndarray, off: np.ndarray, *, normalize: bool = True,
                     channel: int | None = None, **stripe_options: Any) -> StripeResult:
    """The stripe of one laser on/off pair, as the session pipeline extracts it.

    Difference image (paper Eq. 23; divided by the laser-off frame with ``normalize``, which
    removes the pull of the board's edges on the stripe) and :func:`extract_stripe` with
    ``stripe_options``; for a normalised image without a given threshold, a noise-aware one.
    """
    on_g = _as_gray(on, "the laser-on image", channel)
    off_g = _as_gray(off, "the laser-off image", channel)
    d = difference_image(on_g, off_g, normalize=normalize)
    opts = dict(stripe_options)
    if normalize and opts.get("threshold") is None:
        opts["threshold"] = _normalized_threshold(on_g, off_g, d)
    return extract_stripe(d, **opts)


def _record_pose(rec: dict[str, Any], robot: Any, unit: str) -> tuple[np.ndarray | None,
                                                                     np.ndarray]:
    """(joints in rad or None, base_from_hand pose) of a record; raises _Reject."""
    if "pose" in rec:
        pose = np.asarray(rec["pose"], dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise _Reject("'pose' must be a finite 4x4 base_from_hand matrix")
        return None, pose
    if "joints" not in rec:
        raise _Reject("the record lacks 'joints' (or 'pose')")
    joints = np.asarray(rec["joints"], dtype=float).reshape(-1)
    if joints.shape != (robot.dof,) or not np.all(np.isfinite(joints)):
        raise _Reject(f"joint readings must be {robot.dof} finite numbers, got "
                      f"{np.asarray(rec['joints']).tolist()}")
    if unit == "deg":
        joints = np.radians(joints)
    return joints, robot.poses(joints[None])[0]


@dataclass(frozen=True)
class StripeList:
    """Stripe pixels given as a list (a manifest's ``stripe`` CSV) instead of an image."""

    pixels: np.ndarray
    intensity: np.ndarray


def _normalized_threshold(on: np.ndarray, off: np.ndarray, d: np.ndarray) -> float:
    """Automatic threshold for an albedo-normalised difference image.

    Normalising multiplies the noise by the gain mean(off) / max(off, floor), which is
    largest on dark surfaces (black squares): the global 5-sigma rule of
    :func:`extract_stripe` would let noise peaks through there. Use 5 x the plain
    difference's noise x the 95th percentile of the gain instead (and at least 0.15 x the
    image maximum, as for the plain image).
    """
    raw = _core._difference_image(on, off, False, -1.0, -1.0)
    sigma = float(_core._estimate_difference_noise(raw))
    mean = float(off.mean())
    gain = mean / np.maximum(off[::4, ::4].astype(float), max(1.0, 0.1 * mean))
    return max(5.0 * sigma * float(np.percentile(gain, 95)), 0.15 * float(d[::4].max()))


def _counts_text(counts: dict[str, int]) -> str:
    return ", ".join(f"{k.lower()} {v}" for k, v in counts.items() if v)
