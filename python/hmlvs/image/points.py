"""Calibration points: stripe pixels paired with reference points of one image."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from .corner_base import Corners
from .stripe import StripeResult

# ------------------------------------------------------------------------------------------
# Calibration points

Mode = Literal["corners", "homography"]
#: the division distortion model: (image centre (2,), k in 1/px^2)
Distortion = tuple[np.ndarray, float]

#: homography mode: largest RMS corner residual (px) of the one-homography board model for
#: which it maps the stripe points (else each square's own homography does)
GLOBAL_RESIDUAL = 0.15


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
                       step: int = 8, distortion: Distortion | None = None
                       ) -> CalibrationPoints:
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
        it lies in (all four must have been found), or, when the homography of all corners
        fits every corner within ``GLOBAL_RESIDUAL`` px, by that one (for points in squares
        with at least one found corner), then to the base frame; the reference
        points are points of the board plane where the stripe is, many per image. Radial
        distortion is taken out first: the division model of docs/model.md about the image
        centre, its coefficient fitted so that all corners obey one homography, or
        ``distortion``.
    distortion : homography mode: the division model (centre, k in 1/px^2) to take out
        instead of the one fitted to this image's corners, e.g. fitted to all views of a
        session (:func:`fit_division_distortion`). Then the one homography of the corners
        needs 6 of them (9 when it is fitted here, with the distortion).
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
    if not stripe.found.any():
        return _empty_points(mode, {"stripe": "no scan line with a found centre"})
    if mode == "corners":
        return _corner_points(stripe, corners, tolerance, int(window))
    return _homography_points(stripe, corners, board, int(step), distortion)


def _corner_points(stripe: StripeResult, corners: Corners, tolerance: float, window: int
                   ) -> CalibrationPoints:
    """:func:`calibration_points` in "corners" mode: the corners the stripe's centre line
    passes within ``tolerance`` px of, at the foot of the perpendicular onto it."""
    found = stripe.found
    pos = stripe.position[found].astype(float)
    cen = stripe.centre[found]
    sig = stripe.sigma[found]
    rejected: dict[str, str] = {}
    mode = "corners"
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


def _homography_points(stripe: StripeResult, corners: Corners, board: Any, step: int,
                       distortion: Distortion | None) -> CalibrationPoints:
    """:func:`calibration_points` in "homography" mode: every ``step``-th found stripe
    centre placed on the board by the corners' homography (one for the board, or each
    square's own)."""
    import cv2

    mode = "homography"
    found = stripe.found
    pos = stripe.position[found].astype(float)
    cen = stripe.centre[found]
    sig = stripe.sigma[found]
    if len(corners) < 4:
        return _empty_points(mode, {"board": "fewer than 4 corners"})
    sel = np.arange(0, pos.size, int(step))
    spx = np.stack([pos[sel], cen[sel]], axis=1) if stripe.direction == "columns" else \
        np.stack([cen[sel], pos[sel]], axis=1)
    ssig = sig[sel]
    # Radial distortion bends the board's lines, which a homography cannot follow. Fit the
    # model's division distortion p_u = c + (p - c) / (1 + k |p - c|^2) about the image
    # centre so that the corners best fit one homography, and map undistorted pixels.
    if distortion is None:
        centre, k_px = fit_division_distortion([corners])
        min_global = 9
    else:
        centre, k_px = np.asarray(distortion[0], float).reshape(2), float(distortion[1])
        if not (np.isfinite(centre).all() and np.isfinite(k_px)):
            raise ValueError(f"distortion must be a finite (centre, k), got {distortion!r}")
        min_global = 6
    cpx = _undistort(corners.pixels, centre, k_px)
    spx_u = _undistort(spx, centre, k_px)
    lookup = {int(i): cpx[j] for j, i in enumerate(corners.index)}
    hmat, _ = cv2.findHomography(cpx, corners.board_xy, 0)
    if hmat is None:
        return _empty_points(mode, {"board": "no homography from the corners"})
    rough = cv2.perspectiveTransform(spx_u.reshape(-1, 1, 2), hmat).reshape(-1, 2)
    # Where one homography (after the distortion fit) explains every corner to within
    # GLOBAL_RESIDUAL, it maps the stripe points: it averages the corners' detection noise
    # over all of them, where a square's own homography has four (measured on independent
    # renders, tests/oracles/independent_check.py: the reference points' error 0.008-0.0096 ->
    # 0.004-0.005 mm, the held-out map error down by 10-30 %). Otherwise (a lens the
    # division model does not fit, a board that is not flat) each square's own.
    back = cv2.perspectiveTransform(corners.board_xy.reshape(-1, 1, 2).astype(float),
                                    np.linalg.inv(hmat)).reshape(-1, 2)
    use_global = len(corners) >= min_global and \
        float(np.sqrt(np.mean(np.sum((back - cpx) ** 2, axis=1)))) <= GLOBAL_RESIDUAL
    return _placed_points(stripe, board, spx, spx_u, rough, ssig, lookup, use_global)


def _placed_points(stripe: StripeResult, board: Any, spx: np.ndarray, spx_u: np.ndarray,
                   rough: np.ndarray, ssig: np.ndarray, lookup: dict[int, np.ndarray],
                   use_global: bool) -> CalibrationPoints:
    """The stripe pixels ``spx`` (undistorted ``spx_u``, on the board by the one homography
    at ``rough``) placed in their squares: by the one homography (``use_global``) or by
    each square's own from its four corners (``lookup``: corner id -> undistorted pixel)."""
    import cv2

    sq = board.square
    mode = "homography"
    rejected: dict[str, str] = {}
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
        if use_global:
            # the board's one homography holds inside the inner corners' area, whether or
            # not all four corners of the square were found (one is enough: no farther
            # from the detected corners than a square)
            if 0 <= i < board.rows - 1 and 0 <= j < board.cols - 1 and any(
                    (i + di) * board.cols + (j + dj) in lookup for di in (0, 1) for dj in (0, 1)):
                placed = rxy
        for _ in range(0 if use_global else 2):  # the rough homography may pick a neighbour
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
        rejected["squares"] = f"{n_missing} stripe pixels in squares without " + (
            "a found corner" if use_global else "all four corners")
    if n_outside:
        rejected["outside"] = f"{n_outside} stripe pixels outside the inner corners' area"
    if not out_px:
        return _empty_points(mode, rejected)
    xy = np.array(out_xy)
    return CalibrationPoints(np.array(out_px), _to_base(board, xy), xy, np.array(out_ids),
                             np.array(out_sig), np.zeros(len(out_px)), mode, rejected)


def view_corners(view: Any, board: Any, image_size: tuple[int, int] | None = None
                 ) -> Corners:
    """The numbered corners of a view (:class:`hmlvs.data.views.ViewData`: its
    ``corner_pixels`` and ``corner_index``) on ``board``, the board the view was numbered on
    (placed in the base for the paper model), as :func:`calibration_points` and
    :func:`fit_division_distortion` take them; ``image_size`` (w, h): the view's image's."""
    index = np.asarray(view.corner_index, int)
    return Corners(np.asarray(view.corner_pixels, float), index, np.ones(len(index), bool),
                   board, image_size=None if image_size is None else
                   (int(image_size[0]), int(image_size[1])))


def view_points(view: Any, board: Any, *, image_size: tuple[int, int] | None = None,
                mode: Mode = "corners", tolerance: float = 0.5, window: int = 4,
                step: int = 8, distortion: Distortion | None = None) -> CalibrationPoints:
    """The paper model's calibration points of one view, derived from its observations
    (:class:`hmlvs.data.views.ViewData`): its stripe, every scan line with its status
    (``view.stripe``), and its numbered corners (:func:`view_corners` on ``board``, the
    board placed in the base), by :func:`calibration_points` in ``mode``. ValueError for a
    view without its stripe (one not read from images)."""
    if not isinstance(view.stripe, StripeResult):
        raise ValueError(f"view {view.id}: calibration points need the view's stripe with "
                         "every scan line (ViewData.stripe), as the image pipeline gives it")
    return calibration_points(view.stripe, view_corners(view, board, image_size), board,
                              mode=mode, tolerance=tolerance, window=window, step=step,
                              distortion=distortion)


def _undistort(px: np.ndarray, centre: np.ndarray, k: float) -> np.ndarray:
    d = px - centre
    return centre + d / (1.0 + k * np.sum(d * d, axis=1, keepdims=True))


def fit_division_distortion(views: Sequence[Corners]) -> Distortion:
    """The division model (docs/model.md step 2, in pixels: k_px = k Su^2) about the image
    centre, (centre, k_px), that makes the numbered corners of each view fit that view's own
    homography best. One lens serves every view of a session: fitted to all of them, the
    coefficient holds for views with too few corners to fit it alone. Views with fewer than
    9 corners do not take part; with none left, k_px = 0."""
    import cv2
    from scipy.optimize import minimize_scalar
    views = list(views)
    if not views or not all(isinstance(c, Corners) for c in views):
        raise ValueError("views must be a non-empty sequence of the Corners of find_corners")
    sizes = {c.image_size for c in views if c.image_size is not None}
    if len(sizes) > 1:
        raise ValueError(f"the views come from images of different sizes: {sorted(sizes)}")
    if sizes:
        w, h = sizes.pop()
        centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    else:
        centre = np.vstack([c.pixels for c in views]).mean(axis=0)
    use = [c for c in views if len(c) >= 9]
    if not use:
        return centre, 0.0
    r2max = max(float(np.max(np.sum((c.pixels - centre) ** 2, axis=1))) for c in use)

    def cost(kn: float) -> float:
        total = 0.0
        for c in use:
            u = _undistort(c.pixels, centre, kn / r2max)
            hm, _ = cv2.findHomography(c.board_xy, u, 0)
            if hm is None:
                return np.inf
            total += float(np.sum((cv2.perspectiveTransform(
                c.board_xy.reshape(-1, 1, 2), hm).reshape(-1, 2) - u) ** 2))
        return total

    # |k r^2| up to 10 % at the farthest corner
    res = minimize_scalar(cost, bounds=(-0.1, 0.1), method="bounded",
                          options={"xatol": 1e-7})
    return centre, float(res.x) / r2max


def _empty_points(mode: str, rejected: dict[str, str]) -> CalibrationPoints:
    return CalibrationPoints(np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 2)),
                             np.array([], dtype=str), np.zeros(0), np.zeros(0), mode, rejected)


