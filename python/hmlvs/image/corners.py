"""Checkerboard corners: OpenCV's detectors, numbered on the board."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from numbers import Real
from typing import Any

import numpy as np

from .._arrays import robust_sigma
from .._opencv import calibrate_camera
from ..errors import BoardNotFoundError, NumberingError  # noqa: F401 (re-exported)
from ..models.paper import project
from .stripe import as_gray

# ------------------------------------------------------------------------------------------
# Options


@dataclass(frozen=True)
class CornerOptions:
    """Options of :func:`find_corners` and :func:`detect_board`, checked on construction: a
    wrong type or value gives a ``ValueError`` naming the option.

    Attributes
    ----------
    extend : follow the board's homography to corners outside the detected grid
    max_error : a detected corner matches a predicted one within this fraction of the corner
        spacing (``find_corners`` with ``expected`` only)
    fallback : when ``findChessboardCornersSB`` finds no whole board, try the classic
        ``findChessboardCorners`` (+ ``cornerSubPix``) before giving up (whole board only)
    refine : "saddle" (default): ``cornerSubPix``, then the saddle point of the smoothed
        image (:func:`saddle_refine`); "cornersubpix": ``cornerSubPix`` alone, as OpenCV's
        classic pipeline
    """

    extend: bool = True
    max_error: float = 0.35
    fallback: bool = True
    refine: str = "saddle"

    def __post_init__(self) -> None:
        for name in ("extend", "fallback"):
            v = getattr(self, name)
            if not isinstance(v, (bool, np.bool_)):
                raise ValueError(f"corners.{name} must be true or false, got {v!r}")
            object.__setattr__(self, name, bool(v))
        v = self.max_error
        if isinstance(v, bool) or not isinstance(v, Real) or not (np.isfinite(v) and v > 0):
            raise ValueError(f"corners.max_error must be a positive number, got {v!r}")
        object.__setattr__(self, "max_error", float(v))
        if self.refine not in REFINE_METHODS:
            raise ValueError(f"corners.refine must be one of {', '.join(REFINE_METHODS)}, "
                             f"got {self.refine!r}")

    @classmethod
    def from_dict(cls, values: Any) -> "CornerOptions":
        """Options from a mapping (a configuration file's ``corners:`` block); an unknown
        name raises ``ValueError`` listing the valid ones."""
        if not isinstance(values, dict):
            raise ValueError(f"corner options must be a mapping, got {type(values).__name__}")
        valid = [f.name for f in fields(cls)]
        unknown = sorted(str(k) for k in values if k not in valid)
        if unknown:
            raise ValueError(f"unknown corner option(s) {', '.join(unknown)}; valid: "
                             f"{', '.join(valid)}")
        return cls(**values)


#: corner refinements (:class:`CornerOptions` ``refine``)
REFINE_METHODS = ("saddle", "cornersubpix")


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
    rule : how the ordering was fixed: "expected" (nearest to predicted pixels),
        "top-left" (the marker-free rule for a fully visible board, :func:`detect_board`) or
        "top-left flipped" (that numbering turned by 180 degrees, :func:`flip_board_numbering`)
    """

    pixels: np.ndarray
    index: np.ndarray
    anchor: np.ndarray
    board: Any
    rule: str = "expected"
    image_size: tuple[int, int] | None = None  # (width, height) of the image
    #: (rows * cols, 2) findChessboardCornersSB's own sub-pixel positions by board index
    #: (NaN where it gave none), for a whole board it found; None otherwise
    detected: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.index.shape[0])

    def as_detected(self) -> "Corners":
        """The same board with ``findChessboardCornersSB``'s own positions (no refinement,
        no corners added by the homography); ``self`` when there are none."""
        if self.detected is None:
            return self
        idx = np.nonzero(np.isfinite(self.detected).all(axis=1))[0]
        return replace(self, pixels=self.detected[idx].copy(), index=idx,
                       anchor=np.ones(len(idx), bool))

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


def _to_8bit(gray: np.ndarray) -> np.ndarray:
    """An 8-bit copy for OpenCV's board detectors. A 16-bit image is scaled by its actual
    range (its 99.9th percentile), not by 1/256: 10- and 12-bit cameras store values up to
    1023 or 4095 in 16-bit files, which ``>> 8`` would squeeze into 0-3 or 0-15."""
    if gray.dtype == np.uint8:
        return np.ascontiguousarray(gray)
    top = float(np.percentile(gray, 99.9)) if gray.size else 0.0
    top = top if top > 0 else float(gray.max()) or 1.0
    return np.clip(gray.astype(np.float32) * (255.0 / top), 0, 255).astype(np.uint8)


def _handedness(board: Any) -> float:
    """Sign of the image cross product (row step x column step) of a board seen from the
    side its ``normal`` points to: the camera's z axis looks into the scene, so a board frame
    whose row x col points towards the camera appears clockwise (negative) in (u, v)."""
    n = np.cross(board.row_direction, board.col_direction)
    return -1.0 if float(n @ board.normal) > 0 else 1.0


def _orientation(px: np.ndarray, idx: np.ndarray, board: Any) -> float:
    """Image cross product sign of the board's row and column steps under a numbering."""
    return _orientation_rc(px, np.stack([idx // board.cols, idx % board.cols], axis=-1))


def _orientation_rc(px: np.ndarray, rc: np.ndarray) -> float:
    """Image cross product sign of the row and column steps of corners at board (row,
    column) positions ``rc``."""
    rc = np.asarray(rc).reshape(-1, 2).astype(float)
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


#: blur variance (px^2) of the image itself (the pixel's area, 1/12, and a slight optical
#: blur) assumed by the illumination correction of :func:`saddle_refine`; its result
#: changes little with it (on independent renders the same from 1 to 2 times this)
IMAGE_BLUR_VAR = 0.33
#: the largest illumination gradient (|grad log L|, 1/px) the correction takes: 0.5 % per
#: pixel, 10 times a strong vignette's; a larger fitted one is clipped to it
MAX_LIGHT_GRADIENT = 0.005


def saddle_refine(gray: np.ndarray, pts: np.ndarray, spacing: float,
                  illumination: bool = True, parity: np.ndarray | None = None) -> np.ndarray:
    """Corners ``pts`` (k, 2) moved to the saddle point of the Gaussian-smoothed image.

    A checkerboard corner is point-symmetric (opposite quadrants alike, whatever the
    perspective), so the smoothed image is too and its gradient vanishes at the corner. A
    quadratic fitted to a (2h+1)^2 window of the smoothed image, resampled (bilinear) around
    the current estimate, gives its saddle; 8 Newton steps of at most 1 px each. The window
    scales with the corner ``spacing`` (h = 0.12 spacing, 2..4 px; smoothing 0.375 h), so
    with its smoothing it reaches about a fifth of a square. ``cornerSubPix`` aligns the
    gradients over a larger window and is pulled by the blur of perspective-distorted
    edges: measured on independent renders (3 sessions of 16 views, 1 grey level of noise),
    0.022-0.023 px RMS per axis against 0.010-0.012 px for the saddle (0.008-0.010 px with
    the illumination correction below); on OpenCV's real left/right sample images the
    calibration RMS falls from 0.18/0.19 px to 0.17/0.16 px.

    ``illumination``: uneven light (vignetting, a lamp to one side) multiplies the print by
    a smooth L, which breaks the symmetry: to first order in g = grad log L the smoothed
    image gains the gradient (F0 + s2 H) g at the corner (F0 its value there, H its Hessian,
    s2 the smoothing's and the image's blur variance, :data:`IMAGE_BLUR_VAR`), and the
    saddle moves. With 6 or more corners, log F0 is fitted over them (a quadratic in the
    pixel position, linear with fewer than 10 corners; points more than 3 robust standard
    deviations (1.4826 MAD) off dropped once), its gradient taken as g (at most
    :data:`MAX_LIGHT_GRADIENT`), and the saddles are found again with that gradient taken
    out. It needs ``parity`` (k,), the corners' (row + column) on the board
    (``find_corners`` passes it; without it the corners are not corrected): where the
    squares are not square, F0 alternates from corner to corner (by 14 % at 80 degrees) with
    which diagonal is dark, which a fit without a term for it takes for light. Measured on
    independent renders with a 30 % vignette (seed 3, 16 views): 0.0075 -> 0.0047 px RMS per
    axis without noise (0.0040 with no vignette, where it changes nothing); with 1 grey
    level of noise 0.0097 -> 0.0076, 0.0114 -> 0.0097, 0.0097 -> 0.0076 px (seeds 0, 1, 3);
    on OpenCV's real left/right images the calibration RMS does not move (0.1661 / 0.1630 px
    -> 0.1663 / 0.1626 px).

    A corner is left where it was when its fit is no saddle (Hessian not indefinite), does
    not converge, reaches the image border, or would move by more than min(1 px, 0.05
    spacings)."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return pts.copy()
    import cv2
    half = int(np.clip(round(0.12 * spacing), 2, 4))
    f = cv2.GaussianBlur(np.asarray(gray, np.float32), (0, 0), 0.375 * half).astype(float)
    q, value, ok = _saddles(f, pts, spacing, half)
    if not illumination or parity is None:
        return q
    g = _light_gradient(q, value, ok, parity)
    return q if g is None else _saddles(f, pts, spacing, half, g)[0]


def _saddles(f: np.ndarray, pts: np.ndarray, spacing: float, half: int,
             light: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The saddle iteration of :func:`saddle_refine` from ``pts`` on the smoothed image
    ``f`` (window half-width ``half``), with the illumination gradient ``light`` (k, 2)
    (grad log L, 1/px) taken out if given: (the refined corners, the smoothed image's value
    at each, which of them converged)."""
    s2 = (0.375 * half) ** 2 + IMAGE_BLUR_VAR
    h, w = f.shape
    ys, xs = np.mgrid[-half:half + 1, -half:half + 1].astype(float)
    x, y = xs.ravel(), ys.ravel()
    wt = np.exp(-0.5 * (x * x + y * y) / (0.5 * half) ** 2)
    design = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1) * wt[:, None]
    fit = np.linalg.pinv(design) * wt[None, :]  # (6, K): coefficients from grey values
    q = pts.copy()
    step = np.full(len(q), np.inf)
    ok = np.ones(len(q), bool)
    value = np.full(len(q), np.nan)
    for _ in range(8):
        sx, sy = q[:, :1] + x, q[:, 1:] + y
        x0, y0 = np.floor(sx), np.floor(sy)
        inside = ((x0 >= 0) & (x0 <= w - 2) & (y0 >= 0) & (y0 <= h - 2)).all(axis=1)
        ok &= inside
        ix = np.clip(x0, 0, w - 2).astype(int)
        iy = np.clip(y0, 0, h - 2).astype(int)
        fx, fy = sx - x0, sy - y0
        z = ((1 - fx) * (1 - fy) * f[iy, ix] + fx * (1 - fy) * f[iy, ix + 1] +
             (1 - fx) * fy * f[iy + 1, ix] + fx * fy * f[iy + 1, ix + 1])
        c = z @ fit.T
        value = c[:, 5]
        if light is not None:  # the light's share of the gradient: (F0 + s2 H) g
            c[:, 3] -= c[:, 5] * light[:, 0] + s2 * (2 * c[:, 0] * light[:, 0] +
                                                      c[:, 1] * light[:, 1])
            c[:, 4] -= c[:, 5] * light[:, 1] + s2 * (c[:, 1] * light[:, 0] +
                                                      2 * c[:, 2] * light[:, 1])
        det = 4.0 * c[:, 0] * c[:, 2] - c[:, 1] ** 2
        ok &= det < 0
        safe = np.where(det < 0, det, -1.0)
        d = np.stack([-(2 * c[:, 2] * c[:, 3] - c[:, 1] * c[:, 4]),
                      -(2 * c[:, 0] * c[:, 4] - c[:, 1] * c[:, 3])], axis=1) / safe[:, None]
        d = np.clip(np.where(ok[:, None], d, 0.0), -1.0, 1.0)
        q += d
        step = np.abs(d).max(axis=1)
    ok &= (step < 1e-3) & (np.linalg.norm(q - pts, axis=1) < min(1.0, 0.05 * spacing))
    return np.where(ok[:, None], q, pts), value, ok


def _light_gradient(px: np.ndarray, value: np.ndarray, ok: np.ndarray,
                    parity: np.ndarray) -> np.ndarray | None:
    """grad log L (k, 2) at corners ``px`` from the smoothed image's ``value`` at those that
    converged (``ok``): log value fitted by a quadratic in the pixel position (linear with
    fewer than 10 corners, None with fewer than 6), refitted once without the points more
    than 3 robust standard deviations off, the gradient clipped to :data:`MAX_LIGHT_GRADIENT`."""
    good = ok & np.isfinite(value) & (value > 0)
    if good.sum() < 6:
        return None
    centre = px[good].mean(axis=0)
    scale = max(float(px[good].std()), 1.0)
    quadratic = good.sum() >= 10

    def terms(p: np.ndarray) -> np.ndarray:
        u, v = ((p - centre) / scale).T
        return np.stack([np.ones_like(u), u, v] + ([u * u, u * v, v * v] if quadratic else []),
                        axis=1)

    a, b = terms(px[good]), np.log(value[good])
    # which diagonal is dark: the value differs unless the squares are square
    a = np.hstack([a, np.where(np.asarray(parity)[good] % 2 == 0, 1.0, -1.0)[:, None]])
    coef = np.linalg.lstsq(a, b, rcond=None)[0]
    r = b - a @ coef
    keep = np.abs(r - np.median(r)) <= 3.0 * max(robust_sigma(r), 1.4826e-6)
    if keep.sum() >= a.shape[1] + 2:
        coef = np.linalg.lstsq(a[keep], b[keep], rcond=None)[0]
    u, v = ((px - centre) / scale).T
    g = np.stack([coef[1] + (2 * coef[3] * u + coef[4] * v if quadratic else 0.0 * u),
                  coef[2] + (coef[4] * u + 2 * coef[5] * v if quadratic else 0.0 * v)],
                 axis=1) / scale
    norm = np.linalg.norm(g, axis=1, keepdims=True)
    return g * np.minimum(1.0, MAX_LIGHT_GRADIENT / np.maximum(norm, 1e-12))


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
    import cv2

    from ..geometry.board import Checkerboard
    if options is None:
        options = CornerOptions(extend=extend, max_error=max_error)
    elif not isinstance(options, CornerOptions):
        raise ValueError(f"options must be a CornerOptions, got {options!r}")
    extend, max_error = options.extend, options.max_error
    board = Checkerboard() if board is None else board
    gray = _to_8bit(as_gray(image, "the image", None))
    h, w = gray.shape
    n_board = board.rows * board.cols
    bxy = board.board_coordinates()
    flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    if expected is not None:
        expected = np.asarray(expected, dtype=float)
        if expected.shape != (n_board, 2):
            raise ValueError(f"expected must hold the ({n_board}, 2) predicted pixels of the "
                             f"board's corners, got shape {expected.shape}")
        cv2.setRNGSeed(0)  # its random samples: the result depends on the image alone
        ok, found, _ = cv2.findChessboardCornersSBWithMeta(gray, (3, 3),
                                                           flags | cv2.CALIB_CB_LARGER)
        if not ok or found is None or len(found) < 4:
            # a close view of the board's edge can show fewer than 3 x 3 corners, or corners
            # OpenCV does not follow: find its X-junctions where the prediction expects them
            return _junction_corners(gray, board, expected, options)
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
        px, idx = _on_grid(det[i_det], idx, bxy, 0.1 * spacing)
        # A mirror image of the board is a homography too, so a mirrored expectation can match
        # every corner with every label wrong (a small view of a symmetric grid): only the
        # board's handedness, as the camera sees it, tells.
        if _orientation(px, idx, board) != _handedness(board):
            raise ValueError("the expected corner pixels are a mirror image of the board as "
                             "the camera sees it (its rows and columns swapped or one of "
                             "them reversed): numbering them would label every corner wrong")
        # The median offset taken out above makes any common error of the prediction look
        # small: a prediction off by more than half a square would number every corner one
        # square off. Placed on the board without it, the numbering must be clearly the best.
        if np.ptp(idx // board.cols) > 0 and np.ptp(idx % board.cols) > 0:
            idx = _place(px, idx // board.cols, idx % board.cols, board, expected, spacing,
                         _RATIO, 1.0, f"the {len(idx)} corners found")
        rule = "expected"
    else:
        grid, by_sb = _whole_board(gray, board, options.fallback)
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
        corners = _refine_and_extend(gray, px, idx, board, spacing, extend, rule,
                                     refine=options.refine)
        if not by_sb:
            return corners
        detected = np.full((n_board, 2), np.nan)
        detected[idx] = px
        return replace(corners, detected=detected)
    return _refine_and_extend(gray, px, idx, board, spacing, extend, rule,
                              refine=options.refine)


def _on_grid(px: np.ndarray, idx: np.ndarray, bxy: np.ndarray, tol: float
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
_RATIO = 3.0


def _junction_corners(gray: np.ndarray, board: Any, expected: np.ndarray,
                      options: CornerOptions) -> Corners:
    """The corners of a board that ``findChessboardCornersSB`` does not find (a close view
    of its edge, fewer than 3 x 3 corners): X-junctions of the image (maxima of the negative
    Hessian determinant, refined with ``cornerSubPix``, two opposite quadrants dark and two
    light), put on a lattice by the homography of the ``expected`` pixels, fitted again
    to themselves and numbered on the board by :func:`_place`."""
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
    spacing = _spacing(expected[vis])
    if not (np.isfinite(spacing) and 2.0 <= spacing <= max(h, w)):
        # a prediction whose squares are larger than the image (a board predicted at the
        # camera) or degenerate: no junction lattice to look for (and no kernel that size)
        raise none
    g = gray.astype(np.float32)
    sm = cv2.GaussianBlur(g, (0, 0), max(1.0, 0.05 * spacing))
    ixx = cv2.Sobel(sm, cv2.CV_32F, 2, 0, ksize=3)
    iyy = cv2.Sobel(sm, cv2.CV_32F, 0, 2, ksize=3)
    ixy = cv2.Sobel(sm, cv2.CV_32F, 1, 1, ksize=3)
    sad = ixy * ixy - ixx * iyy  # > 0 at a saddle: an X-junction
    k = 2 * int(max(2, 0.15 * spacing)) + 1
    peak = (sad == cv2.dilate(sad, np.ones((k, k), np.uint8))) & (sad > 0.05 * sad.max())
    win = int(np.clip(round(0.2 * spacing), 2, 9))
    m = win + 2
    v, u = np.nonzero(peak[m:h - m, m:w - m])
    if u.size < 4:
        raise none
    order = np.argsort(-sad[v + m, u + m])[:400]
    cand = _refine(gray, np.stack([u[order] + m, v[order] + m], axis=1).astype(float), win)
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
    cand = np.array(keep)
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
    if len(cand) < 4 or np.ptp(lab[:, 0]) == 0 or np.ptp(lab[:, 1]) == 0:
        raise BoardNotFoundError(
            f"no checkerboard found in the image (findChessboardCornersSB found no 3 x 3 "
            f"grid of corners, and only {len(cand)} X-junctions in one row lie on a board "
            "lattice)")
    spacing = _spacing(cand)
    idx = _place(cand, lab[:, 0] - lab[:, 0].min(), lab[:, 1] - lab[:, 1].min(), board,
                 expected, spacing, _RATIO, options.max_error,
                 f"the {len(cand)} X-junctions found")
    return _refine_and_extend(gray, cand, idx, board, spacing, options.extend, "predicted",
                              x_check=True, refine=options.refine)


def _refine_and_extend(gray: np.ndarray, px: np.ndarray, idx: np.ndarray, board: Any,
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
            ref = _refine(gray, pred[inside], win)
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
    q = [_sample(gray, px + a * di + b * dj) for a, b in
         ((0.25, 0.25), (-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25))]
    gap = np.maximum(np.minimum(q[0], q[1]) - np.maximum(q[2], q[3]),
                     np.minimum(q[2], q[3]) - np.maximum(q[0], q[1]))
    return gap, 0.5 * (q[0] + q[1] - q[2] - q[3])


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
    refined at full size (:func:`_refine_and_extend`). The full-size accurate search runs only
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
            spacing = _spacing(px)
            win = int(np.clip(round(0.2 * spacing), 2, 9))
            m = win + 2
            fits = (px[:, 0] >= m) & (px[:, 0] <= w - 1 - m) & (px[:, 1] >= m) & \
                (px[:, 1] <= h - 1 - m)
            ref = px.copy()
            ref[fits] = _refine(gray, px[fits], win)
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
    if not ok or found is None or found.size != 2 * n:
        raise BoardNotFoundError(
            f"no fully visible {board.rows} x {board.cols} checkerboard found in the image "
            f"({tried} found none); for a partly visible board pass the expected corner "
            "pixels to find_corners")
    return found.reshape(board.rows, board.cols, 2).astype(float), by_sb


#: the halved image's shorter side must be at least this (px) for the halved search
_MIN_HALF_SIDE = 200


def sb_positions(image: np.ndarray, corners: Corners) -> Corners:
    """``corners`` with ``detected`` set: ``findChessboardCornersSB``'s own positions from
    its full-size accurate search (``CALIB_CB_EXHAUSTIVE | CALIB_CB_ACCURACY``), matched to
    the numbered corners (each within a quarter of the corner spacing); ``corners``
    unchanged when that search finds no whole board. Costly (4-5x the halved search): for
    :func:`prefer_detected`, which asks only when the refined corners fit poorly."""
    import cv2

    board = corners.board
    gray = _to_8bit(as_gray(image, "the image", None))
    cv2.setRNGSeed(0)
    ok, found = cv2.findChessboardCornersSB(
        gray, (board.cols, board.rows),
        flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not ok or found is None or len(corners) < 2:
        return corners
    det = found.reshape(-1, 2).astype(float)
    spacing = _spacing(np.asarray(corners.pixels, float))
    d = np.linalg.norm(det[:, None] - corners.pixels[None], axis=2)
    near = np.argmin(d, axis=1)
    close = d[np.arange(len(det)), near] < 0.25 * spacing
    detected = np.full((board.rows * board.cols, 2), np.nan)
    detected[corners.index[near[close]]] = det[close]
    return replace(corners, detected=detected)


def detect_board(image: np.ndarray, board: Any,
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


# ------------------------------------------------------------------------------------------
# Partly visible plain checkerboards


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


def _sample(gray: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear grey values of the float32 image at pixels ``pts`` (..., 2); NaN outside."""
    import cv2
    xy = np.ascontiguousarray(pts, np.float32).reshape(-1, 2)
    v = cv2.remap(gray, xy[:, :1].copy(), xy[:, 1:].copy(), cv2.INTER_LINEAR,
                  borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    return v.reshape(pts.shape[:-1])


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
    vals = _sample(gray, (1 - s) * (1 - t) * p00 + s * (1 - t) * p10 + (1 - s) * t * p01
                   + s * t * p11)
    mean = vals.mean(axis=2)
    spread = vals.max(axis=2) - vals.min(axis=2)
    di = np.concatenate([grid[1:] - grid[:-1], grid[-1:] - grid[-2:-1]], axis=0)
    dj = np.concatenate([grid[:, 1:] - grid[:, :-1], grid[:, -1:] - grid[:, -2:-1]], axis=1)
    q = np.stack([_sample(gray, grid + a * di + b * dj) for a, b in
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
            spacing = _spacing(g.reshape(-1, 2))
            win = int(np.clip(round(0.2 * spacing), 2, 9))
            if not ((pred >= win + 2).all() and (pred[:, 0] <= w - 3 - win).all()
                    and (pred[:, 1] <= h - 3 - win).all()):
                blocked.add(side)
                continue
            ref = _refine(gray8, pred, win)
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
    gray8 = _to_8bit(as_gray(image, "the image", None))
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
        return CornerGrid(grown, _spacing(grown.reshape(-1, 2)), (w, h))
    extra = f"; rejected: {', '.join(dict.fromkeys(seen))}" if seen else ""
    raise BoardNotFoundError("no checkerboard found in the image (findChessboardCornersSB "
                             f"found no regular grid of at least 6 corners{extra})")


def grid_placements(i: np.ndarray, j: np.ndarray, board: Any, px: np.ndarray
                ) -> list[tuple[np.ndarray, str]]:
    """Every way corners at grid positions (``i``, ``j``) (integers, one row or column apart
    per square) can lie on the board with the board's handedness: (board indices of the
    corners in their order, a description)."""
    sign = _handedness(board)
    out = []
    for swap in (False, True):
        for si in (1, -1):
            for sj in (1, -1):
                r0, c0 = (sj * j, si * i) if swap else (si * i, sj * j)
                if _orientation_rc(px, np.stack([r0, c0], axis=1)) != sign:
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


def _place(px: np.ndarray, i: np.ndarray, j: np.ndarray, board: Any, expected: np.ndarray,
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
    gray = _to_8bit(as_gray(image, "the image", None))
    exp = np.asarray(expected, dtype=float)
    n_board = board.rows * board.cols
    if exp.shape != (n_board, 2):
        raise ValueError(f"expected must hold the ({n_board}, 2) predicted pixels of the "
                         f"board's corners, got shape {exp.shape}")
    m, n = grid.shape
    px = grid.pixels.reshape(-1, 2)
    spacing = grid.spacing
    i, j = (a.ravel() for a in np.meshgrid(np.arange(m), np.arange(n), indexing="ij"))
    idx = _place(px, i, j, board, exp, spacing, ratio, options.max_error,
                 f"the {m} x {n} corners found")
    return _refine_and_extend(gray, px, idx, board, spacing, options.extend, "predicted",
                              x_check=True, refine=options.refine)


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
    from ..geometry.board import board_pose_from_corners

    bxy = board.board_coordinates()
    pts = np.c_[bxy, np.zeros(len(bxy))]
    ref = pts @ base_from_board[:3, :3].T + base_from_board[:3, 3]
    k = np.asarray(camera_matrix, float)
    d = np.asarray(dist_coeffs, float)
    scored = []
    for idx, desc in grid_placements(i, j, board, px):
        cfb = board_pose_from_corners(pts[idx], px, k, d)
        if cfb is None:
            continue
        est = base_from_camera @ cfb
        moved = pts @ est[:3, :3].T + est[:3, 3]
        scored.append((float(np.sqrt(np.mean(np.sum((moved - ref) ** 2, axis=1)))), desc,
                       idx))
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


def number_grid_by_pose(image: np.ndarray, grid: CornerGrid, board: Any,
                        camera_matrix: np.ndarray, dist_coeffs: np.ndarray,
                        base_from_camera: np.ndarray, base_from_board: np.ndarray,
                        ratio: float = 3.0, options: CornerOptions | None = None) -> Corners:
    """:func:`number_grid` with the numbering from the robot chain (:func:`place_by_pose`)
    instead of predicted pixels; then refined and extended the same way
    (``Corners.rule == "pose"``)."""
    options = CornerOptions() if options is None else options
    gray = _to_8bit(as_gray(image, "the image", None))
    m, n = grid.shape
    px = grid.pixels.reshape(-1, 2)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(m), np.arange(n), indexing="ij"))
    idx = place_by_pose(px, i, j, board, camera_matrix, dist_coeffs, base_from_camera,
                        base_from_board, ratio, f"the {m} x {n} corners found")
    return _refine_and_extend(gray, px, idx, board, grid.spacing, options.extend, "pose",
                              x_check=True, refine=options.refine)


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
    gray = _to_8bit(as_gray(image, "the image", None))
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
        ref = _refine(gray, px, win)
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
    return _spacing(px) if len(px) > 1 else 20.0


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
