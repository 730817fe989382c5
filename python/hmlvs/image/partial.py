"""Views of a partly visible plain checkerboard, numbered from the robot's pose.

A plain checkerboard cut by the image border shows the same pattern wherever it is cut: its
corners (:func:`hmlvs.image.grid.detect_grid`) could be any rows and columns of the board,
and turned by half a turn. The views of the whole board give a first calibration
(:func:`calibrate_joint`); under each placement of a partial view's grid its corners give the
board's pose, and through the view's robot pose and that calibration's hand-eye transform the
board's pose in the base, where the other views put it: the placement that agrees, clearly
better than every other, is taken (:func:`hmlvs.image.grid.number_grid_by_pose`). A view
without a grid (a few X-junctions at the board's edge) is numbered by the pixels the first
calibration predicts. A view that cannot be numbered so is rejected with the reason, never
guessed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..data.views import ViewData
from .accounts import ImageReport
from .corner_base import Corners, away_from_light
from .corners import BoardNotFoundError, find_corners
from .grid import CornerGrid, detect_grid, number_grid_by_pose
from .session import ESTIMATED_OFF
from .stripe import StripeStatus


@dataclass(frozen=True)
class PartialView:
    """A view whose board was found only as an unnumbered grid of corners.

    id : the view's id; image : its laser-off (grey) image; grid : the corners found, or
    None with ``reason`` saying why not; base_from_hand : the robot's pose (None without
    one); stripe : (m, 2) stripe pixels
    """

    id: str
    image: np.ndarray
    grid: CornerGrid | None
    base_from_hand: np.ndarray | None
    stripe: np.ndarray
    reason: str = ""


def predicted_board_pixels(sensor: Any, base_from_hand: np.ndarray, board: Any) -> np.ndarray:
    """(rows*cols, 2) pixels where a calibrated general sensor (:class:`OpenCvSensor` with
    ``hand_from_camera`` and ``base_from_board``) sees every board corner at a robot pose;
    NaN for corners behind the camera."""
    import cv2

    from ..geometry.board import BoardSpec
    spec = BoardSpec.of(board)
    pts = spec.points()
    cam_from_board = (np.linalg.inv(sensor.hand_from_camera) @ np.linalg.inv(base_from_hand)
                      @ sensor.base_from_board)
    cam = pts @ cam_from_board[:3, :3].T + cam_from_board[:3, 3]
    rvec, _ = cv2.Rodrigues(cam_from_board[:3, :3])
    px, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), rvec, cam_from_board[:3, 3].copy(),
                              sensor.camera_matrix, sensor.dist_coeffs)
    px = px.reshape(-1, 2).astype(float)
    px[cam[:, 2] <= 1e-6] = np.nan
    return px


def number_partial_views(full: Sequence[ViewData], partial: Sequence[PartialView], board: Any,
                         image_size: tuple[int, int], detector_board: Any,
                         base_from_board: np.ndarray | None = None, min_corners: int = 6
                         ) -> tuple[list[Corners | None], list[str]]:
    """Number each partial view's corners from a first calibration on the ``full`` views:
    its grid placed where the robot chain puts the board (:func:`number_grid_by_pose`), or
    for a view without one (``grid`` None) the image's
    X-junctions near the predicted board (:func:`find_corners` with ``expected``).

    Returns per partial view its :class:`Corners` (``rule == "predicted"``) or None, and the
    reason ("" when numbered). ``detector_board`` is the :class:`hmlvs.Checkerboard` the
    corners are numbered on; ``base_from_board`` a measured board pose, held fixed in the
    first calibration as in the final one."""
    from ..calibration.joint import calibrate_joint

    out: list[Corners | None] = [None] * len(partial)
    reasons = [""] * len(partial)
    need = ("a partly visible board is numbered from its robot pose and a first calibration "
            "from at least 3 views of the whole board")
    if not partial:
        return out, reasons

    def unnumbered(why: str) -> list[str]:
        # a view in which no grid was found says so first: it was not only left unnumbered
        return [f"{p.reason}; {why}" if p.grid is None and p.reason else why for p in partial]

    if len(full) < 3 or any(v.base_from_hand is None for v in full):
        return out, unnumbered(f"{need}; the session has {len(full)}" if len(full) < 3
                               else f"{need}, all with robot poses")
    try:
        first = calibrate_joint(list(full), board, image_size, base_from_board=base_from_board)
    except ValueError as e:
        return out, unnumbered(f"{need}; that calibration failed: {e}")
    for k, p in enumerate(partial):
        if p.base_from_hand is None:
            reasons[k] = "a partly visible board needs the view's robot pose to be numbered"
            continue
        expected = predicted_board_pixels(first.sensor, p.base_from_hand, board)
        sensor = first.sensor
        try:
            if p.grid is not None:
                # numbered by where the chain puts the board (AX = XB), not by pixels
                # predicted from a first calibration
                corners = number_grid_by_pose(
                    p.image, p.grid, detector_board, sensor.camera_matrix, sensor.dist_coeffs,
                    p.base_from_hand @ sensor.hand_from_camera, sensor.base_from_board)
            else:
                # no grid OpenCV could follow (a close view of the board's edge): the
                # X-junctions where the first calibration predicts the board
                corners = find_corners(p.image, detector_board, expected=expected)
        except ValueError as e:
            # without a grid, a view in which no junction lattice was found either says
            # that no board was found; an ambiguous numbering says so
            reasons[k] = p.reason if p.grid is None and isinstance(e, BoardNotFoundError) \
                else str(e)
            continue
        if len(corners) < min_corners:
            reasons[k] = (f"partly visible board: only {len(corners)} corners numbered; a view "
                          f"needs at least {min_corners}")
            continue
        out[k] = corners
    return out, reasons


#: stripe statuses whose centre lies on the stripe's light (measured or checked)
_ON_THE_STRIPE = (StripeStatus.FOUND, StripeStatus.SATURATED, StripeStatus.CLIPPED,
                  StripeStatus.DOUBLE_PEAK, StripeStatus.ALBEDO_EDGE)


def clear_of_stripe(corners: Corners, pair: Any) -> Corners:
    """The corners of a laser-on frame alone (``pair``: its ``hmlvs.image.session.Pair``)
    without those its stripe's light can have pulled (:func:`away_from_light`: within the
    stripe's width plus 1.5 refinement half-windows of the stripe's centre line, which is
    interpolated across the scan lines without a centre, where a corner under the stripe
    leaves two peaks or none). A pair with a laser-off frame keeps them all: its corners
    are found on that frame."""
    if pair.off_name != ESTIMATED_OFF:
        return corners
    s = pair.stripe
    pos, centre = np.asarray(s.position, float), np.asarray(s.centre, float)
    # the centres of the stripe's own light: a MULTIPLE scan line's strongest peak may lie
    # elsewhere (a square's corner)
    ok = np.isin(np.asarray(s.status), _ON_THE_STRIPE) & np.isfinite(centre)
    if ok.sum() < 2:
        return corners
    ok[ok] = _on_the_line(centre[ok], np.asarray(s.width, float)[ok])
    span = (pos >= pos[ok].min()) & (pos <= pos[ok].max())
    line = np.stack([pos[span], np.interp(pos[span], pos[ok], centre[ok])], axis=1)
    return away_from_light(corners, line if s.direction == "columns" else line[:, ::-1],
                           np.where(ok, np.asarray(s.width, float), np.nan)[span])


def _on_the_line(centre: np.ndarray, width: np.ndarray, window: int = 41) -> np.ndarray:
    """Which of a stripe's centres (in scan-line order) lie on its line: within twice the
    stripe's median FWHM plus 2 px of the running median of ``window`` of them. A clipped
    or double peak far from the stripe (the image's border, a shelf beside the board) is not
    the stripe, and a line drawn through it would sweep corners away (a green stripe down a
    hand-held board: 6 corners a square or more from the stripe were left out)."""
    from scipy.ndimage import median_filter

    if len(centre) < 5:
        return np.ones(len(centre), bool)
    fwhm = float(np.nanmedian(width)) if np.isfinite(width).any() else 0.0
    med = median_filter(centre, size=min(window, len(centre) | 1), mode="nearest")
    return np.abs(centre - med) <= 2.0 * fwhm + 2.0


def corner_image(pair: Any) -> np.ndarray:
    """The frame a view's board corners are found on (``pair``: its
    ``hmlvs.image.session.Pair``): a grey laser-on frame alone is searched itself, as a
    colour one is (in grey), the corners its stripe can have pulled then left out
    (:func:`clear_of_stripe`). Its background estimated for the stripe (each column opened)
    wears the squares' tips down and moves corners far from the stripe too: on renders
    0.26-0.31 px RMS, up to 1.2 px, against 0.016 px on the frame itself. Otherwise the
    pair's ``board_image``."""
    if pair.off_name == ESTIMATED_OFF and pair.board is None and pair.on is not None:
        return pair.on
    return pair.board_image


def partial_view(pid: str, pair: Any, board: Any, whole_error: Exception) -> PartialView:
    """The :class:`PartialView` of an image pair (``hmlvs.image.session.Pair``) in which
    no whole board was found (``whole_error`` says so): its corner grid, or the reason why
    there is none."""
    try:
        grid, reason = detect_grid(corner_image(pair), board), ""
    except ValueError:
        grid = None
        reason = (str(whole_error).split("; for a partly visible")[0] + "; nor a partly "
                  "visible one (no regular grid of at least 6 corners)")
    return PartialView(pid, corner_image(pair), grid, pair.pose, pair.stripe.pixels, reason)


def add_partial_views(partial: list[tuple[int, PartialView, Any]], views: list[ViewData],
                      reports: list[Any], board: Any, size: Any, detector_board: Any,
                      board_pose: np.ndarray | None, min_corners: int) -> None:
    """Number the partial views (:func:`number_partial_views`) of
    :func:`hmlvs.image.views.views_from_images` and put them in session order among
    ``views``; fill their reports (``reports[slot]`` is None for each (slot, view, pair))."""
    full = list(views)
    numbered, reasons = number_partial_views(full, [p for _, p, _ in partial], board, size,
                                             detector_board, board_pose, min_corners)
    result = iter(zip(numbered, reasons))
    # the whole-board views' places in the session: the reports accepted so far, in order
    keyed = list(zip([k for k, r in enumerate(reports) if r is not None and r.ok], full))
    for slot, p, pair in partial:
        corners, why = next(result)
        if corners is not None:
            corners = clear_of_stripe(corners, pair)
            if len(corners) < min_corners:
                corners, why = None, (f"partly visible board: only {len(corners)} corners "
                                      f"numbered clear of the stripe; a view needs at least "
                                      f"{min_corners}")
        if corners is None and p.grid is None and p.base_from_hand is not None:
            # no board in the image at all: a laser-only view (the stripe on the board's
            # plane, e.g. taken with the lights off), used through the robot poses
            keyed.append((slot, ViewData(p.id, np.zeros((0, 2)), np.zeros(0, int), p.stripe,
                                         p.base_from_hand, stripe=pair.stripe,
                                         joints=pair.joints)))
            reports[slot] = ImageReport(p.id, slot, pair.on_name, pair.off_name, True, "",
                                        pair.stripe.counts(), 0, int(pair.stripe.found.sum()))
            continue
        if corners is None:
            reports[slot] = ImageReport(p.id, slot, pair.on_name, pair.off_name, False, why)
            continue
        keyed.append((slot, ViewData(p.id, np.asarray(corners.pixels, float),
                                     np.asarray(corners.index, int), p.stripe,
                                     p.base_from_hand, stripe=pair.stripe, joints=pair.joints)))
        reports[slot] = ImageReport(p.id, slot, pair.on_name, pair.off_name, True, "",
                                    pair.stripe.counts(), len(corners.index),
                                    int(pair.stripe.found.sum()))
    views[:] = [v for _, v in sorted(keyed, key=lambda kv: kv[0])]
