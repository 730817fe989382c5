"""A session of laser on/off images -> stripes and a calibration data set."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .. import _core
from ..data.views import ViewData
from .accounts import ImageReport
from .colour import (  # noqa: F401 (laser_channel, estimate_background re-exported)
    board_gray,
    colour_stripe,
    drop_jumps,
    estimate_background,
    is_colour,
    laser_channel,
)
from .corners import BoardNotFoundError, find_corners
from .points import Mode, calibration_points, fit_division_distortion
from .stripe import (
    StripeOptions,
    StripeResult,
    StripeStatus,
    as_gray,
    extract_stripe,
    finite_number,
    real_number,
)

#: the laser-off name of a pair without a laser-off frame (shown in its report)
ESTIMATED_OFF = "none: background estimated from the laser-on image"

# ------------------------------------------------------------------------------------------
# A session of images -> a calibration data set


class PairRejected(Exception):
    """A whole image pair is unusable (the message says why)."""


_BOARD_POSE_HINT = ("check the board's origin, row_direction and col_direction in the "
                    "manifest and this pair's pose")


def opencv_failure(err: Exception, stage: str, hint: str = _BOARD_POSE_HINT) -> PairRejected:
    """An OpenCV error inside one pair's processing, as that pair's rejection: OpenCV
    asserts on degenerate input (corners predicted far from the detected ones, as with a
    wrong board origin or direction in the manifest), which concerns this pair only."""
    lines = str(err).strip().splitlines() or [type(err).__name__]
    what = getattr(err, "err", "") or lines[-1]
    func = getattr(err, "func", "")
    return PairRejected(f"{stage}: OpenCV failed ({func + ': ' if func else ''}{what})"
                   + (f"; {hint}" if hint else ""))


def _load(item: Any, folder: Any, what: str) -> tuple[np.ndarray, str]:
    import os
    from pathlib import Path

    from .._io import read_image
    if isinstance(item, np.ndarray):
        return item, "<array>"
    if not isinstance(item, (str, Path)):
        raise PairRejected(f"the {what} image must be a file name or an array, got "
                      f"{type(item).__name__}")
    path = Path(item)
    if folder is not None and not path.is_absolute():
        path = Path(folder) / path
    try:
        os.fsencode(path)  # before is_file, which says False for a name no file can have
        if not path.is_file():
            raise PairRejected(f"the {what} image file {path} does not exist")
        img = read_image(path)  # by bytes: cv2.imread crashes on a name that is not UTF-8
    except UnicodeError:
        raise PairRejected(f"the {what} image file {str(path)!r}: its name holds a character no "
                      "file name can (an unpaired surrogate); rename it") from None
    except ValueError as e:
        raise PairRejected(str(e)) from None
    except OSError as e:
        raise PairRejected(f"the {what} image file {path} cannot be read ({e.strerror})") from None
    if img is None:
        raise PairRejected(f"the {what} image file {path.name} cannot be read as an image")
    return img, path.name


def read_session_manifest(source: Any) -> tuple[list[dict[str, Any]], dict[str, Any], Any]:
    from ..data.manifest import read_manifest

    return read_manifest(source)


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
    import cv2

    from ..data.dataset import Dataset
    from ..geometry.board import Checkerboard
    from ..geometry.robot import Robot
    from ..models.params import Parameters
    from .corners import predicted_corners

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
        robot = _manifest_robot(doc, robot, source)
        if isinstance(doc.get("image_size"), list) and len(doc["image_size"]) == 2:
            size = (int(doc["image_size"][0]), int(doc["image_size"][1]))
    if unit not in ("rad", "deg"):
        raise ValueError(f"joint_unit must be 'rad' or 'deg', got {unit!r}")
    if not records:
        raise ValueError("the session has no image pairs")
    _require_poses(records, "the paper model's calibration points need the robot pose of "
                   "every view: calibrate a bench session with the opencv model (--model "
                   "opencv)")
    robot = Robot.scorbot_er7() if robot is None else robot
    board = Checkerboard() if board is None else board
    approx = Parameters.nominal() if params is None else params
    # Check the stripe options once, up front: a typo is the caller's error, not the image's.
    extract_stripe(np.zeros((4, 4), np.uint8), **_core_options(stripe_options))
    # The stripe on the board is one straight line (a curve of the lens's distortion):
    # Steger's line detector may smooth along it over more than across it.
    stripe_options = dict(stripe_options)
    stripe_options["smooth_along"] = smooth_along_of(stripe_options.get("smooth_along",
                                                                      BOARD_SMOOTH_ALONG))
    # The camera's blur, for the correction of the centres at the squares' edges: given, or
    # fitted to the whole session once every stripe is in (session_blur_var).
    fit_blur = stripe_options.get("blur_var") is None
    stripe_options["blur_var"] = checked_blur_var(stripe_options.get("blur_var"))

    # First every pair's stripe and corners; then, in homography mode, the lens distortion
    # fitted to the corners of all views (one lens: views with few corners need it), and the
    # calibration points.
    found: list[ImageReport | tuple[Any, ...]] = []

    def accept(pid: str, index: int, pair: _Pair, corners: Any, info: dict[str, Any]
               ) -> tuple[Any, ...]:
        if not _pending(pair):
            if fit_blur:
                info["edge"] = edge_shift(pair, normalize, stripe_options)
            pair = replace(pair, on=None, off=None)  # the images are no longer needed
        return (pid, index, pair, corners, info)

    # pairs whose board the prediction could not number: (place in found, pair, info, error)
    unnumbered: list[tuple[int, _Pair, dict[str, Any], str]] = []
    for index, rec in enumerate(records):
        pid = record_id(rec, index)
        on_name, off_name = record_names(rec)
        info: dict[str, Any] = {}
        try:
            pair = read_pair(rec, index, folder, unit, robot, size, channel, normalize,
                              stripe_options, min_stripe, defer=True)
            on_name, off_name, size = pair.on_name, pair.off_name, pair.size
            info["stripe"] = pair.stripe.counts()
            try:
                corners = find_corners(pair.board_image, board, expected=predicted_corners(
                    approx, pair.pose, board))
            except BoardNotFoundError as e:
                raise PairRejected(f"checkerboard: {e}") from None
            except ValueError as e:
                # numbered again once the views' agreement fixes the hand-eye (below)
                unnumbered.append((len(found), pair, info, f"checkerboard: {e}"))
                found.append(ImageReport(pid, index, str(on_name), str(off_name), False,
                                         f"checkerboard: {e}", info["stripe"], 0))
                continue
            except cv2.error as e:
                raise opencv_failure(e, "checkerboard") from None
        except PairRejected as e:
            found.append(ImageReport(pid, index, str(on_name), str(off_name), False, str(e),
                                     info.get("stripe", {}), info.get("corners", 0)))
            continue
        found.append(accept(pid, index, pair, corners, info))
    if unnumbered:
        _number_by_agreement(found, unnumbered, board, approx, accept)
    # One board print and one laser: a pair whose stripe lies on one level of the board only
    # (along a row of light squares) cannot fit the albedo offset; it takes the session's,
    # the median of the other pairs' (with 0 instead, its stripe would be lost on the
    # light squares and pulled towards the dark ones where it touches them).
    offsets = [f[2].offset for f in found if not isinstance(f, ImageReport)
               and f[2].offset is not None and np.isfinite(f[2].offset)]
    session_offset = float(np.median(offsets)) if offsets else 0.0
    taken: set[int] = set()
    for n, item in enumerate(found):
        if isinstance(item, ImageReport) or not _pending(item[2]):
            continue
        pid, index, pair, corners, info = item
        try:
            if offsets:
                pair = _restripe(pair, session_offset, normalize, stripe_options, min_stripe)
            else:
                _check_stripe(pair, min_stripe)
        except PairRejected as e:
            found[n] = ImageReport(pid, index, pair.on_name, pair.off_name, False, str(e),
                                   pair.stripe.counts(), 0)
            continue
        if offsets:
            taken.add(index)
        if fit_blur:
            info["edge"] = edge_shift(pair, normalize, dict(stripe_options,
                                                             albedo_offset=session_offset)
                                       if offsets else stripe_options)
        info["stripe"] = pair.stripe.counts()
        found[n] = (pid, index, replace(pair, on=None, off=None), corners, info)
    blur_var = stripe_options["blur_var"]
    if fit_blur:
        kept = [f for f in found if not isinstance(f, ImageReport)]
        blur_var = session_blur_var([(f[2].stripe, f[4]["edge"]) for f in kept])
        for n, item in enumerate(found):
            if not isinstance(item, ImageReport):
                pid, index, pair, corners, info = item
                found[n] = (pid, index, replace(pair, stripe=with_blur_var(
                    pair.stripe, info["edge"], blur_var)), corners, info)
    distortion = None
    if mode == "homography":
        views = [f[3] for f in found if not isinstance(f, ImageReport)]
        distortion = fit_division_distortion(views) if views else None

    reports: list[ImageReport] = []
    px_all, pt_all, ids_all, joints_all, pidx_all, poses_all = [], [], [], [], [], []
    quality_all: list[dict[str, np.ndarray]] = []
    for item in found:
        if isinstance(item, ImageReport):
            reports.append(item)
            continue
        pid, index, pair, corners, info = item
        on_name, off_name, joints, pose = pair.on_name, pair.off_name, pair.joints, pair.pose
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
            reports.append(ImageReport(pid, index, str(on_name), str(off_name), False, str(e),
                                       info.get("stripe", {}), info.get("corners", 0), 0,
                                       info.get("rejected", {})))
            continue
        reports.append(ImageReport(pid, index, str(on_name), str(off_name), True, "",
                                   info["stripe"], info["corners"], len(cp), info["rejected"],
                                   blur_var, ViewData(pid, np.asarray(corners.pixels, float),
                                                      np.asarray(corners.index, int),
                                                      pair.stripe.pixels, pose)))
        px_all.append(cp.pixels)
        pt_all.append(cp.points)
        ids_all += [f"{pid}:{k}" for k in cp.ids]
        joints_all.append(None if joints is None else np.repeat(joints[None], len(cp), axis=0))
        poses_all.append(np.repeat(pose[None], len(cp), axis=0))
        pidx_all.append(np.full(len(cp), index, dtype=np.int64))
        quality_all.append(_point_quality(pair.stripe, cp))
    if not px_all:
        raise ValueError("no image pair gave a calibration point:\n" +
                         "\n".join(str(r) for r in reports))
    joints_arr = None if any(j is None for j in joints_all) else np.vstack(joints_all)
    ds = Dataset(np.vstack(px_all), np.concatenate(poses_all), np.vstack(pt_all),
                 ids=np.array(ids_all), joints=joints_arr, pose_index=np.concatenate(pidx_all),
                 quality={k: np.concatenate([q[k] for q in quality_all])
                          for k in quality_all[0]},
                 meta={"source": "images", "mode": mode, "normalize": normalize,
                       **_board_meta(board),
                       "smooth_along": stripe_options["smooth_along"],
                       **({"albedo_step": stripe_options["albedo_step"]}
                          if stripe_options.get("albedo_step") is not None else {}),
                       "blur_var": blur_var, "blur_var_fitted": fit_blur,
                       "pairs": len(records),
                       "pairs_used": sum(r.ok for r in reports),
                       "image_size": list(size) if size else None,
                       **({"albedo_offset_session": session_offset,
                           "albedo_offset_taken_by": [r.id for r in reports if r.index in
                                                      taken]} if taken else {}),
                       **({} if distortion is None else {"division_distortion": {
                           "centre_px": [float(x) for x in distortion[0]],
                           "k_per_px2": float(distortion[1])}})})
    return ds, reports


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
    from .corners import detect_grid

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


def record_id(rec: Any, index: int) -> str:
    return str(rec.get("id", f"p{index:03d}")) if isinstance(rec, dict) else f"p{index:03d}"


def record_names(rec: Any) -> tuple[str, str]:
    if not isinstance(rec, dict):
        return "?", "?"
    return tuple(str(rec.get(k, "?")) if not isinstance(rec.get(k), np.ndarray) else "<array>"
                 for k in ("on", "off"))  # type: ignore[return-value]


def iter_stripes_from_images(source: Any, *, robot: Any = None,
                             joint_unit: str | None = None, channel: int | None = None,
                             normalize: bool = True, min_stripe: int = 20,
                             image_size: tuple[int, int] | None = None,
                             image_size_of: str = "the calibration", **stripe_options: Any
                             ) -> Iterator[tuple[ImageReport, Any, np.ndarray | None]]:
    """Laser on/off pairs + joint readings (a manifest or a list of records) -> stripes.

    The measurement counterpart of :func:`dataset_from_images` (no checkerboard needed): for
    each pair the same checks, difference image and stripe extraction. A pair that fails is
    reported and skipped. Entries may give a stripe list (``stripe``: CSV of u, v[, intensity])
    instead of an image pair, and a ``pose`` instead of joint readings. Returns (ids, stripes,
    base_from_hand poses (n, 4, 4), reports). With ``image_size`` (width, height: that of
    ``image_size_of``, the calibration) images of another size are refused, a ValueError
    naming both sizes: a calibration holds for one camera at one resolution.

    One pair at a time, in the session's order: (its report, its stripe or None when it was
    rejected, its base_from_hand pose or None); the frames are read as the iteration asks, so
    a scan of any length needs the memory of one frame. The manifest and the options are
    checked before the first pair is read. :func:`stripes_from_images` collects them.
    """
    from ..geometry.robot import Robot

    folder = None
    unit = joint_unit
    manifest_size = None
    if isinstance(source, (list, tuple)):
        records = list(source)
        unit = "rad" if unit is None else unit
    else:
        records, doc, folder = read_session_manifest(source)
        unit = doc.get("joint_unit", "rad") if unit is None else unit
        robot = _manifest_robot(doc, robot, source)
        if isinstance(doc.get("image_size"), list) and len(doc["image_size"]) == 2:
            manifest_size = (int(doc["image_size"][0]), int(doc["image_size"][1]))
            if image_size is not None and tuple(image_size) != manifest_size:
                raise ValueError(f"{source}: the manifest's image_size is {manifest_size[0]} x "
                                 f"{manifest_size[1]} pixels but {image_size_of} is for "
                                 f"{image_size[0]} x {image_size[1]} pixel images: measure "
                                 "with a calibration of this camera at this resolution")
    if unit not in ("rad", "deg"):
        raise ValueError(f"joint_unit must be 'rad' or 'deg', got {unit!r}")
    if not records:
        raise ValueError("the scan has no image pairs")
    _require_poses(records, "measuring in the robot's base frame needs the robot pose of "
                   "every frame")
    robot = Robot.scorbot_er7() if robot is None else robot
    # option typos fail here
    extract_stripe(np.zeros((4, 4), np.uint8), **_core_options(stripe_options))
    checked_blur_var(stripe_options.get("blur_var"))
    return _iter_pairs(records, folder, source, unit, robot, channel, normalize, min_stripe,
                       image_size, image_size_of, manifest_size, stripe_options)


def _iter_pairs(records: list[Any], folder: Any, source: Any, unit: str, robot: Any,
                channel: int | None, normalize: bool, min_stripe: int,
                image_size: tuple[int, int] | None, image_size_of: str,
                manifest_size: tuple[int, int] | None, stripe_options: dict[str, Any]
                ) -> Iterator[tuple[ImageReport, Any, np.ndarray | None]]:
    """The pairs of :func:`iter_stripes_from_images`, once its checks have passed."""
    from ..data.manifest import read_stripe_list

    blur_var = checked_blur_var(stripe_options.get("blur_var"))
    size = manifest_size
    for index, rec in enumerate(records):
        pid = record_id(rec, index)
        on_name, off_name = record_names(rec)
        try:
            if isinstance(rec, dict) and "stripe" in rec:
                _, pose = _record_pose(rec, robot, unit)
                path = Path(rec["stripe"])
                path = path if folder is None or path.is_absolute() else Path(folder) / path
                if not path.is_file():
                    raise PairRejected(f"the stripe list {path} does not exist")
                try:
                    px, inten = read_stripe_list(path)
                except ValueError as e:
                    raise PairRejected(str(e)) from None
                item: Any = StripeList(px, inten)
                on_name = off_name = path.name
                found = len(px)
            else:
                pair = read_pair(rec, index, folder, unit, robot, size, channel, normalize,
                                  stripe_options, min_stripe)
                size, pose, item = pair.size, pair.pose, pair.stripe
                on_name, off_name = pair.on_name, pair.off_name
                found = int(pair.stripe.found.sum())
                if image_size is not None and tuple(size) != tuple(image_size):
                    where = pid if folder is None else f"{source}: entry {pid}"
                    raise ValueError(f"{where}: the images {on_name} and {off_name} are "
                                     f"{size[0]} x {size[1]} pixels but {image_size_of} is for "
                                     f"{image_size[0]} x {image_size[1]} pixel images: "
                                     "measure with a calibration of this camera at this "
                                     "resolution")
        except PairRejected as e:
            yield (ImageReport(pid, index, on_name, off_name, False, str(e), {}, 0, 0, {}),
                   None, None)
            continue
        yield (ImageReport(pid, index, on_name, off_name, True, "",
                           getattr(item, "counts", lambda: {})(), 0, found, {},
                           None if isinstance(item, StripeList) else blur_var), item, pose)


def stripes_from_images(source: Any, **options: Any
                        ) -> tuple[list[str], list[Any], np.ndarray, list[ImageReport]]:
    """:func:`iter_stripes_from_images` (same arguments) collected: (ids, stripes,
    base_from_hand poses (n, 4, 4), reports) of the pairs that gave a stripe, and every
    pair's report."""
    ids, stripes, poses, reports = [], [], [], []
    for report, item, pose in iter_stripes_from_images(source, **options):
        reports.append(report)
        if item is not None:
            ids.append(report.id)
            stripes.append(item)
            poses.append(pose)
    return ids, stripes, np.array(poses).reshape(-1, 4, 4), reports


@dataclass
class _Pair:
    """One laser on/off pair after the checks shared by calibration and measurement."""

    on_name: str
    off_name: str
    joints: np.ndarray | None  # rad; None when the entry gives a pose
    pose: np.ndarray | None  # base_from_hand (4, 4); None in a bench session
    on: np.ndarray | None  # None once the stripe and corners are found
    off: np.ndarray | None  # the laser-off frame, or the background estimated from the
    # laser-on one
    stripe: StripeResult
    size: tuple[int, int]
    offset: float | None = None  # the albedo offset fitted (see _stripe_and_background)
    board: np.ndarray | None = None  # the frame for the board's corners, when not ``off``

    @property
    def board_image(self) -> np.ndarray:
        """The frame the board's corners are found on: a colour frame's grey (all channels),
        else the laser-off frame (or the background estimated for it)."""
        return self.board if self.board is not None else self.off


def read_pair(rec: Any, index: int, folder: Any, unit: str, robot: Any,
               size: tuple[int, int] | None, channel: int | None, normalize: bool,
               stripe_options: dict[str, Any], min_stripe: int,
               defer: bool = False) -> _Pair:
    """Load, check and extract the stripe of one manifest record; raises PairRejected.

    A record without ``off`` is a laser-on image alone: its background (the board under
    ambient light) is estimated from it (:func:`estimate_background`) and stands in for the
    laser-off frame, and the report's laser-off name says so. With ``defer``, a pair whose
    albedo offset could not be fitted (``offset`` NaN) is returned without the check of
    ``min_stripe``: its stripe is to be extracted again with the session's offset
    (:func:`_restripe`)."""
    if not isinstance(rec, dict):
        raise PairRejected(f"record {index} is not a mapping with on, off and joints")
    if "on" not in rec:
        raise PairRejected("the record lacks 'on'")
    joints, pose = _record_pose(rec, robot, unit)
    on, on_name = _load(rec["on"], folder, "laser-on")
    off = None
    off_name = ESTIMATED_OFF
    if rec.get("off") is not None:
        off, off_name = _load(rec["off"], folder, "laser-off")
    # a colour frame alone: the stripe from the laser's colour (hmlvs.image.colour), unless
    # a channel is named
    by_colour = off is None and channel is None and is_colour(on)
    board = board_gray(on if off is None else off) if is_colour(on) else None
    if channel is None:
        try:
            channel = laser_channel(on, off)
        except ValueError as e:
            raise PairRejected(str(e)) from None
    try:
        on_g = as_gray(on, "the laser-on image", channel)
        off_g = None if off is None else as_gray(off, "the laser-off image", channel)
    except ValueError as e:
        raise PairRejected(str(e)) from None
    if off_g is not None and (on_g.shape != off_g.shape or on_g.dtype != off_g.dtype):
        raise PairRejected(f"the laser-on image ({on_g.shape[1]} x {on_g.shape[0]}, "
                      f"{on_g.dtype}) and the laser-off image ({off_g.shape[1]} x "
                      f"{off_g.shape[0]}, {off_g.dtype}) differ in size or depth")
    if size is None:
        size = (on_g.shape[1], on_g.shape[0])
    if (on_g.shape[1], on_g.shape[0]) != size:
        raise PairRejected(f"the images are {on_g.shape[1]} x {on_g.shape[0]} pixels but the "
                      f"session's are {size[0]} x {size[1]}")
    top = float(np.iinfo(on_g.dtype).max)
    if off_g is not None and int(off_g.max()) == 0:
        raise PairRejected("the laser-off image is all black")
    if int(on_g.max()) == 0:
        raise PairRejected("the laser-on image is all black")
    if off_g is not None:
        diff_big = np.abs(on_g.astype(np.int32) - off_g.astype(np.int32)) > 0.1 * top
        if diff_big.mean() > 0.05:
            raise PairRejected(f"the laser-on and laser-off images differ in "
                          f"{100 * diff_big.mean():.0f}% of the pixels, far more than a "
                          "stripe: they are not a pair taken at the same pose")
    try:
        if by_colour:
            stripe, offset = colour_stripe(on, channel, **stripe_options), None
            off_g = board
        else:
            stripe, off_g, offset = _stripe_and_background(on_g, off_g, normalize,
                                                           stripe_options)
    except ValueError as e:  # the threshold leaves no pixel
        raise PairRejected(f"no laser stripe found in {on_name}: {e}") from None
    pair = _Pair(str(on_name), str(off_name), joints, pose, on_g, off_g, stripe, size, offset,
                 board)
    if not (defer and _pending(pair)):
        _check_stripe(pair, min_stripe)
    return pair


def _pending(pair: _Pair) -> bool:
    """Whether the pair's stripe waits for the session's albedo offset (see read_pair)."""
    return pair.offset is not None and bool(np.isnan(pair.offset))


def _check_stripe(pair: _Pair, min_stripe: int) -> None:
    if pair.stripe.found.sum() < min_stripe:
        raise PairRejected(f"no laser stripe found in {pair.on_name}: only "
                      f"{int(pair.stripe.found.sum())} scan lines have one "
                      f"({_counts_text(pair.stripe.counts())})")


def _restripe(pair: _Pair, offset: float, normalize: bool, stripe_options: dict[str, Any],
              min_stripe: int) -> _Pair:
    """The pair's stripe extracted again with the albedo offset ``offset``; raises PairRejected."""
    try:
        stripe = _stripe_and_background(pair.on, pair.off, normalize,
                                        dict(stripe_options, albedo_offset=offset))[0]
    except ValueError as e:
        raise PairRejected(f"no laser stripe found in {pair.on_name}: {e}") from None
    pair = replace(pair, stripe=stripe)
    _check_stripe(pair, min_stripe)
    return pair


def _stripe_and_background(on_g: np.ndarray, off_g: np.ndarray | None, normalize: bool,
                           stripe_options: dict[str, Any]
                           ) -> tuple[StripeResult, np.ndarray, float | None]:
    """The stripe of a pair, its laser-off frame (estimated when None: see
    :func:`stripe_from_pair`) and the albedo offset fitted to a given laser-off frame (NaN
    when the stripe does not lie on two clearly different levels and 0 was used; None when
    none was fitted: given, no normalisation, or no laser-off frame)."""
    core = frames_options(normalize=normalize, **stripe_options)
    stripe, background, fitted = frames_stripe(on_g, off_g, core, background=off_g is None)
    return stripe, off_g if off_g is not None else background, fitted


def stripe_from_pair(on: np.ndarray, off: np.ndarray | None, *, normalize: bool = True,
                     channel: int | None = None, assess: bool = True,
                     **stripe_options: Any) -> StripeResult:
    """The stripe of one laser on/off pair, as the session pipeline extracts it.

    Difference image (paper Eq. 23; divided by the laser-off frame with ``normalize``, which
    removes most of the pull of the board's edges on the stripe: by ``off + a``, the laser's
    return being an affine function of the laser-off level whose offset ``a`` is fitted to
    the stripe by :func:`~hmlvs.image.stripe.albedo_offset`, or given as ``albedo_offset``;
    0 divides by the laser-off frame itself) and :func:`extract_stripe`
    with ``stripe_options``; for a normalised image without a given threshold, a noise-aware
    one, the peaks found on the image smoothed along the stripe (``detect_sigma_along``,
    default :data:`DETECT_ALONG`); without a given ``method``, Steger's at ``steger_sigma``
    = half the stripe's median FWHM (at least 3 px), robust to laser speckle, and along
    the stripe ``smooth_along`` (default 1; calibration sessions use
    :data:`BOARD_SMOOTH_ALONG`) times that, then refined
    by :func:`~hmlvs.image.stripe.refine_centres` (noise-weighted symmetric centres, on the
    unrounded difference with a denoised laser-off frame; ``method`` "weighted"). With
    ``assess`` the centres are checked by :func:`assess_stripe` (saturation of the laser-on
    frame, clipping, double peaks, and albedo steps of the laser-off frame under the profile
    by more than ``albedo_step``, default 1.5 without ``normalize`` and no check with it).
    ``blur_var`` (px^2, default 0: none): the variance of the camera's blur (optics and the
    pixel's area, about 0.33 for a 0.5 px blur). Dividing by the laser-off frame does not
    undo an albedo step under a blurred profile (the blur of a product is not the product
    of the blurs); to first order in the blur's variance s2 the normalised profile P is
    P_true + s2 grad(P) . grad(log albedo), which is subtracted before the centre fit.
    Measured on noise-free independent renders (0.5 px blur): column error 0.017 -> 0.011
    px RMS, each view's mean error 0.0041 -> 0.0023 px. Calibration sessions fit it
    (:func:`session_blur_var`).
    ``off``
    None: a laser-on image alone, its background estimated (:func:`estimate_background` at a
    stripe width of 16 px, then at the median FWHM of the stripe found against it), the
    peaks taken when 1.5 x brighter than any other (``dominance``, unless given) and centres
    that jump from their neighbours' dropped (MULTIPLE).
    Colour frames use ``channel``, by default the laser's (:func:`laser_channel`); a colour
    laser-on frame alone without a channel goes to :func:`~hmlvs.image.colour.colour_stripe`.

    The whole pipeline runs in C++ (``hmlvs._core``, cpp/hmlvs/image/frames.h), one call
    per frame that releases the GIL, computing the normalised difference, its smoothing and
    the denoised laser-off frame only around the stripe and wherever a pixel could clear a
    threshold; tests/reference_frames.py holds the NumPy composition of the whole-image
    steps it reproduces (tests/test_frames.py compares them).

    Raises ``ValueError`` naming the threshold when an automatic one leaves no pixel of the
    image above it (nothing to find, rather than a silent empty stripe).
    """
    if off is None and channel is None and is_colour(on):
        return colour_stripe(on, None, **stripe_options)
    if channel is None:
        channel = laser_channel(on, off)
    on_g = as_gray(on, "the laser-on image", channel)
    off_g = None if off is None else as_gray(off, "the laser-off image", channel)
    return frames_stripe(on_g, off_g, frames_options(normalize=normalize, assess=assess,
                                                     **stripe_options))[0]


#: the options of :func:`extract_stripe` whose None is the pipeline's choice, not a value
_CHOSEN = ("method", "threshold", "noise", "steger_sigma", "steger_sigma_along")


def frames_options(*, normalize: bool = True, **stripe_options: Any) -> Any:
    """The C++ options of :func:`stripe_from_pair` with ``stripe_options`` (checked: an
    unknown option raises ``TypeError``, a wrong value ``ValueError`` naming it), built once
    for many frames (:class:`hmlvs.Measurer`)."""
    o = dict(stripe_options)
    assess = o.pop("assess", True)
    albedo_step = o.pop("albedo_step", None)
    albedo_offset_ = o.pop("albedo_offset", None)
    blur_var = checked_blur_var(o.pop("blur_var", None))
    along = smooth_along_of(o.pop("smooth_along", None))
    opts = StripeOptions(**{k: v for k, v in o.items() if not (k in _CHOSEN and v is None)
                            and k != "channel"})
    fo = _core._FrameStripeOptions()
    fo.stripe = opts.to_core()
    fo.method_given = o.get("method") is not None
    fo.steger_sigma_given = o.get("steger_sigma") is not None
    fo.steger_sigma_along_given = o.get("steger_sigma_along") is not None
    fo.detect_sigma_along_given = "detect_sigma_along" in o
    fo.dominance_given = "dominance" in o
    fo.normalize = bool(normalize)
    if albedo_offset_ is not None:
        a = real_number(albedo_offset_, "offset")
        if np.isnan(a):
            raise ValueError("offset must be a number or inf, got nan")
        fo.albedo_offset = a
    fo.assess = bool(assess)
    if albedo_step is not None:
        fo.albedo_step = finite_number(albedo_step, "albedo_step")
    fo.blur_var = blur_var
    fo.smooth_along = along
    return fo


def frames_stripe(on_g: np.ndarray, off_g: np.ndarray | None, options: Any,
                  background: bool = False
                  ) -> tuple[StripeResult, np.ndarray | None, float | None]:
    """:func:`stripe_from_pair` of grey frames with the C++ ``options`` of
    :func:`frames_options`: the stripe, the background estimated for a laser-on frame alone
    (with ``background``; else None) and the albedo offset fitted (see
    :func:`_stripe_and_background`)."""
    r, fitted, offset, no_pixel, image_max, refined, bg = _core._stripe_from_frames(
        on_g, off_g, options, bool(background))
    if no_pixel:
        raise ValueError(f"the automatic threshold {r.threshold:.4g} leaves no pixel of the "
                         f"difference image (its maximum is {int(image_max)}): no stripe")
    o = options.stripe
    direction = "columns" if o.direction == _core._StripeDirection.columns else "rows"
    if not options.method_given:
        method = "weighted" if refined else "steger"
    else:
        method = o.method.name
    n = r.centre.shape[0]
    stripe = StripeResult(
        position=np.arange(n), centre=np.asarray(r.centre), intensity=np.asarray(r.intensity),
        width=np.asarray(r.width), sigma=np.asarray(r.sigma),
        status=np.asarray(r.status, dtype=np.uint8), num_peaks=np.asarray(r.num_peaks),
        direction=direction, method=method, threshold=float(r.threshold),
        noise=float(r.noise), residual=np.asarray(r.residual))
    return stripe, bg, (float(offset) if fitted else None)


#: Steger's default smoothing along the stripe, as a multiple of its scale across it, in
#: calibration sessions (:func:`dataset_from_images`), where the stripe lies on the board's
#: plane. Measured on 9 sessions of an independent renderer (16 views each, 10 % laser
#: speckle): centre error 0.059-0.069 px RMS (at most 0.26-0.36 px) at 1, 0.044-0.052 px
#: (at most 0.16-0.25 px) at 2; each view's mean error, which the calibration feels, is
#: unchanged.
BOARD_SMOOTH_ALONG = 2.0

#: The smoothing along the stripe (px) of the image a normalised stripe's peaks are found
#: on (``detect_sigma_along`` of :func:`~hmlvs.image.stripe.extract_stripe`): 2.7x less
#: noise, at most 4 px of a jump's ends blurred together (the C++ pipeline's default).
DETECT_ALONG = float(_core._FrameStripeOptions.detect_along)


def _in_range(value: Any, lo: float, hi: float) -> float | None:
    """``value`` as a float when it is a number in [lo, hi], else None."""
    if isinstance(value, bool):
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) and lo <= v <= hi else None


def checked_blur_var(value: Any) -> float:
    """The ``blur_var`` stripe option, checked (None: 0, no correction at albedo steps)."""
    if value is None:
        return 0.0
    v = _in_range(value, 0.0, MAX_BLUR_VAR)
    if v is None:
        raise ValueError(f"blur_var must lie in [0, {MAX_BLUR_VAR:g}] px^2 (the variance of "
                         f"the camera's blur, for the correction at albedo steps), got "
                         f"{value!r}")
    return v


#: the largest blur variance (px^2) the correction at albedo steps takes or fits: a blur of
#: 2 px (1 sigma); beyond it the first-order correction no longer holds
MAX_BLUR_VAR = 4.0
#: the blur variance (px^2) at which a pair's centre shift per unit variance is measured
_EDGE_REF = 0.5


def edge_shift(pair: _Pair, normalize: bool, stripe_options: dict[str, Any]) -> np.ndarray:
    """Per scan line, how far the pair's stripe centre moves per px^2 of assumed blur
    variance (the correction at albedo steps, :func:`stripe_from_pair` ``blur_var``): the
    centres extracted again at a reference variance, against the pair's. 0 where either
    has no centre, and everywhere without a laser-off frame or normalisation (no
    correction is made there). ``stripe_options`` must be those the pair's stripe was
    extracted with."""
    k = np.zeros(pair.stripe.centre.shape)
    if not normalize or pair.off_name == ESTIMATED_OFF or pair.on is None:
        return k
    base = checked_blur_var(stripe_options.get("blur_var"))
    ref = _stripe_and_background(pair.on, pair.off, normalize,
                                 dict(stripe_options, blur_var=base + _EDGE_REF))[0]
    ok = _centred(pair.stripe) & _centred(ref)
    k[ok] = (ref.centre[ok] - pair.stripe.centre[ok]) / _EDGE_REF
    return k


def _detrend(values: np.ndarray, ok: np.ndarray, scale: float = 15.0) -> np.ndarray:
    """``values`` minus their Gaussian-weighted local mean over the ``ok`` scan lines
    (``scale`` scan lines): what changes faster than a smooth stripe."""
    from scipy.ndimage import gaussian_filter1d

    w = ok.astype(float)
    x = np.where(ok, values, 0.0)
    mean = gaussian_filter1d(x, scale, mode="nearest") / np.maximum(
        gaussian_filter1d(w, scale, mode="nearest"), 1e-12)
    return np.where(ok, values - mean, 0.0)


def session_blur_var(stripes: list[tuple[StripeResult, np.ndarray]]) -> float:
    """The camera's blur variance (px^2) that best removes the bumps albedo steps leave on
    a session's stripes: each (stripe, :func:`edge_shift`) pair's centres, less their
    local mean along the stripe (a smooth curve on the board), regressed on the shift's,
    pooled over the session; clipped to [0, MAX_BLUR_VAR]. 0 when no stripe crosses a
    step. Measured on independent renders with 0.5 px of optical blur (0.33 px^2 with the
    pixel's area): 0.25-0.44; with 1 px (1.08 px^2): 1.12-1.30."""
    num = den = 0.0
    for stripe, k in stripes:
        ok = _centred(stripe) & np.isfinite(k)
        if ok.sum() < 20:
            continue
        r = _detrend(stripe.centre, ok)
        kd = _detrend(k, ok)
        num -= float(np.sum(r * kd))
        den += float(np.sum(kd * kd))
    if not den > 0:
        return 0.0
    return float(np.clip(num / den, 0.0, MAX_BLUR_VAR))


def with_blur_var(stripe: StripeResult, k: np.ndarray, var: float) -> StripeResult:
    """The stripe's centres moved by ``var`` px^2 of blur variance along their shifts ``k``
    (first order; exact at the reference variance)."""
    if var == 0.0 or not np.any(k):
        return stripe
    return replace(stripe, centre=np.where(_centred(stripe), stripe.centre + var * k,
                                           stripe.centre))


def _centred(stripe: StripeResult) -> np.ndarray:
    """The scan lines with a measured centre on the board: found, or flagged ALBEDO_EDGE
    (a centre at a square's edge, corrected like the others but left out of the
    calibration points; the blur fit needs exactly those lines)."""
    return (stripe.found | (stripe.status == StripeStatus.ALBEDO_EDGE)) & \
        np.isfinite(stripe.centre)


def smooth_along_of(value: Any) -> float:
    """The ``smooth_along`` stripe option, checked (None: 1, the same scale as across)."""
    if value is None:
        return 1.0
    v = _in_range(value, 1.0, 10.0)
    if v is None:
        raise ValueError(f"smooth_along must lie in [1, 10] (Steger's scale along the stripe "
                         f"as a multiple of the scale across it), got {value!r}")
    return v


def _manifest_robot(doc: dict[str, Any], robot: Any, source: Any) -> Any:
    """The arm of a manifest: ``robot`` when given; else the manifest's ``robot:``, a built-in
    arm's name or a mapping in the :meth:`hmlvs.Robot.to_dict` form; else None (the default,
    SCORBOT ER-VII)."""
    from ..data.robot_file import robot_from_description

    if robot is not None or doc.get("robot") is None:
        return robot
    return robot_from_description(doc["robot"], str(source))


def _require_poses(records: list[Any], why: str) -> None:
    """Refuse a bench session (records without a robot pose) where poses are needed."""
    if any(isinstance(r, dict) and "pose" not in r and "joints" not in r for r in records):
        raise ValueError(f"the session has no robot poses (a bench session): {why}")


def _record_pose(rec: dict[str, Any], robot: Any, unit: str
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(joints in rad or None, base_from_hand pose in mm) of a record, (None, None) for a
    bench session's record (neither ``pose`` nor ``joints``); raises PairRejected.

    A ``pose`` is a 4x4 matrix (mm) or a mapping ``{position, quaternion | rotation_vector}``
    (see :func:`hmlvs.data.poses.pose_from_entry`; records from a manifest come with their
    ``pose_format`` applied, as 4x4 in mm).
    """
    if "pose" in rec:
        from ..data.poses import PoseFormat, pose_from_entry

        try:
            return None, pose_from_entry(rec["pose"], PoseFormat())
        except ValueError as e:
            raise PairRejected(str(e)) from None
    if "joints" not in rec:
        return None, None  # a bench session's record: no robot pose
    joints = np.asarray(rec["joints"], dtype=float).reshape(-1)
    if joints.shape != (robot.dof,) or not np.all(np.isfinite(joints)):
        raise PairRejected(f"joint readings must be {robot.dof} finite numbers, got "
                      f"{np.asarray(rec['joints']).tolist()}")
    if unit == "deg":
        joints = np.radians(joints)
    return joints, robot.poses(joints[None])[0]


@dataclass(frozen=True)
class StripeList:
    """Stripe pixels given as a list (a manifest's ``stripe`` CSV) instead of an image."""

    pixels: np.ndarray
    intensity: np.ndarray


def _counts_text(counts: dict[str, int]) -> str:
    return ", ".join(f"{k.lower()} {v}" for k, v in counts.items() if v)



def _core_options(stripe_options: dict[str, Any]) -> dict[str, Any]:
    """The options of :func:`extract_stripe` among the pipeline's stripe options."""
    return {k: v for k, v in stripe_options.items()
            if k not in ("albedo_step", "albedo_offset", "smooth_along", "blur_var")}
