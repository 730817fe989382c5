"""Laser on/off images + robot poses -> the views of the general model's joint calibration.

For every pair, in the session's one pass (:mod:`hmlvs.image.reading`, as the paper model's
:func:`hmlvs.image.paper_session.paper_views`): the stripe (the same checks, difference image
and extraction, :func:`hmlvs.image.session.stripe_from_pair`) and the whole board, found and
numbered without any prior model (:func:`hmlvs.image.corners.detect_board`). Which stripe
pixels lie on the board is decided by the calibration itself, once the board's pose in each
view is known.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..data.manifest import checkerboard_of
from ..data.views import ViewData
from ..geometry.board import BoardSpec, CharucoSpec
from .accounts import ImageReport
from .charuco import detect_charuco
from .corners import BoardNotFoundError, detect_board, prefer_detected
from .frames import checked_blur_var
from .partial import (
    PartialView,
    add_partial_views,
    clear_of_stripe,
    corner_image,
    partial_view,
)
from .reading import PairRead, PairReader, read_pairs, same_size, session_blur
from .session import (
    ESTIMATED_OFF,
    Pair,
    PairRejected,
    manifest_direction,
    manifest_robot,
    opencv_failure,
    read_session_manifest,
)
from .stripe import StripeStatus
from .whole_check import renumbered_by_pose

MIN_CORNERS = 6  # a view needs this many numbered corners (calibrate_joint's minimum)


def board_of(doc: dict[str, Any], board: Any, source: Any) -> tuple[BoardSpec, np.ndarray | None]:
    """The board (rows, cols, square; or a ChArUco board, ``type: charuco``) of a manifest or
    the caller, and its measured pose in the base when the manifest gives one (``origin``),
    else None."""
    from ..geometry.board import Checkerboard

    spec = board if board is not None else doc.get("board")
    if spec is None:
        raise ValueError(f"{source}: the manifest has no 'board' (rows, cols, square) and no "
                         "board was given")
    pose = None
    if isinstance(spec, CharucoSpec):
        return spec, None
    if isinstance(spec, (BoardSpec, Checkerboard)):
        return BoardSpec.of(spec), (spec.base_from_board() if isinstance(spec, Checkerboard)
                                    else None)
    if isinstance(spec, dict) and spec.get("type", "checkerboard") != "checkerboard":
        if spec["type"] != "charuco":
            raise ValueError(f"{source}: unknown board type {spec['type']!r}; choose "
                             "checkerboard or charuco")
        try:
            return CharucoSpec.from_dict(spec), None
        except (TypeError, ValueError) as e:
            raise ValueError(f"{source}: {e}") from None
    if isinstance(spec, dict):
        spec = {k: v for k, v in spec.items() if k != "type"}
    checked = checkerboard_of(spec, source)
    if "origin" in spec:
        pose = checked.base_from_board()
    return BoardSpec.of(spec), pose


def views_from_images(source: Any, *, robot: Any = None, board: Any = None,
                      joint_unit: str | None = None, channel: int | None = None,
                      normalize: bool = True, min_stripe: int = 20,
                      threads: int | None = None, **stripe_options: Any
                      ) -> tuple[list[ViewData], BoardSpec, tuple[int, int], np.ndarray | None,
                                 list[ImageReport]]:
    """An image session (a manifest, see docs/file-formats.md) -> joint-calibration views.

    Returns (views, board, image size (w, h), the board's measured base_from_board or None,
    one :class:`ImageReport` per pair). A fully visible checkerboard is numbered by the
    top-left rule (made consistent across views by
    :func:`hmlvs.calibration.joint.calibrate_joint`); a partly visible one from its robot pose
    and a first calibration on the whole-board views (:mod:`hmlvs.image.partial`), or the
    view is rejected with the reason; a ChArUco board may be partly visible, its corners
    numbered by the marker ids. A pair
    without a stripe, without the board or with fewer than 6 numbered corners is reported
    and skipped; the rest of the session goes through. Unless ``blur_var`` is given, the
    stripes' correction at the board's albedo steps uses the camera blur fitted to the
    session (:func:`hmlvs.image.session.session_blur_var`). The views are read on
    ``threads`` threads (default: one per core); the result does not depend on the number.
    """
    from ..geometry.board import Checkerboard

    records, doc, folder = read_session_manifest(source)
    board_spec, board_pose = board_of(doc, board, source)
    given = doc.get("image_size")  # the manifest's: every pair must have it
    options = manifest_direction(doc, dict(stripe_options))
    fit_blur = options.get("blur_var") is None
    options["blur_var"] = checked_blur_var(options.get("blur_var"))
    numbering = _ModelFree(board_spec, board_spec if board_spec.unambiguous else Checkerboard(
        rows=board_spec.rows, cols=board_spec.cols, square=board_spec.square))
    reader = PairReader(
        folder, doc.get("joint_unit", "rad") if joint_unit is None else joint_unit,
        _session_robot(doc, records, robot, source),
        (int(given[0]), int(given[1])) if isinstance(given, list) and len(given) == 2
        else None, channel, normalize, min_stripe, options, fit_blur, numbering.number,
        keep_board=_top_left)
    # the views one per core, then in the session's order
    reads = read_pairs(reader, records, threads)
    size = same_size(reads)
    if size is None:
        where = "" if isinstance(source, (list, tuple)) else f"{source}: "
        if not reads:
            raise ValueError(f"{where}the session lists no image pairs (its poses list is "
                             "empty)")
        raise ValueError(f"{where}no image pair could be read: " +
                         "; ".join(f"{r.id}: {r.why}" for r in reads))
    fitted = session_blur(reads)
    var = options["blur_var"] if fitted is None else fitted
    got = _Gathered(size=size)
    for read in reads:
        got.add(read)
    got.prefer_detected()
    if not board_spec.unambiguous:  # a detection whole squares off, by the robot chain
        got.views[:], moved = renumbered_by_pose(got.views, numbering.detector_board, got.size,
                                                 board_pose)
        got.reports[:] = [replace(r, note=moved[r.id]) if r is not None and r.id in moved else r
                          for r in got.reports]
    if got.partial:
        add_partial_views(got.partial, got.views, got.reports, board_spec, got.size,
                          numbering.detector_board, board_pose, MIN_CORNERS)
    views, reports = _stripes_on_one_line(got.views, got.reports, var)
    return views, board_spec, got.size, board_pose, reports


def _session_robot(doc: dict[str, Any], records: list[Any], robot: Any, source: Any) -> Any:
    """The arm of an image session, as the paper model's pass and the scans take it
    (:func:`~hmlvs.image.session.manifest_robot`: ``robot``, else the manifest's built-in
    name or DH mapping), else SCORBOT ER-VII; a session whose entries all give their pose
    needs no arm, and its manifest's ``robot:`` is not read."""
    from ..geometry.robot import Robot

    if robot is None and not any(isinstance(r, dict) and "joints" in r for r in records):
        return Robot.scorbot_er7()
    return manifest_robot(doc, robot, source) or Robot.scorbot_er7()


@dataclass(frozen=True)
class _ModelFree:
    """The general model's numbering of a pair's board (for :class:`PairReader`), without
    any prior model: a whole board's corners (:func:`detect_corners`), or the
    :class:`PartialView` of a partly visible plain checkerboard, numbered later from a first
    calibration."""

    board_spec: BoardSpec
    detector_board: Any  # the board the detector looks for

    def number(self, pid: str, pair: Pair) -> Any:
        import cv2

        try:
            found = detect_corners(corner_image(pair), self.detector_board)
        except BoardNotFoundError as e:
            if self.board_spec.unambiguous:
                raise PairRejected(str(e)) from None
            return partial_view(pid, pair, self.detector_board, e)
        except ValueError as e:
            raise PairRejected(str(e)) from None
        except cv2.error as e:
            raise opencv_failure(e, "board", hint="") from None
        found = clear_of_stripe(found, pair)
        if len(found) < MIN_CORNERS:
            raise PairRejected(f"only {len(found)} board corners found and numbered; a "
                               f"view needs at least {MIN_CORNERS}")
        return found


def _top_left(found: Any) -> bool:
    """Whether a whole board's image is kept: for :func:`prefer_detected`, which may search
    a board numbered by the top-left rule again."""
    return found.rule.startswith("top-left")


@dataclass
class _Gathered:
    """The views read, in the session's order, with a report for each."""

    size: tuple[int, int]
    views: list[ViewData] = field(default_factory=list)
    reports: list[Any] = field(default_factory=list)  # None: a partial view's, for now
    partial: list[tuple[int, PartialView, Any]] = field(default_factory=list)
    whole: dict[str, Any] = field(default_factory=dict)  # the whole boards' Corners
    board_images: dict[str, np.ndarray] = field(default_factory=dict)  # and their images
    alone: set[str] = field(default_factory=set)  # the views of laser-on frames alone

    def add(self, read: PairRead) -> None:
        """One pair as the session's pass read it (its stripe corrected for the blur)."""
        if not read.kept:
            self.reports.append(ImageReport(read.id, read.index, read.names[0],
                                            read.names[1], False, read.why))
            return
        pair, found = read.pair, read.found
        if isinstance(found, PartialView):
            self.partial.append((len(self.reports), replace(found, stripe=pair.stripe.pixels),
                                 pair))
            self.reports.append(None)
            return
        self.whole[read.id] = found
        if pair.off_name == ESTIMATED_OFF:
            self.alone.add(read.id)
        if read.image is not None:
            self.board_images[read.id] = read.image  # for prefer_detected, if it asks
        self.views.append(ViewData(read.id, np.asarray(found.pixels, float),
                                   np.asarray(found.index, int), pair.stripe.pixels,
                                   pair.pose, stripe=pair.stripe, joints=pair.joints))
        self.reports.append(ImageReport(read.id, read.index, pair.on_name, pair.off_name, True,
                                        "", pair.stripe.counts(), len(found.index),
                                        int(pair.stripe.found.sum())))

    def prefer_detected(self) -> None:
        """The whole boards' corners as the detector gave them, when
        :func:`~hmlvs.image.corners.prefer_detected` says they are better."""
        ids = list(self.whole)
        prefer, _, _, with_detected = prefer_detected(
            [self.whole[k] for k in ids], self.size,
            {n: self.board_images.get(k) for n, k in enumerate(ids)})
        self.board_images.clear()
        if not prefer:
            return
        # the detector's own positions; on a laser-on frame alone only of the corners the
        # view kept (clear_of_stripe left out those its stripe can have pulled)
        raw = {}
        for k, c in zip(ids, with_detected):
            d = c.as_detected()
            keep = np.isin(d.index, self.whole[k].index) if k in self.alone else \
                np.ones(len(d), bool)
            raw[k] = replace(d, pixels=d.pixels[keep], index=d.index[keep],
                             anchor=d.anchor[keep])
        self.views = [replace(v, corner_pixels=np.asarray(raw[v.id].pixels, float),
                              corner_index=np.asarray(raw[v.id].index, int))
                      if v.id in raw else v for v in self.views]
        self.reports = [replace(r, corners=len(raw[r.id])) if r is not None and r.id in raw
                        else r for r in self.reports]


def _stripes_on_one_line(views: list[ViewData], reports: list[ImageReport], var: float
                         ) -> tuple[list[ViewData], list[ImageReport]]:
    """The views with the light off their stripe's line left out
    (:func:`stripe_on_one_line`), and the reports counting it, with the blur variance."""
    counts: dict[str, dict[str, int]] = {}
    for k, v in enumerate(views):
        on_line = stripe_on_one_line(v.laser_pixels)
        if not on_line.all():
            stripe = v.stripe
            if stripe is not None:  # its found centres are the view's stripe pixels
                status = np.array(stripe.status, copy=True)
                status[np.nonzero(stripe.found)[0][~on_line]] = StripeStatus.OFF_LINE
                stripe = replace(stripe, status=status)
                counts[v.id] = stripe.counts()
            views[k] = replace(v, laser_pixels=np.asarray(v.laser_pixels)[on_line],
                               stripe=stripe)
    reports = [replace(r, blur_var=var, stripe=counts.get(r.id, r.stripe)) if r.ok else r
               for r in reports]
    return views, reports


def detect_corners(image: np.ndarray, board: Any) -> Any:
    """The numbered corners of one laser-off image: :func:`detect_charuco` for a ChArUco
    board (``board.unambiguous``), else :func:`detect_board` (a whole checkerboard, numbered
    by the top-left rule)."""
    if getattr(board, "unambiguous", False):
        return detect_charuco(image, board)
    return detect_board(image, board)


#: stripe pixels farther than this from the smooth curve through a calibration view's stripe
#: are left out (px); at least 5 robust sigmas of the fit
LINE_TOLERANCE = 3.0


def stripe_on_one_line(pixels: np.ndarray, tolerance: float = LINE_TOLERANCE
                       ) -> np.ndarray:
    """Which stripe pixels of a calibration view lie on its one stripe: (m,) bool.

    In a calibration view the laser meets one plane (the board and the sheet it is printed
    on), so its stripe is the image of a straight line: one smooth curve across the image (a
    cubic in the scan direction follows a lens' distortion over the image). Light elsewhere
    that passed the stripe's checks (a reddish edge of the table, a reflection, a square's
    corner on a laser-on frame alone) lies off it. The curve is grown from each of the three
    longest runs of neighbouring centres (a run: steps of at most 2 px across and 8 scan
    lines along), keeping what lies within 8 px of its extension, refitted; the run that
    gathers most pixels wins, and the pixels within ``tolerance`` (or 5 robust sigmas) of its
    final cubic are kept."""
    px = np.asarray(pixels, float).reshape(-1, 2)
    keep = np.ones(len(px), bool)
    if len(px) < 10:
        return keep
    along = 0 if np.ptp(px[:, 0]) >= np.ptp(px[:, 1]) else 1
    x, y = px[:, along], px[:, 1 - along]
    order = np.argsort(x, kind="stable")
    xs, ys = x[order], y[order]
    breaks = np.nonzero((np.diff(xs) > 8) | (np.abs(np.diff(ys)) > 2))[0] + 1
    runs = sorted(np.split(np.arange(len(xs)), breaks), key=len, reverse=True)[:3]
    span = max(float(np.ptp(xs)), 1.0)
    scale = (xs - xs.mean()) / span

    def grow(seed: np.ndarray) -> np.ndarray:
        inl = np.zeros(len(xs), bool)
        inl[seed] = True
        for _ in range(6):
            deg = min(3, 1 + int(np.ptp(xs[inl]) > 0.25 * span) + int(np.ptp(xs[inl]) > 0.5 * span))
            coef = np.polyfit(scale[inl], ys[inl], deg)
            new = np.abs(np.polyval(coef, scale) - ys) < 8.0
            if np.array_equal(new, inl) or new.sum() < len(seed):
                break
            inl = new
        return inl

    best = max((grow(r) for r in runs if len(r) >= 5), key=lambda m: int(m.sum()), default=None)
    if best is None or best.sum() < 10:
        return keep
    coef = np.polyfit(scale[best], ys[best], 3)
    res = np.polyval(coef, scale) - ys
    spread = 1.4826 * float(np.median(np.abs(res[best])))
    ok_sorted = np.abs(res) <= max(tolerance, 5.0 * spread)
    keep[order] = ok_sorted
    return keep
