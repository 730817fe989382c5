"""A scan of laser on/off images (or stripe lists) with their robot poses -> stripes, one
frame at a time: the reading side of measuring from images (:mod:`hmlvs.measurement`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .accounts import ImageReport
from .frames import checked_blur_var
from .session import (
    PairRejected,
    core_options,
    manifest_direction,
    manifest_robot,
    read_pair,
    read_session_manifest,
    record_id,
    record_names,
    record_pose,
    require_poses,
)
from .stripe import extract_stripe


def iter_stripes_from_images(source: Any, *, robot: Any = None,
                             joint_unit: str | None = None, channel: int | None = None,
                             normalize: bool = True, min_stripe: int = 20,
                             image_size: tuple[int, int] | None = None,
                             image_size_of: str = "the calibration", frame: str = "base",
                             **stripe_options: Any
                             ) -> Iterator[tuple[ImageReport, Any, np.ndarray | None]]:
    """Laser on/off pairs + joint readings (a manifest or a list of records) -> stripes.

    The measurement counterpart of
    :func:`~hmlvs.image.paper_session.dataset_from_images` (no checkerboard needed): for
    each pair the same checks, difference image and stripe extraction. A pair that fails is
    reported and skipped. Entries may give a stripe list (``stripe``: CSV of u, v[, intensity])
    instead of an image pair, and a ``pose`` instead of joint readings. Returns (ids, stripes,
    base_from_hand poses (n, 4, 4), reports). With ``image_size`` (width, height: that of
    ``image_size_of``, the calibration) images of another size are refused, a ValueError
    naming both sizes: a calibration holds for one camera at one resolution. With
    ``frame="camera"`` (points measured in the camera frame) a session without robot poses
    (a bench session) is read too; each pair's pose is then None.

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
        robot = manifest_robot(doc, robot, source)
        stripe_options = manifest_direction(doc, stripe_options)
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
    if frame not in ("base", "camera"):
        raise ValueError(f"frame must be 'base' or 'camera', got {frame!r}")
    if frame == "base":
        require_poses(records, "measuring in the robot's base frame needs the robot pose of "
                      "every frame (measure in the camera frame without them: hmlvs measure "
                      "--frame camera)")
    robot = Robot.scorbot_er7() if robot is None else robot
    # option typos fail here
    extract_stripe(np.zeros((4, 4), np.uint8), **core_options(stripe_options))
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
                _, pose = record_pose(rec, robot, unit)
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
    base_from_hand poses (n, 4, 4), NaN for a pair without one, reports) of the pairs that
    gave a stripe, and every pair's report."""
    ids, stripes, poses, reports = [], [], [], []
    for report, item, pose in iter_stripes_from_images(source, **options):
        reports.append(report)
        if item is not None:
            ids.append(report.id)
            stripes.append(item)
            poses.append(np.full((4, 4), np.nan) if pose is None else pose)
    return ids, stripes, np.array(poses).reshape(-1, 4, 4), reports


@dataclass(frozen=True)
class StripeList:
    """Stripe pixels given as a list (a manifest's ``stripe`` CSV) instead of an image."""

    pixels: np.ndarray
    intensity: np.ndarray


