"""A session of laser on/off images -> the paper model's calibration data set
(:func:`dataset_from_images`): every pair's stripe and numbered corners, then the session's
albedo offset and blur, then the calibration points of each view."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..data.views import ViewData
from .accounts import ImageReport
from .corners import BoardNotFoundError, find_corners
from .points import Mode, calibration_points, fit_division_distortion
from .session import (
    BOARD_SMOOTH_ALONG,
    Pair,
    PairRejected,
    check_stripe,
    checked_blur_var,
    core_options,
    edge_shift,
    manifest_robot,
    opencv_failure,
    read_pair,
    read_session_manifest,
    record_id,
    record_names,
    require_poses,
    restripe,
    session_blur_var,
    smooth_along_of,
    stripe_pending,
    with_blur_var,
)
from .stripe import StripeResult, extract_stripe

#: a pair on its way: (id, index, pair, corners, info)
Found = tuple[str, int, Pair, Any, dict[str, Any]]


def dataset_from_images(source: Any, *, robot: Any = None, board: Any = None,
                        params: Any = None, mode: Mode = "corners", normalize: bool = True,
                        channel: int | None = None, tolerance: float = 0.5, step: int = 8,
                        min_stripe: int = 20, joint_unit: str | None = None,
                        base_from_board: np.ndarray | None = None,
                        **stripe_options: Any) -> tuple[Any, list[ImageReport]]:
    """Laser on/off image pairs + joint readings -> a calibration :class:`~hmlvs.Dataset`.

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
    stripe_options : options of :func:`stripe_from_pair`. Without ``blur_var`` the camera's
        blur variance for the correction at the squares' edges is fitted to the session
        (:func:`session_blur_var`); ``meta["blur_var"]`` records the value used.

    Returns
    -------
    (dataset, report) : the data set (ids ``"<pose id>:<point id>"``, ``pose_index`` = pair
        index, joints in rad) and one :class:`ImageReport` per pair.
    """
    inputs = _session_inputs(source, robot, board, joint_unit, base_from_board)
    run = _Run(board=inputs.board, robot=inputs.robot, approx=inputs.approx
               if params is None else params, normalize=normalize, min_stripe=min_stripe,
               stripe_options=_board_stripe_options(stripe_options))
    run.fit_blur = stripe_options.get("blur_var") is None
    run.read_all(inputs, channel)
    run.session_offset()
    run.session_blur()
    distortion = None
    if mode == "homography":
        views = [f[3] for f in run.found if not isinstance(f, ImageReport)]
        distortion = fit_division_distortion(views) if views else None
    points = _Points()
    for item in run.found:
        points.add(item, run.board, mode, tolerance, step, distortion, run.blur_var)
    meta = {"source": "images", "mode": mode, "normalize": normalize, **_board_meta(run.board),
            **run.meta(), "pairs": len(inputs.records),
            "pairs_used": sum(r.ok for r in points.reports),
            "image_size": list(run.size) if run.size else None,
            **({"albedo_offset_session": run.offset} if run.taken else {}),
            **({"albedo_offset_taken_by": [r.id for r in points.reports
                                           if r.index in run.taken]} if run.taken else {}),
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


def _session_inputs(source: Any, robot: Any, board: Any, joint_unit: str | None,
                    base_from_board: np.ndarray | None) -> _Inputs:
    """The records of a session (a manifest or a list of records), checked, with its arm,
    board and image size (given, the manifest's, or the defaults)."""
    from ..geometry.board import Checkerboard
    from ..geometry.robot import Robot
    from ..models.params import Parameters

    folder = None
    unit = joint_unit
    size = None
    if isinstance(source, (list, tuple)):
        records = list(source)
        if unit is None:
            unit = "rad"
    else:
        records, doc, folder = read_session_manifest(source)
        unit = doc.get("joint_unit", "rad") if unit is None else unit
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
                   Robot.scorbot_er7() if robot is None else robot, Parameters.nominal())


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


@dataclass
class _Run:
    """A session's pairs on their way to calibration points: first every pair's stripe and
    corners (:meth:`read_all`), then the albedo offset and the blur variance of the whole
    session (one board print, one laser, one lens)."""

    board: Any
    robot: Any
    approx: Any
    normalize: bool
    min_stripe: int
    stripe_options: dict[str, Any]
    fit_blur: bool = False
    size: tuple[int, int] | None = None
    #: per pair, in the session's order: its report (rejected) or its Found tuple
    found: list[ImageReport | Found] = field(default_factory=list)
    offset: float | None = None
    taken: set[int] = field(default_factory=set)

    @property
    def blur_var(self) -> float:
        return float(self.stripe_options["blur_var"])

    def accept(self, pid: str, index: int, pair: Pair, corners: Any, info: dict[str, Any]
               ) -> Found:
        """A pair whose board was numbered; its images are dropped once its stripe is final."""
        if not stripe_pending(pair):
            if self.fit_blur:
                info["edge"] = edge_shift(pair, self.normalize, self.stripe_options)
            pair = replace(pair, on=None, off=None)
        return (pid, index, pair, corners, info)

    def read_all(self, inputs: _Inputs, channel: int | None) -> None:
        """Every pair's stripe and numbered corners (or its report); boards the approximate
        parameters could not number are numbered again by the views' agreement."""
        import cv2

        from .corners import predicted_corners

        self.size = inputs.size
        # pairs whose board the prediction could not number: (place in found, pair, info,
        # error)
        unnumbered: list[tuple[int, Pair, dict[str, Any], str]] = []
        for index, rec in enumerate(inputs.records):
            pid = record_id(rec, index)
            on_name, off_name = record_names(rec)
            info: dict[str, Any] = {}
            try:
                pair = read_pair(rec, index, inputs.folder, inputs.unit, self.robot,
                                 self.size, channel, self.normalize, self.stripe_options,
                                 self.min_stripe, defer=True)
                on_name, off_name, self.size = pair.on_name, pair.off_name, pair.size
                info["stripe"] = pair.stripe.counts()
                try:
                    corners = find_corners(pair.board_image, self.board,
                                           expected=predicted_corners(self.approx, pair.pose,
                                                                      self.board))
                except BoardNotFoundError as e:
                    raise PairRejected(f"checkerboard: {e}") from None
                except ValueError as e:
                    # numbered again once the views' agreement fixes the hand-eye (below)
                    unnumbered.append((len(self.found), pair, info, f"checkerboard: {e}"))
                    self.found.append(ImageReport(pid, index, str(on_name), str(off_name),
                                                  False, f"checkerboard: {e}",
                                                  info["stripe"], 0))
                    continue
                except cv2.error as e:
                    raise opencv_failure(e, "checkerboard") from None
            except PairRejected as e:
                self.found.append(ImageReport(pid, index, str(on_name), str(off_name), False,
                                              str(e), info.get("stripe", {}),
                                              info.get("corners", 0)))
                continue
            self.found.append(self.accept(pid, index, pair, corners, info))
        if unnumbered:
            _number_by_agreement(self.found, unnumbered, self.board, self.approx, self.accept)

    def session_offset(self) -> None:
        """One board print and one laser: a pair whose stripe lies on one level of the board
        only (along a row of light squares) cannot fit the albedo offset; it takes the
        session's, the median of the other pairs' (with 0 instead, its stripe would be lost
        on the light squares and pulled towards the dark ones where it touches them)."""
        offsets = [f[2].offset for f in self.found if not isinstance(f, ImageReport)
                   and f[2].offset is not None and np.isfinite(f[2].offset)]
        self.offset = float(np.median(offsets)) if offsets else None
        for n, item in enumerate(self.found):
            if isinstance(item, ImageReport) or not stripe_pending(item[2]):
                continue
            pid, index, pair, corners, info = item
            options = self.stripe_options
            try:
                if self.offset is not None:
                    pair = restripe(pair, self.offset, self.normalize, options,
                                    self.min_stripe)
                    options = dict(options, albedo_offset=self.offset)
                else:
                    check_stripe(pair, self.min_stripe)
            except PairRejected as e:
                self.found[n] = ImageReport(pid, index, pair.on_name, pair.off_name, False,
                                            str(e), pair.stripe.counts(), 0)
                continue
            if self.offset is not None:
                self.taken.add(index)
            if self.fit_blur:
                info["edge"] = edge_shift(pair, self.normalize, options)
            info["stripe"] = pair.stripe.counts()
            self.found[n] = (pid, index, replace(pair, on=None, off=None), corners, info)

    def session_blur(self) -> None:
        """Without a given blur variance, the session's (:func:`session_blur_var`) applied to
        every kept pair's stripe."""
        if not self.fit_blur:
            return
        kept = [f for f in self.found if not isinstance(f, ImageReport)]
        self.stripe_options["blur_var"] = session_blur_var([(f[2].stripe, f[4]["edge"])
                                                            for f in kept])
        for n, item in enumerate(self.found):
            if not isinstance(item, ImageReport):
                pid, index, pair, corners, info = item
                self.found[n] = (pid, index, replace(pair, stripe=with_blur_var(
                    pair.stripe, info["edge"], self.blur_var)), corners, info)

    def meta(self) -> dict[str, Any]:
        """What the data set's ``meta`` records of the stripes' extraction."""
        o = self.stripe_options
        return {"smooth_along": o["smooth_along"],
                **({"albedo_step": o["albedo_step"]} if o.get("albedo_step") is not None
                   else {}),
                "blur_var": self.blur_var, "blur_var_fitted": self.fit_blur}


@dataclass
class _Points:
    """The calibration points of a session's pairs, gathered view by view."""

    reports: list[ImageReport] = field(default_factory=list)
    columns: dict[str, list[Any]] = field(default_factory=lambda: {
        k: [] for k in ("pixels", "points", "joints", "poses", "pose_index", "quality")})
    ids: list[str] = field(default_factory=list)

    def add(self, item: ImageReport | Found, board: Any, mode: Mode, tolerance: float,
            step: int, distortion: Any, blur_var: float) -> None:
        """One pair's calibration points, or its report saying why it has none."""
        import cv2

        if isinstance(item, ImageReport):
            self.reports.append(item)
            return
        pid, index, pair, corners, info = item
        info["corners"] = len(corners)
        try:
            try:
                cp = calibration_points(pair.stripe, corners, board, mode=mode,
                                        tolerance=tolerance, step=step, distortion=distortion)
            except cv2.error as e:
                raise opencv_failure(e, "calibration points") from None
            info["rejected"] = dict(cp.rejected)
            if len(cp) == 0:
                raise PairRejected("no calibration points: " + (
                    "; ".join(f"{k}: {v}" for k, v in cp.rejected.items()) or
                    ("no corner lies on the stripe" if mode == "corners" else
                     "the stripe does not cross a square with four found corners")))
        except PairRejected as e:
            self.reports.append(ImageReport(pid, index, pair.on_name, pair.off_name, False,
                                            str(e), info.get("stripe", {}),
                                            info.get("corners", 0), 0,
                                            info.get("rejected", {})))
            return
        self.reports.append(ImageReport(
            pid, index, pair.on_name, pair.off_name, True, "", info["stripe"],
            info["corners"], len(cp), info["rejected"], blur_var,
            ViewData(pid, np.asarray(corners.pixels, float), np.asarray(corners.index, int),
                     pair.stripe.pixels, pair.pose)))
        c = self.columns
        c["pixels"].append(cp.pixels)
        c["points"].append(cp.points)
        self.ids += [f"{pid}:{k}" for k in cp.ids]
        c["joints"].append(None if pair.joints is None
                           else np.repeat(pair.joints[None], len(cp), axis=0))
        c["poses"].append(np.repeat(pair.pose[None], len(cp), axis=0))
        c["pose_index"].append(np.full(len(cp), index, dtype=np.int64))
        c["quality"].append(_point_quality(pair.stripe, cp))

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


def _number_by_agreement(found: list[Any], unnumbered: list[tuple[int, Any, dict, str]],
                         board: Any, approx: Any, accept: Any) -> None:
    """Number again the boards the approximate parameters could not (partly visible ones,
    predicted a third of a square or more off): with the camera and hand-eye on which all
    views' corners agree (:mod:`hmlvs.image.consensus`), the board is predicted within a few
    pixels. ``found`` entries are replaced in place (by ``accept``'s tuple, or by a report
    saying why the view stays unnumbered)."""
    import cv2

    from .._arrays import as_params
    from .consensus import MIN_VIEWS, consensus_hand_eye, grid_intrinsics
    from .grid import detect_grid

    grids: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for item in found:
        if not isinstance(item, ImageReport):
            c = item[3]
            grids.append((c.pixels, np.c_[c.index // board.cols, c.index % board.cols],
                          item[2].pose))
    for _, pair, _, _ in unnumbered:
        try:
            g = detect_grid(pair.board_image, board)
        except ValueError:
            continue
        m, n = g.shape
        ij = np.stack([a.ravel() for a in np.meshgrid(np.arange(m), np.arange(n),
                                                      indexing="ij")], axis=1)
        grids.append((g.pixels.reshape(-1, 2), ij, pair.pose))
    q = as_params(approx)
    why = ""
    if len(grids) < MIN_VIEWS:
        why = (f"only {len(grids)} views show a grid of corners, too few to number partly "
               "visible boards by their agreement")
    else:
        try:
            k0 = np.array([[q[0] / q[1], 0.0, q[3]], [0.0, q[0] / q[2], q[4]], [0, 0, 1.0]])
            size = unnumbered[0][1].size
            k, d = grid_intrinsics([(px, ij) for px, ij, _ in grids], board.square, size, k0)
            hand_eye = consensus_hand_eye(grids, board, k, d)
        except (ValueError, cv2.error) as e:
            why = str(e)
    if not why:
        from types import SimpleNamespace

        from .partial import predicted_board_pixels

        # the camera, hand-eye and board the views agree on, as predicted_board_pixels reads
        agreed = SimpleNamespace(camera_matrix=k, dist_coeffs=d, hand_from_camera=hand_eye,
                                 base_from_board=board.base_from_board())
    for place, pair, info, error in unnumbered:
        old = found[place]
        if not why:
            expected = predicted_board_pixels(agreed, pair.pose, board)
            try:
                corners = find_corners(pair.board_image, board, expected=expected)
            except (ValueError, cv2.error) as e:
                found[place] = replace(old, reason=f"checkerboard: {e} (predicted with the "
                                       "hand-eye the views agree on)")
                continue
            found[place] = accept(old.id, old.index, pair, corners, info)
        else:
            found[place] = replace(old, reason=f"{error}; {why}")


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
