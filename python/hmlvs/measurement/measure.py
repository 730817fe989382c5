"""Measurement with a calibrated sensor: stripe pixels + poses -> 3D points -> point clouds."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._arrays import as_matrix
from .._io import atomic_write
from ..data.calibration_file import Calibration
from ..geometry.robot import Robot
from ..models.base import SensorModel
from ..models.paper import PaperSensor
from ..models.params import Parameters


@dataclass(frozen=True)
class PointCloud:
    """Measured points (mm) in the robot base frame, or in the camera frame.

    Attributes
    ----------
    points : (n, 3) points in ``frame``; NaN rows where ``valid`` is False
    valid : (n,) whether the stripe pixel's ray met the laser plane
    pixels : (n, 2) the stripe pixels measured
    pose_index : (n,) the pose (image) each point was measured at
    intensity : (n,) stripe intensity per point (0 when unknown)
    frame : "base" (the robot base frame) or "camera" (the camera frame: each image's profile
        where the sensor saw it, no robot pose applied)
    """

    points: np.ndarray
    valid: np.ndarray
    pixels: np.ndarray
    pose_index: np.ndarray
    intensity: np.ndarray
    frame: str = "base"

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def num_valid(self) -> int:
        return int(self.valid.sum())

    def valid_points(self) -> np.ndarray:
        return self.points[self.valid]

    def concat(self, other: "PointCloud") -> "PointCloud":
        if other.frame != self.frame:
            raise ValueError(f"cannot join a cloud in the {self.frame} frame and one in the "
                             f"{other.frame} frame")
        offset = int(self.pose_index.max()) + 1 if len(self) else 0
        return PointCloud(np.vstack([self.points, other.points]),
                          np.concatenate([self.valid, other.valid]),
                          np.vstack([self.pixels, other.pixels]),
                          np.concatenate([self.pose_index, other.pose_index + offset]),
                          np.concatenate([self.intensity, other.intensity]), self.frame)

    def save(self, path: str | os.PathLike, only_valid: bool = True) -> Path:
        """Write atomically as binary PLY (``.ply``) or CSV (``.csv``) by the suffix."""
        with CloudWriter(path) as w:
            w.add(self, only_valid)
        return Path(path)

    def save_ply(self, path: str | os.PathLike, only_valid: bool = True) -> Path:
        """Binary little-endian PLY: x, y, z (double, mm), intensity (float), pose_index (int)."""
        with CloudWriter(path, "ply") as w:
            w.add(self, only_valid)
        return Path(path)

    def save_csv(self, path: str | os.PathLike, only_valid: bool = True) -> Path:
        """CSV with a header: x_mm, y_mm, z_mm, intensity, pose_index, u_px, v_px."""
        with CloudWriter(path, "csv") as w:
            w.add(self, only_valid)
        return Path(path)


FRAMES = ("base", "camera")
_FRAME_NAMES = {None: "robot base frame", "base": "robot base frame", "camera": "camera frame"}
_PLY_RECORD = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", "<f4"),
                        ("pose_index", "<i4")])


class CloudWriter:
    """A point cloud file written piece by piece (:meth:`add`), then atomically as a whole
    when the ``with`` block ends without an error (nothing is written otherwise): binary PLY
    (``kind="ply"``) or CSV. The points go to an anonymous temporary file (gone with the
    process, whatever stops it) until then, so memory holds one piece at a time."""

    def __init__(self, path: str | os.PathLike, kind: str | None = None) -> None:
        self.path = Path(path)
        self.kind = kind or self.path.suffix.lstrip(".")
        if self.kind not in ("ply", "csv"):
            raise ValueError(f"{self.path}: point clouds are written as .ply or .csv")
        self.count = 0
        self.frame: str | None = None  # that of the clouds added
        self._body: Any = None

    def __enter__(self) -> "CloudWriter":
        import tempfile

        self._body = tempfile.TemporaryFile()
        return self

    def add(self, cloud: "PointCloud", only_valid: bool = True) -> None:
        if self.frame not in (None, cloud.frame):
            raise ValueError(f"{self.path}: a cloud in the {cloud.frame} frame cannot join "
                             f"points in the {self.frame} frame")
        self.frame = cloud.frame
        keep = cloud.valid if only_valid else np.ones(len(cloud), bool)
        if self.kind == "ply":
            rec = np.empty(int(keep.sum()), dtype=_PLY_RECORD)
            rec["x"], rec["y"], rec["z"] = cloud.points[keep].T
            rec["intensity"] = cloud.intensity[keep]
            rec["pose_index"] = cloud.pose_index[keep]
            self._body.write(rec.tobytes())
        else:
            self._body.write("".join(
                f"{p[0]:.6f},{p[1]:.6f},{p[2]:.6f},{i:.6g},{int(k)},{px[0]:.4f},{px[1]:.4f}\n"
                for p, i, k, px in zip(cloud.points[keep], cloud.intensity[keep],
                                       cloud.pose_index[keep], cloud.pixels[keep])
            ).encode("ascii"))
        self.count += int(keep.sum())

    def __exit__(self, kind: Any, value: Any, tb: Any) -> None:
        import shutil

        body, self._body = self._body, None
        try:
            if kind is not None:
                return
            body.seek(0)
            with atomic_write(self.path, "wb") as fh:
                if self.kind == "ply":
                    fh.write(("ply\nformat binary_little_endian 1.0\n"
                              f"comment hmlvs point cloud, {_FRAME_NAMES[self.frame]}, "
                              "units mm\n"
                              f"element vertex {self.count}\nproperty double x\n"
                              "property double y\nproperty double z\n"
                              "property float intensity\nproperty int pose_index\n"
                              "end_header\n").encode("ascii"))
                else:
                    fh.write(b"x_mm,y_mm,z_mm,intensity,pose_index,u_px,v_px\n")
                shutil.copyfileobj(body, fh, 1 << 20)
        finally:
            body.close()


def read_ply(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a binary little-endian PLY written by :meth:`PointCloud.save_ply`."""
    path = Path(path)
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise ValueError(f"{path}: not a PLY file")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise ValueError(f"{path}: only binary little-endian PLY is read")
    types = {"double": "<f8", "float": "<f4", "int": "<i4", "uchar": "u1"}
    n, fields = 0, []
    for line in header:
        parts = line.split()
        if parts[:2] == ["element", "vertex"]:
            n = int(parts[2])
        elif parts and parts[0] == "property":
            fields.append((parts[2], types[parts[1]]))
    rec = np.frombuffer(data[end + len(b"end_header\n"):], dtype=fields, count=n)
    return {name: rec[name].copy() for name, _ in fields}


def require_hand_eye(calibration: Any) -> None:
    """Refuse to measure in the base frame with a bench session's calibration (camera mode:
    the camera and laser plane only, its hand_from_camera not calibrated)."""
    method = getattr(calibration, "method", None) or ""
    if getattr(calibration, "mode", None) == "camera" or str(method).endswith("(camera)"):
        raise ValueError("this calibration is a bench session's (camera mode): it holds the "
                         "camera and laser plane but no hand-eye transform; measure in the "
                         "camera frame (hmlvs measure --frame camera), or calibrate the "
                         "hand-eye with a robot session first (hmlvs calibrate ROBOT_SESSION "
                         "--initial THIS_FILE)")


def checked_frame(frame: Any) -> str:
    """``frame`` if it names a frame points are measured in ("base" or "camera")."""
    if frame not in FRAMES:
        raise ValueError(f"frame must be 'base' (the robot base frame) or 'camera' (the "
                         f"camera frame, without robot poses), got {frame!r}")
    return str(frame)


def sensor_model(calibration: Any) -> SensorModel:
    """The :class:`~hmlvs.models.base.SensorModel` of a calibration of either model: a
    :class:`Calibration`, a calibration result, :class:`Parameters`, an :class:`OpenCvSensor`
    or the path of a calibration file."""
    if isinstance(calibration, (str, os.PathLike)):
        calibration = Calibration.load(calibration)
    if isinstance(calibration, SensorModel):
        return calibration
    sensor = getattr(calibration, "sensor", None)
    if isinstance(sensor, SensorModel):
        return sensor  # an opencv-model Calibration or JointCalibration
    if isinstance(calibration, Parameters):
        return PaperSensor(calibration)
    params = getattr(calibration, "params", None)
    if isinstance(params, Parameters):
        return PaperSensor(params)  # a paper Calibration or CalibrationResult
    raise ValueError("calibration must be a Calibration, a calibration result, Parameters, an "
                     "OpenCvSensor or the path of a calibration file")


def measure(calibration: Calibration | Parameters | SensorModel,
            stripes: Sequence[Any] | np.ndarray, poses: np.ndarray | None = None, *,
            joints: np.ndarray | None = None, robot: Robot | None = None, degrees: bool = False,
            on_invalid: str = "mask", stripe_options: dict[str, Any] | None = None,
            frame: str = "base") -> PointCloud:
    """Stripe pixels seen at hand poses -> a point cloud in the robot base frame (or, with
    ``frame="camera"`` and no poses, each stripe's profile in the camera frame).

    Parameters
    ----------
    calibration : a :class:`Calibration` of either model (:func:`hmlvs.calibrate`'s, or a
        file's), its path, or a solver's result, :class:`Parameters` or a sensor model
    stripes : one entry per pose: an (k, 2) array of stripe pixels (u, v), an object with
        ``pixels`` (and optionally ``intensity``) such as :class:`hmlvs.image.StripeResult`,
        or a tuple ``(laser_on, laser_off)`` of images whose stripe is extracted as the
        session pipeline does (:func:`hmlvs.image.stripe_from_pair` with ``stripe_options``)
    poses : (n_poses, 4, 4) base_from_hand poses, or
    joints : (n_poses, dof) joint readings, with ``robot`` (default: the calibration's robot,
        else SCORBOT ER-VII); ``degrees`` for readings in degrees
    on_invalid : "mask" keeps rays that miss the laser plane as invalid points; "raise" raises
    frame : "base" (needs the poses, and a calibration with its hand-eye transform) or
        "camera": the points in the camera frame, without poses; what a bench session's
        calibration (camera and laser plane, no hand-eye) measures

    Returns
    -------
    PointCloud
    """
    if isinstance(calibration, (str, os.PathLike)):
        calibration = Calibration.load(calibration)
    frame = checked_frame(frame)
    if frame == "base":
        require_hand_eye(calibration)
    model = sensor_model(calibration)
    stripes = list(stripes) if not isinstance(stripes, np.ndarray) or stripes.ndim != 2 \
        else [stripes]
    if frame == "camera":
        if poses is not None or joints is not None:
            raise ValueError("frame='camera' measures without robot poses: give no poses or "
                             "joints (or frame='base')")
    elif (poses is None) == (joints is None):
        raise ValueError("give either poses or joints (with a robot), not both or neither")
    elif poses is None:
        if robot is None:
            robot = getattr(calibration, "robot", None) or Robot.scorbot_er7()
        poses = robot.poses(joints, degrees=degrees)
    poses = np.full((len(stripes), 4, 4), np.nan) if frame == "camera" else \
        np.asarray(poses, dtype=float)
    if poses.ndim == 2:
        poses = poses[None]
    if poses.shape[0] != len(stripes):
        raise ValueError(f"{len(stripes)} stripes but {poses.shape[0]} poses: give one pose per "
                         "stripe (image)")
    px_all, pose_idx, inten = [], [], []
    for k, s in enumerate(stripes):
        if isinstance(s, tuple) and len(s) == 2 and all(np.ndim(x) >= 2 for x in s):
            from ..image.session import stripe_from_pair

            s = stripe_from_pair(s[0], s[1], **(stripe_options or {}))
        px = s.pixels if hasattr(s, "pixels") else s
        px = as_matrix(px, 2, f"stripe {k} pixels") if np.size(px) else np.empty((0, 2))
        it = getattr(s, "intensity", None)
        if it is not None and hasattr(s, "pixels"):
            found = getattr(s, "found", None)
            it = np.asarray(it, float)
            if found is not None and it.shape[0] != px.shape[0]:
                it = it[np.asarray(found, bool)]
        it = np.zeros(px.shape[0]) if it is None or np.shape(it)[0] != px.shape[0] else it
        px_all.append(px)
        pose_idx.append(np.full(px.shape[0], k, dtype=np.int32))
        inten.append(np.asarray(it, float))
    pixels = np.vstack(px_all) if px_all else np.empty((0, 2))
    pidx = np.concatenate(pose_idx) if pose_idx else np.empty(0, np.int32)
    if pixels.shape[0] == 0:
        raise ValueError("no stripe pixels to measure")
    if frame == "camera":
        pts, valid = model.points_in_camera(pixels, on_invalid=on_invalid)
    else:
        pts, valid = model.points_in_base(pixels, poses[pidx], on_invalid=on_invalid)
    return PointCloud(pts, valid, pixels, pidx, np.concatenate(inten), frame)


def measure_source(calibration: Any, source: str | os.PathLike) -> tuple[PointCloud, dict]:
    """Measure every stripe of a data set file (.npz/.json) or an image manifest.

    Returns the cloud and a summary; for a data set with reference points the summary holds
    the RMS distance between measured and reference points (``rms_mm``); for images, the
    :meth:`MeasureResult.summary` dict (this shape is kept for the command line).
    """
    from ..data.dataset import Dataset

    path = Path(source)
    if path.suffix in (".npz", ".json") and path.is_file() and path.name != "manifest.json":
        ds = Dataset.load(path)
        cloud = measure(calibration, [ds.pixels[i:i + 1] for i in range(len(ds))], ds.poses)
        err = np.linalg.norm(cloud.points - ds.points, axis=1)[cloud.valid]
        return cloud, {"rms_mm": float(np.sqrt(np.mean(err**2))) if err.size else None}
    result = measure_images(calibration, path)
    return result.cloud, result.summary()


@dataclass(frozen=True)
class RejectedPair:
    """An image pair that gave no stripe: its id in the manifest and why."""

    id: str
    reason: str


@dataclass(frozen=True)
class MeasureResult:
    """The outcome of :func:`measure_images`.

    cloud : the measured points; images : pairs in the source; used : pairs that gave a
    stripe; ids : the used pairs' ids; rejected : the pairs skipped, with the reason
    """

    cloud: PointCloud
    images: int
    used: int
    ids: list[str]
    rejected: tuple[RejectedPair, ...] = ()

    @property
    def rejected_reasons(self) -> dict[str, str]:
        """id -> reason of each rejected pair."""
        return {r.id: r.reason for r in self.rejected}

    def summary(self) -> dict[str, Any]:
        """The old summary dict: images, used, rejected (id -> reason) and ids."""
        return {"images": self.images, "used": self.used, "rejected": self.rejected_reasons,
                "ids": list(self.ids)}


def _calibration_robot(calibration: Any, source: Any) -> Robot | None:
    """The calibration's robot, unless the manifest names another arm (by a name that is not
    the calibration robot's, or by a DH mapping): the manifest says which arm took the images."""
    robot = getattr(calibration, "robot", None)
    if robot is None or isinstance(source, (list, tuple)):
        return robot
    from ..data.manifest import read_manifest

    declared = read_manifest(source)[1].get("robot")
    return robot if declared is None or declared == robot.name else None


def _prepared(calibration: Any, source: Any, robot: Robot | None, options: dict[str, Any]
              ) -> tuple[Any, Robot | None, dict[str, Any]]:
    """The calibration (loaded), the robot and the stripe options for measuring ``source``:
    the calibration's camera blur and image size unless given."""
    if robot is None:
        robot = _calibration_robot(calibration, source)
    cal_name = None
    if isinstance(calibration, (str, os.PathLike)):
        cal_name = str(calibration)
        calibration = Calibration.load(calibration)
    options = dict(options)
    if options.get("blur_var") is None and getattr(calibration, "blur_var", None) is not None:
        options["blur_var"] = calibration.blur_var
    sensor = getattr(calibration, "sensor", None)
    size = getattr(sensor, "image_size", None) or getattr(calibration, "image_size", None)
    if size is not None and options.get("image_size") is None:
        # an opencv calibration's sensor, a paper calibration from images, an OpenCvSensor
        options["image_size"] = tuple(size)
        options.setdefault("image_size_of", f"the calibration {cal_name}" if cal_name
                           else "the calibration")
    return calibration, robot, options


@dataclass(frozen=True)
class StreamedMeasure:
    """What :func:`measure_images_to` wrote: the file, its points, the stripe pixels
    without a measurement, the pairs read and used (their ids) and those rejected."""

    path: Path
    points: int
    invalid: int
    images: int
    ids: list[str]
    rejected: tuple[RejectedPair, ...] = ()

    def summary(self) -> dict[str, Any]:
        """As :meth:`MeasureResult.summary`: images, used, rejected (id -> reason), ids."""
        return {"images": self.images, "used": len(self.ids),
                "rejected": {r.id: r.reason for r in self.rejected}, "ids": list(self.ids)}


def measure_images_to(calibration: Any, source: Any, out: str | os.PathLike, *,
                      robot: Robot | None = None, progress: Any = None, frame: str = "base",
                      **options: Any) -> StreamedMeasure:
    """:func:`measure_images` written to the point cloud ``out`` (.ply or .csv) as the frames
    are read: one frame in memory at a time, whatever the scan's length; ``out`` appears
    whole, or not at all when the run fails. ``progress``: a callable (done, total) after
    each frame."""
    from ..data.manifest import read_manifest
    from ..image.scan import iter_stripes_from_images

    frame = checked_frame(frame)
    calibration, robot, options = _prepared(calibration, source, robot, options)
    if frame == "base":
        require_hand_eye(calibration)
    pairs = iter_stripes_from_images(source, robot=robot, frame=frame,
                                     **options)  # checks the session
    total = len(source) if isinstance(source, (list, tuple)) else len(read_manifest(source)[0])
    model = sensor_model(calibration)
    ids: list[str] = []
    rejected: list[RejectedPair] = []
    points = invalid = images = 0
    with CloudWriter(out) as writer:
        for report, item, pose in pairs:
            images += 1
            if item is None:
                rejected.append(RejectedPair(str(report.id), str(report.reason)))
            else:
                cloud = measure(model, [item], None if frame == "camera" else pose[None],
                                frame=frame)
                writer.add(dataclasses.replace(
                    cloud, pose_index=np.full(len(cloud), report.index, np.int32)))
                ids.append(str(report.id))
                points += cloud.num_valid
                invalid += len(cloud) - cloud.num_valid
            if progress is not None:
                progress(images, total)
        if not ids:
            raise ValueError("no image pair gave a stripe: " +
                             "; ".join(f"{r.id}: {r.reason}" for r in rejected))
        if points == 0:
            raise ValueError(f"none of the {invalid} stripe pixels' rays meets the calibration's "
                             "laser plane: nothing to write (is this calibration of the sensor "
                             "that took these images?)")
    return StreamedMeasure(Path(out), points, invalid, images, ids, tuple(rejected))


def measure_images(calibration: Any, source: Any, *, robot: Robot | None = None,
                   frame: str = "base", **options: Any) -> MeasureResult:
    """Laser on/off image pairs + joint readings (an image manifest, see docs/file-formats.md,
    or a list of records) -> a point cloud, one stripe profile per pair: in the robot base
    frame, or with ``frame="camera"`` in the camera frame (no robot poses needed).

    Pairs that fail (no stripe, bad image, mismatched pair) are skipped and named in the
    result's ``rejected``; ``options`` go to :func:`hmlvs.image.scan.stripes_from_images`.
    Without a ``blur_var`` option, that of the calibration (the camera blur its image session
    fitted, :attr:`hmlvs.Calibration.blur_var`) corrects the stripes at albedo steps.

    Returns
    -------
    MeasureResult
    """
    from ..image.scan import stripes_from_images

    frame = checked_frame(frame)
    calibration, robot, options = _prepared(calibration, source, robot, options)
    if frame == "base":
        require_hand_eye(calibration)
    ids, stripes, poses, reports = stripes_from_images(source, robot=robot, frame=frame,
                                                       **options)
    rejected = tuple(RejectedPair(str(r.id), str(r.reason)) for r in reports if not r.ok)
    if not stripes:
        raise ValueError("no image pair gave a stripe: " +
                         "; ".join(f"{r.id}: {r.reason}" for r in rejected))
    cloud = measure(calibration, stripes, None if frame == "camera" else poses, frame=frame)
    # pose_index: the pair's index in the manifest, whatever pairs were skipped before it
    used = np.array([r.index for r in reports if r.ok], dtype=np.int32)
    cloud = dataclasses.replace(cloud, pose_index=used[cloud.pose_index])
    return MeasureResult(cloud=cloud, images=len(reports), used=len(stripes), ids=list(ids),
                         rejected=rejected)
