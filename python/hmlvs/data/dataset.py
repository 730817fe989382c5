"""Calibration data: stripe pixels, hand poses and reference points, with validation and I/O."""

from __future__ import annotations

from dataclasses import dataclass, field
import json
import math
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._arrays import as_matrix, same_rows
from .._io import atomic_write, existing_file, parse_text
from ..models.paper import validate_poses

FORMAT = "hmlvs-dataset"
FORMAT_VERSION = 1
_LENGTH_SCALE = {"mm": 1.0, "m": 1000.0}
#: The per-point stripe quality a data set from images carries (:attr:`Dataset.quality`).
QUALITY_FIELDS = ("sigma", "width", "peak", "residual")
_ANGLE_UNITS = ("rad", "deg")


@dataclass(frozen=True)
class Dataset:
    """m calibration points: stripe pixel, hand pose and reference point of each.

    Attributes
    ----------
    pixels : (m, 2) stripe pixels (u = column, v = row), px
    poses : (m, 4, 4) base_from_hand transforms, mm
    points : (m, 3) reference points in the robot base frame, mm
    ids : (m,) point identifiers (strings), unique
    joints : (m, n) joint readings the poses came from, or None
    joint_unit : "rad" or "deg"
    pose_index : (m,) index of the image/pose each point was seen in, or None
    quality : the stripe's quality at each point, or None: a dict of (m,) arrays named by
        :data:`QUALITY_FIELDS`, some or all of ``sigma`` (1-sigma uncertainty of the centre
        from the pixel noise, px), ``width`` (the profile's FWHM, px), ``peak`` (its peak on
        the stripe's difference image) and ``residual`` (the profile's asymmetry about its
        centre, relative to the peak; 0 when symmetric), as
        :class:`~hmlvs.image.stripe.StripeResult` gives them for the scan line of the point.
        Data sets from images have them (every point is a ``FOUND`` scan line); a
        calibration can drop points by them, e.g.
        ``ds.subset(ds.quality["residual"] < 0.05)``.

    Lengths given in metres (``length_unit="m"``) are converted to mm on construction.
    """

    pixels: np.ndarray
    poses: np.ndarray
    points: np.ndarray
    ids: np.ndarray | None = None
    joints: np.ndarray | None = None
    joint_unit: str = "rad"
    pose_index: np.ndarray | None = None
    length_unit: str = "mm"
    meta: dict[str, Any] = field(default_factory=dict)
    quality: dict[str, np.ndarray] | None = None

    def __post_init__(self) -> None:
        if self.length_unit not in _LENGTH_SCALE:
            raise ValueError(f"length_unit must be 'mm' or 'm', got {self.length_unit!r}")
        scale = _LENGTH_SCALE[self.length_unit]
        px = as_matrix(self.pixels, 2, "pixels").copy()
        pts = as_matrix(self.points, 3, "reference points") * scale
        poses = np.asarray(self.poses, dtype=float)
        if poses.ndim != 3 or poses.shape[1:] != (4, 4):
            raise ValueError(f"poses must have shape (m, 4, 4), got {poses.shape}")
        poses = np.ascontiguousarray(poses).copy()
        poses[:, :3, 3] *= scale
        m = same_rows(pixels=px, poses=poses, points=pts)
        validate_poses(poses)
        if m > 0:
            self._check_units(poses, pts)
        ids = np.arange(m).astype(str) if self.ids is None else np.asarray(self.ids).astype(str)
        if ids.shape != (m,):
            raise ValueError(f"ids must have {m} entries, got shape {ids.shape}")
        uniq, counts = np.unique(ids, return_counts=True)
        if np.any(counts > 1):
            raise ValueError(f"ids must be unique; {str(uniq[counts > 1][0])!r} appears "
                             f"{counts[counts > 1][0]} times")
        joints = None
        if self.joints is not None:
            joints = np.asarray(self.joints, dtype=float)
            if joints.ndim != 2 or joints.shape[0] != m:
                raise ValueError(f"joints must have shape ({m}, n), got {joints.shape}")
            if not np.all(np.isfinite(joints)):
                raise ValueError(f"joint readings row {int(np.argmin(np.isfinite(joints).all(1)))}"
                                 " is not finite")
            if self.joint_unit not in _ANGLE_UNITS:
                raise ValueError(f"joint_unit must be 'rad' or 'deg', got {self.joint_unit!r}")
            if self.joint_unit == "rad" and np.abs(joints).max(initial=0) > 4 * math.pi:
                raise ValueError("joint readings exceed 4 pi rad: they look like degrees; pass "
                                 "joint_unit='deg'")
        pose_index = None
        if self.pose_index is not None:
            pose_index = np.asarray(self.pose_index)
            if pose_index.shape != (m,) or not np.issubdtype(pose_index.dtype, np.integer):
                raise ValueError(f"pose_index must be {m} integers, got {pose_index.shape} "
                                 f"{pose_index.dtype}")
        quality = _check_quality(self.quality, m)
        for name, value in (("pixels", px), ("poses", poses), ("points", pts), ("ids", ids),
                            ("joints", joints), ("pose_index", pose_index),
                            ("quality", quality)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "length_unit", "mm")

    @staticmethod
    def _check_units(poses: np.ndarray, pts: np.ndarray) -> None:
        # Reference points and the hand positions reaching them must share a length unit: a
        # point far beyond the arm's reach by a factor of ~1000 (or vice versa) is a unit slip.
        reach = float(np.median(np.linalg.norm(poses[:, :3, 3], axis=1)))
        size = float(np.median(np.linalg.norm(pts, axis=1)))
        if reach > 10.0 and size > 0.0 and not 1e-2 < size / reach < 1e2:
            raise ValueError(
                f"reference points and pose positions do not share a length unit (median "
                f"distance from the base: points {size:.3g}, hand {reach:.3g}); both must be "
                "in mm (or pass length_unit='m' for metres)")

    # ------------------------------------------------------------------ views and splits
    def __len__(self) -> int:
        return int(self.pixels.shape[0])

    @property
    def num_poses(self) -> int:
        if self.pose_index is not None:
            return int(np.unique(self.pose_index).size)
        return int(np.unique(self.poses.reshape(len(self), -1), axis=0).shape[0])

    def subset(self, indices: Sequence[int] | np.ndarray) -> "Dataset":
        idx = np.asarray(indices)
        if idx.dtype == bool:
            if idx.shape != (len(self),):
                raise ValueError(f"a boolean subset mask needs {len(self)} entries, got "
                                 f"{idx.size}")
            idx = np.nonzero(idx)[0]
        if idx.size == 0:
            raise ValueError("the subset is empty: a data set needs at least one point")
        if not np.issubdtype(idx.dtype, np.integer):
            raise ValueError(f"subset indices must be whole numbers, got {idx.dtype}")
        if idx.size and (idx.min() < -len(self) or idx.max() >= len(self)):
            raise ValueError(f"subset index out of range for a data set of {len(self)} points")
        return self._rows(idx, self.ids[idx])

    def _rows(self, idx: np.ndarray, ids: np.ndarray) -> "Dataset":
        """The points at indices ``idx`` (every per-point field), named ``ids``."""
        return Dataset(
            self.pixels[idx], self.poses[idx], self.points[idx], ids=ids,
            joints=None if self.joints is None else self.joints[idx], joint_unit=self.joint_unit,
            pose_index=None if self.pose_index is None else self.pose_index[idx],
            meta=dict(self.meta),
            quality=None if self.quality is None else
            {k: v[idx] for k, v in self.quality.items()})

    def split(self, fit: float | int = 0.5, seed: int | None = None,
              by_pose: bool = False) -> tuple["Dataset", "Dataset"]:
        """Split into (fit, test) sets.

        ``fit`` is a fraction (0-1) or a number of points. Without ``seed`` the first points
        are the fit set (the paper's protocol: first 50 of 100); with a seed the split is a
        seeded random permutation. ``by_pose`` keeps all points of one pose on one side.
        """
        m = len(self)
        if by_pose and self.pose_index is not None:
            groups = np.unique(self.pose_index)
            if seed is not None:
                groups = np.random.default_rng(seed).permutation(groups)
            n_fit = _split_count(fit, groups.size, "poses")
            mask = np.isin(self.pose_index, groups[:n_fit])
            return self.subset(np.nonzero(mask)[0]), self.subset(np.nonzero(~mask)[0])
        order = np.arange(m) if seed is None else np.random.default_rng(seed).permutation(m)
        n_fit = _split_count(fit, m, "points")
        return self.subset(np.sort(order[:n_fit])), self.subset(np.sort(order[n_fit:]))

    def concat(self, other: "Dataset") -> "Dataset":
        joints = None
        if self.joints is not None and other.joints is not None:
            joints = np.vstack([self.joints, other.joints])
        quality = None
        if self.quality is not None and other.quality is not None:
            quality = {k: np.concatenate([v, other.quality[k]])
                       for k, v in self.quality.items() if k in other.quality} or None
        return Dataset(np.vstack([self.pixels, other.pixels]),
                       np.concatenate([self.poses, other.poses]),
                       np.vstack([self.points, other.points]),
                       ids=np.concatenate([self.ids, other.ids]), joints=joints,
                       joint_unit=self.joint_unit, meta=dict(self.meta), quality=quality)

    def summary(self) -> str:
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        lines = [
            f"{len(self)} points from {self.num_poses} poses",
            "reference points (mm): " + ", ".join(
                f"{a} {lo[i]:.1f}..{hi[i]:.1f} (extent {hi[i] - lo[i]:.1f})"
                for i, a in enumerate("xyz")),
            f"stripe pixels: u {self.pixels[:, 0].min():.1f}..{self.pixels[:, 0].max():.1f}, "
            f"v {self.pixels[:, 1].min():.1f}..{self.pixels[:, 1].max():.1f}",
        ]
        if self.joints is not None:
            lines.append(f"joint readings: {self.joints.shape[1]} joints ({self.joint_unit})")
        return "\n".join(lines)

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write the data set atomically as ``.npz`` or ``.json`` (by the suffix)."""
        path = Path(path)
        if path.suffix == ".npz":
            arrays = {"pixels": self.pixels, "poses": self.poses, "points": self.points,
                      "ids": self.ids.astype(str),
                      "header": np.array(json.dumps(self._header()))}
            if self.joints is not None:
                arrays["joints"] = self.joints
            if self.pose_index is not None:
                arrays["pose_index"] = self.pose_index
            for k, v in (self.quality or {}).items():
                arrays[f"quality_{k}"] = v
            with atomic_write(path, "wb") as fh:
                np.savez_compressed(fh, **arrays)
        elif path.suffix == ".json":
            with atomic_write(path, "w") as fh:
                json.dump(self.to_json_dict(), fh, indent=1)
        else:
            raise ValueError(f"{path}: data sets are saved as .npz or .json, not "
                             f"{path.suffix or 'a file without a suffix'}")
        return path

    def _header(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": FORMAT_VERSION, "length_unit": "mm",
                "joint_unit": self.joint_unit, "meta": self.meta}

    def to_json_dict(self) -> dict[str, Any]:
        d = self._header()
        d["points"] = []
        for i in range(len(self)):
            e: dict[str, Any] = {"id": str(self.ids[i]), "pixel": self.pixels[i].tolist(),
                                 "reference": self.points[i].tolist(),
                                 "base_from_hand": self.poses[i].tolist()}
            if self.joints is not None:
                e["joints"] = self.joints[i].tolist()
            if self.pose_index is not None:
                e["pose_index"] = int(self.pose_index[i])
            if self.quality:
                # NaN (no value) as null: JSON has no NaN
                e["quality"] = {k: (float(v[i]) if np.isfinite(v[i]) else None)
                                for k, v in self.quality.items()}
            d["points"].append(e)
        return d

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Dataset":
        """Read a data set written by :meth:`save` (``.npz`` or ``.json``)."""
        from .schema import validate

        path = existing_file(path, "data set file")
        try:
            if path.suffix == ".npz":
                with np.load(path, allow_pickle=False) as z:
                    arrays = {k: z[k] for k in z.files}
                validate(arrays, _npz_schema(), str(path))
                # the header is JSON text: nested at most MAX_DEPTH deep, as every document
                header = parse_text(str(arrays["header"]), True, path, "data set header")
                _check_header(header, path)
                validate(header, _header_schema(), str(path), "header")
                return cls(arrays["pixels"], arrays["poses"], arrays["points"],
                           ids=arrays["ids"], joints=arrays.get("joints"),
                           joint_unit=header.get("joint_unit", "rad"),
                           pose_index=arrays.get("pose_index"),
                           length_unit=header.get("length_unit", "mm"),
                           meta=header.get("meta", {}),
                           quality={k: arrays[f"quality_{k}"] for k in QUALITY_FIELDS
                                    if f"quality_{k}" in arrays} or None)
            if path.suffix == ".json":
                d = parse_text(path.read_text(encoding="utf-8"), True, path, "data set file")
                return cls.from_json_dict(d, source=str(path))
        except (KeyError, OSError, json.JSONDecodeError) as e:  # JSONDecodeError first: a
            # subclass of ValueError
            raise ValueError(f"{path}: malformed data set file ({type(e).__name__}: {e})") \
                from None
        except ValueError as e:
            if str(e).startswith(f"{path}: "):  # the schema's message names the file already
                raise ValueError(str(e)) from None
            raise ValueError(f"{path}: {e}") from None
        except Exception as e:  # noqa: BLE001 - numpy raises assorted errors on corrupt files
            raise ValueError(f"{path}: malformed data set file ({type(e).__name__}: {e})") \
                from None
        raise ValueError(f"{path}: data sets are read from .npz or .json files")

    @classmethod
    def from_json_dict(cls, d: dict[str, Any], source: str = "data set") -> "Dataset":
        """A data set from its JSON form (:meth:`to_json_dict`), validated by its schema: a
        wrong entry raises one ValueError naming ``source`` and the entry
        (``points[3].pixel: must be 2 numbers``)."""
        from .schema import validate

        _check_header(d, source)
        validate(d, _json_schema(), str(source))
        entries = d["points"]
        for key in ("joints", "pose_index", "quality"):
            having = [key in e for e in entries]
            if any(having) and not all(having):
                i = having.index(not having[0])
                raise ValueError(f"{source}: points[{i}] {'has' if having[i] else 'lacks'} "
                                 f"{key} but points[0] {'has' if having[0] else 'does not'}: "
                                 f"give {key} for every point or for none")
        m = len(entries)
        quality = None
        if entries and "joints" in entries[0]:
            _alike(entries, "joints", lambda j: f"{len(j)} readings", source)
        if entries and "quality" in entries[0]:
            keys = _alike(entries, "quality", sorted, source)
            quality = {k: np.array([np.nan if e["quality"][k] is None else e["quality"][k]
                                    for e in entries], float) for k in keys}
        return cls(np.array([e["pixel"] for e in entries], float).reshape(m, 2),
                   np.array([e["base_from_hand"] for e in entries], float).reshape(m, 4, 4),
                   np.array([e["reference"] for e in entries], float).reshape(m, 3),
                   ids=np.array([str(e["id"]) for e in entries]),
                   joints=np.array([e["joints"] for e in entries], float)
                   if entries and "joints" in entries[0] else None,
                   joint_unit=d.get("joint_unit", "rad"),
                   pose_index=np.array([e["pose_index"] for e in entries], dtype=np.int64)
                   if entries and "pose_index" in entries[0] else None,
                   length_unit=d.get("length_unit", "mm"), meta=d.get("meta", {}),
                   quality=quality)


def _alike(entries: list[dict[str, Any]], key: str, describe: Any, source: str) -> Any:
    """``describe(entry[key])`` (the number of joint readings, the quality's names), the same
    for every point as for points[0], or a ValueError naming the first that differs."""
    want = describe(entries[0][key])
    for i, e in enumerate(entries):
        got = describe(e[key])
        if got != want:
            raise ValueError(f"{source}: points[{i}].{key}: has {got}, points[0] has {want}")
    return want


def _check_quality(quality: Any, m: int) -> dict[str, np.ndarray] | None:
    """:attr:`Dataset.quality` checked: None, or a dict of (m,) float arrays named by
    QUALITY_FIELDS (NaN where a value is missing, no infinities)."""
    if quality is None:
        return None
    if not isinstance(quality, dict):
        raise ValueError(f"quality must be a dict of arrays named {', '.join(QUALITY_FIELDS)}"
                         f", got {type(quality).__name__}")
    out = {}
    for k, v in quality.items():
        if k not in QUALITY_FIELDS:
            raise ValueError(f"quality has an unknown entry {k!r}; the entries are "
                             f"{', '.join(QUALITY_FIELDS)}")
        try:
            a = np.array(v, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"quality[{k!r}] must be numbers") from None
        if a.shape != (m,):
            raise ValueError(f"quality[{k!r}] must have {m} entries (one per point), got "
                             f"shape {a.shape}")
        if np.isinf(a).any():
            raise ValueError(f"quality[{k!r}] entry {int(np.argmax(np.isinf(a)))} is infinite")
        out[k] = a
    return out or None


def fit_and_test(dataset: Any, test: Any = None) -> tuple["Dataset", "Dataset | None"]:
    """(fit, test) from a Dataset (+ optional test set) or a simulation with ``fit``/``test``."""
    if hasattr(dataset, "fit") and hasattr(dataset, "test") and not isinstance(dataset, Dataset):
        test = dataset.test if test is None else test
        dataset = dataset.fit
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be an hmlvs.Dataset, got {type(dataset).__name__}")
    if test is not None and not isinstance(test, Dataset):
        raise ValueError("test must be an hmlvs.Dataset")
    return dataset, test


def check_format(d: Any, fmt: str, version: int, source: Any, what: str) -> None:
    """Raise ``ValueError`` unless ``d`` is a mapping with ``format == fmt`` and a version this
    hmlvs understands. Shared by the data set, calibration and manifest readers."""
    if not isinstance(d, dict) or d.get("format") != fmt:
        raise ValueError(f"{source}: not an hmlvs {what} (format field is "
                         f"{d.get('format') if isinstance(d, dict) else None!r})")
    v = d.get("version", 1)
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ValueError(f"{source}: version must be a whole number >= 1, got {v!r}")
    if v > version:
        raise ValueError(f"{source}: {what} format version {v} is newer than this hmlvs "
                         f"understands ({version})")


def _check_header(d: dict[str, Any], source: Any) -> None:
    check_format(d, FORMAT, FORMAT_VERSION, source, "data set")


def _header_schema(**more: Any) -> Any:
    """The keys a data set's header holds (the JSON file's top level, the .npz's header)."""
    from . import schema as sc

    return sc.Field("struct", "an hmlvs data set", required=("format",), keys={
        **sc.header(FORMAT, FORMAT_VERSION),
        "length_unit": sc.text("a length unit", choices=tuple(_LENGTH_SCALE)),
        "joint_unit": sc.text("an angle unit", choices=_ANGLE_UNITS),
        "meta": sc.Field("map", "a mapping (notes on the data)"), **more})


def _json_schema() -> Any:
    """A data set in JSON: the header and a list of calibration points."""
    from . import schema as sc

    def numbers(n: int, what: str) -> Any:
        return sc.Field("list", what, length=n, items=sc.number())

    entry = sc.Field(
        "struct", "a calibration point {id, pixel, reference, base_from_hand[, joints, "
        "pose_index]}", required=("id", "pixel", "reference", "base_from_hand"), keys={
            "id": sc.identifier(), "pixel": numbers(2, "the stripe pixel [u, v]"),
            "reference": numbers(3, "the reference point [x, y, z]"),
            "base_from_hand": sc.matrix(4, 4, "the 4x4 base_from_hand pose"),
            "joints": sc.Field("list", "the joint readings", items=sc.number()),
            "pose_index": sc.integer(),
            "quality": sc.Field("struct", "the stripe's quality {sigma, width, peak, "
                                "residual} (numbers or null)", keys={
                                    k: sc.number(nullable=True) for k in QUALITY_FIELDS})})
    return _header_schema(points=sc.Field("list", "a list of calibration points",
                                          items=entry))


def _npz_schema() -> Any:
    """A data set in .npz: its arrays (m points) and the JSON header."""
    from . import schema as sc

    return sc.Field(
        "struct", "an hmlvs data set (.npz: header, pixels, poses, points, ids)",
        required=("header", "pixels", "poses", "points", "ids"), keys={
            "header": sc.array((), "the JSON header", dtype="id"),
            "pixels": sc.array(("m", 2), "the stripe pixels"),
            "poses": sc.array(("m", 4, 4), "the base_from_hand poses"),
            "points": sc.array(("m", 3), "the reference points"),
            "ids": sc.array(("m",), "the point ids", dtype="id"),
            "joints": sc.array(("m", "n"), "the joint readings"),
            "pose_index": sc.array(("m",), "the pose index of each point", dtype="int"),
            **{f"quality_{k}": sc.array(("m",), f"the stripe's {k} at each point",
                                        nullable=True)
               for k in QUALITY_FIELDS}})


def _split_count(fit: float | int, total: int, what: str) -> int:
    if isinstance(fit, float) or (isinstance(fit, int) and 0 < fit < 1):
        if not 0 < fit < 1:
            raise ValueError(f"a fit fraction must lie in (0, 1), got {fit}")
        n = int(round(fit * total))
    else:
        n = int(fit)
    if not 0 < n < total:
        raise ValueError(f"cannot split {total} {what} into {n} to fit and {total - n} to test")
    return n
