"""A session of laser on/off images -> the paper model's calibration data set
(:func:`dataset_from_images`): the session's views (:func:`paper_views`: one pass over the
pairs, :mod:`hmlvs.image.reading`, every board numbered from the corners the approximate
parameters predict), then the calibration points of each view derived from its observations
(:func:`points_of_views`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..data.views import ViewData
from .accounts import ImageReport
from .corner_base import Corners
from .corners import BoardNotFoundError, find_corners
from .frames import checked_blur_var, smooth_along_of
from .points import Mode, fit_division_distortion, view_corners, view_points
from .reading import (
    PairRead,
    PairReader,
    read_pairs,
    same_size,
    session_blur,
    session_offset,
)
from .session import (
    BOARD_SMOOTH_ALONG,
    Pair,
    PairRejected,
    core_options,
    manifest_direction,
    manifest_robot,
    opencv_failure,
    read_session_manifest,
    require_poses,
)
from .stripe import StripeResult, extract_stripe


def dataset_from_images(source: Any, *, robot: Any = None, board: Any = None,
                        params: Any = None, mode: Mode = "corners", normalize: bool = True,
                        channel: int | None = None, tolerance: float = 0.5, step: int = 8,
                        min_stripe: int = 20, joint_unit: str | None = None,
                        base_from_board: np.ndarray | None = None, threads: int | None = None,
                        **stripe_options: Any) -> tuple[Any, list[ImageReport]]:
    """Laser on/off image pairs + joint readings -> a calibration :class:`~hmlvs.Dataset`:
    the session's views (:func:`paper_views`), then their calibration points
    (:func:`points_of_views`).

    For every pair: difference image (albedo-normalised unless ``normalize=False``), stripe
    centres (:func:`extract_stripe` with ``stripe_options``), corners of the laser-off image
    numbered with the corners predicted from ``params`` and the pose
    (:func:`find_corners`), then :func:`calibration_points` in ``mode`` (in "homography"
    mode with the lens distortion fitted to the corners of all views,
    :func:`~hmlvs.image.points.fit_division_distortion`, and recorded in the data set's
    ``meta``). A pair that fails is reported and skipped; the rest of the session goes
    through.

    Parameters
    ----------
    source : a folder (or its ``manifest.json``) written by
        :func:`hmlvs.simulate.render_session` or in that format, or a list of records
        ``{"id": "p000", "on": file or array, "off": file or array, "joints": [...]}``
    robot : the arm (default: SCORBOT ER-VII); poses are ``robot.poses(joints)``
    board : the board (default: the manifest's, else the paper's)
    params : approximate sensor parameters, to predict where the corners are (default: the
        nominal Table 2 values). They need to place the corners within about a quarter of
        a square (:func:`find_corners`); a view predicted farther off is reported, not
        numbered wrong.
    mode : "corners" or "homography", see :func:`calibration_points`
    tolerance, step : passed to :func:`calibration_points`
    min_stripe : fewest scan lines with a stripe for a usable pair
    joint_unit : "rad" or "deg" for records (a manifest says its unit)
    base_from_board : where the manifest's board lies in the base (4 x 4), when the manifest
        does not say (e.g. estimated by an opencv calibration of the same session)
    threads : pairs read at once (default: one per usable core); the result does not depend
        on the number
    stripe_options : options of :func:`stripe_from_pair`. Without ``blur_var`` the camera's
        blur variance for the correction at the squares' edges is fitted to the session
        (:func:`session_blur_var`); ``meta["blur_var"]`` records the value used.

    Returns
    -------
    (dataset, report) : the data set (ids ``"<pose id>:<point id>"``, ``pose_index`` = pair
        index, joints in rad) and one :class:`ImageReport` per pair.
    """
    views = paper_views(source, robot=robot, board=board, params=params,
                        normalize=normalize, channel=channel, min_stripe=min_stripe,
                        joint_unit=joint_unit, base_from_board=base_from_board,
                        threads=threads, **stripe_options)
    return points_of_views(views, mode=mode, tolerance=tolerance, step=step)


@dataclass
class PaperViews:
    """The views of an image session as the paper model reads them (:func:`paper_views`),
    from which its calibration points are derived (:func:`points_of_views`, in either mode).

    reports : one account per pair, in the session's order; a pair kept holds its view
        (:attr:`ImageReport.view`: numbered corners, the stripe with every scan line's
        status, the robot pose and joints), ``points`` 0 until they are derived
    board : the board, placed in the base; image_size : (w, h), None when no pair was read
    normalize : whether the stripes were extracted from the albedo-normalised difference
    pairs : the number of pairs in the session
    extraction : what the data set's ``meta`` records of the stripes' extraction
    albedo_offset : the session's albedo offset, None when no pair fitted one
    offset_taken : the indices of the pairs that took it
    """

    reports: list[ImageReport]
    board: Any
    image_size: tuple[int, int] | None
    normalize: bool
    pairs: int
    extraction: dict[str, Any]
    albedo_offset: float | None = None
    offset_taken: set[int] = field(default_factory=set)

    @property
    def views(self) -> list[ViewData]:
        """The views kept, in the session's order."""
        return [r.view for r in self.reports if r.view is not None]


def paper_views(source: Any, *, robot: Any = None, board: Any = None, params: Any = None,
                normalize: bool = True, channel: int | None = None, min_stripe: int = 20,
                joint_unit: str | None = None, base_from_board: np.ndarray | None = None,
                threads: int | None = None, **stripe_options: Any) -> PaperViews:
    """The views of an image session for the paper model (the arguments as
    :func:`dataset_from_images` takes them): one pass over the pairs
    (:mod:`hmlvs.image.reading`), each board numbered from the corners ``params`` predict
    (:func:`find_corners`; boards they cannot number are numbered again with the hand-eye
    on which the views agree), the stripes extracted with Steger's smoothing along the stripe
    :data:`BOARD_SMOOTH_ALONG` unless given, those that cannot fit their albedo offset given
    the session's, and all corrected for the camera blur fitted to the session unless
    ``blur_var`` is given."""
    inputs = _session_inputs(source, robot, board, joint_unit, base_from_board)
    options = _board_stripe_options(manifest_direction(
        {"stripe_direction": inputs.direction}, stripe_options))
    fit_blur = stripe_options.get("blur_var") is None
    approx = inputs.approx if params is None else params
    reader = PairReader(inputs.folder, inputs.unit, inputs.robot, inputs.size, channel,
                        normalize, min_stripe, options, fit_blur,
                        _predicted_numbering(approx, inputs.board), defer=True)
    reads = read_pairs(reader, inputs.records, threads)
    size = same_size(reads, of_loaded=True) or inputs.size
    if any(r.kept and isinstance(r.found, _Unnumbered) for r in reads):
        _number_by_agreement(reads, inputs.board, approx, reader)
    offset, taken = session_offset(reads, reader)
    fitted = session_blur(reads)
    blur_var = options["blur_var"] if fitted is None else fitted
    extraction = {"smooth_along": options["smooth_along"],
                  **({"albedo_step": options["albedo_step"]}
                     if options.get("albedo_step") is not None else {}),
                  "blur_var": blur_var, "blur_var_fitted": fit_blur}
    return PaperViews([_account(r, blur_var) for r in reads], inputs.board, size, normalize,
                      len(inputs.records), extraction, offset, taken)


def _account(read: PairRead, blur_var: float) -> ImageReport:
    """A pair's account before its calibration points: a rejected pair's, or a kept pair's
    holding its view."""
    pair = read.pair
    on, off = (pair.on_name, pair.off_name) if pair is not None else read.names
    if not read.kept:
        return ImageReport(read.id, read.index, str(on), str(off), False, read.why,
                           pair.stripe.counts() if pair is not None else {}, 0)
    corners = read.found
    view = ViewData(read.id, np.asarray(corners.pixels, float),
                    np.asarray(corners.index, int), pair.stripe.pixels, pair.pose,
                    stripe=pair.stripe, joints=pair.joints)
    return ImageReport(read.id, read.index, on, off, True, "", pair.stripe.counts(),
                       len(corners), 0, {}, blur_var, view)


def points_of_views(views: PaperViews, *, mode: Mode = "corners", tolerance: float = 0.5,
                    step: int = 8) -> tuple[Any, list[ImageReport]]:
    """The paper model's calibration data set derived from a session's views
    (:func:`paper_views`): each view's calibration points (:func:`view_points` in ``mode``;
    in "homography" mode with the division distortion fitted to the corners of all views),
    and the pairs' accounts (a view that gives no point is rejected, saying why). As
    :func:`dataset_from_images` returns them."""
    distortion = None
    if mode == "homography":
        corners = [view_corners(v, views.board, views.image_size) for v in views.views]
        distortion = fit_division_distortion(corners) if corners else None
    points = _Points()
    for report in views.reports:
        points.add(report, views.board, views.image_size, mode, tolerance, step, distortion)
    taken = views.offset_taken
    meta = {"source": "images", "mode": mode, "normalize": views.normalize,
            **_board_meta(views.board), **views.extraction, "pairs": views.pairs,
            "pairs_used": sum(r.ok for r in points.reports),
            "image_size": list(views.image_size) if views.image_size else None,
            **({"albedo_offset_session": views.albedo_offset} if taken else {}),
            **({"albedo_offset_taken_by": [r.id for r in points.reports
                                           if r.index in taken]} if taken else {}),
            **({} if distortion is None else {"division_distortion": {
                "centre_px": [float(x) for x in distortion[0]],
                "k_per_px2": float(distortion[1])}})}
    return points.dataset(meta), points.reports


@dataclass
class _Inputs:
    """A session's records and what its manifest says of them."""

    records: list[Any]
    folder: Any
    unit: str
    size: tuple[int, int] | None
    board: Any
    robot: Any
    approx: Any
    direction: str | None = None  # the manifest's stripe_direction


def _session_inputs(source: Any, robot: Any, board: Any, joint_unit: str | None,
                    base_from_board: np.ndarray | None) -> _Inputs:
    """The records of a session (a manifest or a list of records), checked, with its arm,
    board and image size (given, the manifest's, or the defaults)."""
    from ..geometry.board import Checkerboard
    from ..geometry.robot import Robot
    from ..models.params import Parameters

    folder = direction = None
    unit = joint_unit
    size = None
    if isinstance(source, (list, tuple)):
        records = list(source)
        if unit is None:
            unit = "rad"
    else:
        records, doc, folder = read_session_manifest(source)
        unit = doc.get("joint_unit", "rad") if unit is None else unit
        direction = doc.get("stripe_direction")
        if board is None and doc.get("board") is not None:
            from ..data.manifest import checkerboard_of

            board = checkerboard_of(doc["board"], source)
            if base_from_board is not None and isinstance(doc["board"], dict) and \
                    "origin" not in doc["board"]:
                board = _placed(board, base_from_board)
        robot = manifest_robot(doc, robot, source)
        if isinstance(doc.get("image_size"), list) and len(doc["image_size"]) == 2:
            size = (int(doc["image_size"][0]), int(doc["image_size"][1]))
    if unit not in ("rad", "deg"):
        raise ValueError(f"joint_unit must be 'rad' or 'deg', got {unit!r}")
    if not records:
        raise ValueError("the session has no image pairs")
    require_poses(records, "the paper model's calibration points need the robot pose of "
                  "every view: calibrate a bench session with the opencv model (--model "
                  "opencv)")
    return _Inputs(records, folder, unit, size, Checkerboard() if board is None else board,
                   Robot.scorbot_er7() if robot is None else robot, Parameters.nominal(),
                   direction)


def _board_stripe_options(stripe_options: dict[str, Any]) -> dict[str, Any]:
    """The stripe options of a calibration session, checked once up front (a typo is the
    caller's error, not the image's): Steger's smoothing along the stripe by default
    :data:`BOARD_SMOOTH_ALONG` (the stripe on the board is one straight line, a curve of the
    lens's distortion) and the blur variance checked (None: fitted to the session later)."""
    extract_stripe(np.zeros((4, 4), np.uint8), **core_options(stripe_options))
    options = dict(stripe_options)
    options["smooth_along"] = smooth_along_of(options.get("smooth_along", BOARD_SMOOTH_ALONG))
    options["blur_var"] = checked_blur_var(options.get("blur_var"))
    return options


@dataclass(frozen=True)
class _Unnumbered:
    """A board the approximate parameters could not number (``why``): numbered again once
    the views' agreement fixes the hand-eye (:func:`_number_by_agreement`)."""

    why: str


def _predicted_numbering(approx: Any, board: Any) -> Any:
    """The paper model's numbering of a pair's board (for :class:`PairReader`): the corners
    found where ``approx`` and the pair's pose predict them (:func:`find_corners`), or
    :class:`_Unnumbered` when the prediction cannot number them."""

    def number(pid: str, pair: Pair) -> Corners | _Unnumbered:
        import cv2

        from .corners import predicted_corners

        try:
            return find_corners(pair.board_image, board,
                                expected=predicted_corners(approx, pair.pose, board))
        except BoardNotFoundError as e:
            raise PairRejected(f"checkerboard: {e}") from None
        except ValueError as e:
            return _Unnumbered(f"checkerboard: {e}")
        except cv2.error as e:
            raise opencv_failure(e, "checkerboard") from None

    return number


@dataclass
class _Points:
    """The calibration points of a session's views, gathered view by view."""

    reports: list[ImageReport] = field(default_factory=list)
    columns: dict[str, list[Any]] = field(default_factory=lambda: {
        k: [] for k in ("pixels", "points", "joints", "poses", "pose_index", "quality")})
    ids: list[str] = field(default_factory=list)

    def add(self, report: ImageReport, board: Any, size: tuple[int, int] | None, mode: Mode,
            tolerance: float, step: int, distortion: Any) -> None:
        """One view's calibration points (its account completed), or its account saying why
        it has none; a rejected pair's account as it is."""
        import cv2

        view = report.view
        if view is None:
            self.reports.append(report)
            return
        rejected: dict[str, str] = {}
        try:
            try:
                cp = view_points(view, board, image_size=size, mode=mode, tolerance=tolerance,
                                 step=step, distortion=distortion)
            except cv2.error as e:
                raise opencv_failure(e, "calibration points") from None
            rejected = dict(cp.rejected)
            if len(cp) == 0:
                raise PairRejected("no calibration points: " + (
                    "; ".join(f"{k}: {v}" for k, v in cp.rejected.items()) or
                    ("no corner lies on the stripe" if mode == "corners" else
                     "the stripe does not cross a square with four found corners")))
        except PairRejected as e:
            self.reports.append(replace(report, ok=False, reason=str(e), points=0,
                                        rejected=rejected, blur_var=None, view=None))
            return
        self.reports.append(replace(report, points=len(cp), rejected=rejected))
        c = self.columns
        c["pixels"].append(cp.pixels)
        c["points"].append(cp.points)
        self.ids += [f"{view.id}:{k}" for k in cp.ids]
        c["joints"].append(None if view.joints is None
                           else np.repeat(view.joints[None], len(cp), axis=0))
        c["poses"].append(np.repeat(view.base_from_hand[None], len(cp), axis=0))
        c["pose_index"].append(np.full(len(cp), report.index, dtype=np.int64))
        c["quality"].append(_point_quality(view.stripe, cp))

    def dataset(self, meta: dict[str, Any]) -> Any:
        """The data set of the points gathered; ValueError when no pair gave one."""
        from ..data.dataset import Dataset

        c = self.columns
        if not c["pixels"]:
            raise ValueError("no image pair gave a calibration point:\n" +
                             "\n".join(str(r) for r in self.reports))
        joints = None if any(j is None for j in c["joints"]) else np.vstack(c["joints"])
        return Dataset(np.vstack(c["pixels"]), np.concatenate(c["poses"]),
                       np.vstack(c["points"]), ids=np.array(self.ids), joints=joints,
                       pose_index=np.concatenate(c["pose_index"]),
                       quality={k: np.concatenate([q[k] for q in c["quality"]])
                                for k in c["quality"][0]}, meta=meta)


def _board_meta(board: Any) -> dict[str, Any]:
    """The data set's record of the board its reference points lie on (rows, cols, square,
    its pose in the base), for the verdict's chain checks."""
    try:
        pose = np.asarray(board.base_from_board(), float)
    except (AttributeError, ValueError):
        return {}
    return {"board": {"rows": int(board.rows), "cols": int(board.cols),
                      "square": float(board.square), "base_from_board": pose.tolist()}}


def _placed(board: Any, base_from_board: np.ndarray) -> Any:
    """``board`` (rows, cols, square) placed at the pose ``base_from_board``."""
    from ..geometry.board import Checkerboard

    r = np.asarray(base_from_board, float)[:3, :3]
    u, _, vt = np.linalg.svd(r)  # the nearest rotation: unit, orthogonal directions
    r = u @ vt
    return Checkerboard(rows=board.rows, cols=board.cols, square=board.square,
                        origin=tuple(float(x) for x in np.asarray(base_from_board)[:3, 3]),
                        row_direction=tuple(float(x) for x in r[:, 0]),
                        col_direction=tuple(float(x) for x in r[:, 1]))


def _number_by_agreement(reads: list[PairRead], board: Any, approx: Any,
                         reader: PairReader) -> None:
    """Number again the boards the approximate parameters could not (partly visible ones,
    predicted a third of a square or more off): with the camera and hand-eye on which all
    views' corners agree (:mod:`hmlvs.image.consensus`), the board is predicted within a few
    pixels. ``reads`` entries are replaced in place (numbered and measured by ``reader``, or
    rejected saying why the view stays unnumbered)."""
    import cv2

    waiting = [n for n, r in enumerate(reads) if r.kept and isinstance(r.found, _Unnumbered)]
    grids: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for r in reads:
        if r.kept and isinstance(r.found, Corners):
            c = r.found
            grids.append((c.pixels, np.c_[c.index // board.cols, c.index % board.cols],
                          r.pair.pose))
    agreed, why = _agreement(grids, [reads[n].pair for n in waiting], board, approx)
    for n in waiting:
        r = reads[n]
        if agreed is None:
            reads[n] = r.rejected(f"{r.found.why}; {why}")
            continue
        from .partial import predicted_board_pixels

        expected = predicted_board_pixels(agreed, r.pair.pose, board)
        try:
            corners = find_corners(r.pair.board_image, board, expected=expected)
        except (ValueError, cv2.error) as e:
            reads[n] = r.rejected(f"checkerboard: {e} (predicted with the hand-eye the views "
                                  "agree on)")
            continue
        reads[n] = reader.measured(replace(r, found=corners))


def _agreement(grids: list[tuple[np.ndarray, np.ndarray, np.ndarray]], waiting: list[Pair],
               board: Any, approx: Any) -> tuple[Any, str]:
    """The camera, hand-eye and board on which the numbered views' corners (``grids``: pixels,
    (row, column), pose) and the grids found in the ``waiting`` pairs agree, as
    :func:`~hmlvs.image.partial.predicted_board_pixels` reads them; or (None, why not)."""
    import cv2

    from .._arrays import as_params
    from .consensus import MIN_VIEWS, consensus_hand_eye, grid_intrinsics
    from .grid import detect_grid

    grids = list(grids)
    for pair in waiting:
        try:
            g = detect_grid(pair.board_image, board)
        except ValueError:
            continue
        m, n = g.shape
        ij = np.stack([a.ravel() for a in np.meshgrid(np.arange(m), np.arange(n),
                                                      indexing="ij")], axis=1)
        grids.append((g.pixels.reshape(-1, 2), ij, pair.pose))
    if len(grids) < MIN_VIEWS:
        return None, (f"only {len(grids)} views show a grid of corners, too few to number "
                      "partly visible boards by their agreement")
    q = as_params(approx)
    try:
        k0 = np.array([[q[0] / q[1], 0.0, q[3]], [0.0, q[0] / q[2], q[4]], [0, 0, 1.0]])
        k, d = grid_intrinsics([(px, ij) for px, ij, _ in grids], board.square,
                               waiting[0].size, k0)
        hand_eye = consensus_hand_eye(grids, board, k, d)
    except (ValueError, cv2.error) as e:
        return None, str(e)
    from types import SimpleNamespace

    return SimpleNamespace(camera_matrix=k, dist_coeffs=d, hand_from_camera=hand_eye,
                           base_from_board=board.base_from_board()), ""


def _point_quality(stripe: StripeResult, cp: Any) -> dict[str, np.ndarray]:
    """The stripe's quality at calibration points ``cp`` (:attr:`Dataset.quality`): the
    points' own centre uncertainty, and width, peak and residual of the scan line each lies
    on (nearest it, for a corner mode point's foot on the fitted centre line)."""
    scan = cp.pixels[:, 0] if stripe.direction == "columns" else cp.pixels[:, 1]
    line = np.clip(np.rint(scan).astype(int), 0, stripe.position.size - 1)
    residual = stripe.residual if stripe.residual is not None else \
        np.full(stripe.position.size, np.nan)
    return {"sigma": np.asarray(cp.sigma, float), "width": stripe.width[line],
            "peak": stripe.intensity[line], "residual": residual[line]}
