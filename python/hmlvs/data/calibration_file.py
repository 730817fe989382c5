"""The calibration file: what `hmlvs calibrate` writes and `hmlvs measure` reads back.

Format ``hmlvs-calibration`` version 1, as YAML (``.yaml``/``.yml``) or JSON (``.json``)::

    format: hmlvs-calibration
    version: 1
    units: {length: mm, angle: rad, pixel: px, k: 1/mm^2}
    parameters: {f: 8.0, Su: 0.0074, ...}     # all 14, paper order (docs/model.md)
    std: {f: 0.002, Su: null, ...}           # standard deviations; null when fixed/unknown
    fixed: [Su]
    fit_rms_mm: 0.09
    test_rms_mm: 0.10                        # null without held-out points
    num_points: 120
    method: pso+lm
    data_sha256: 3f2a...                     # hash of the calibration data used
    created: '2026-11-22T16:00:00+00:00'
    hmlvs_version: 0.1.0
    hand_from_camera: [[...4x4...]]          # derived, for C++/ROS users (mm)
    robot: {...}                             # optional DH description (hmlvs.Robot.to_dict)
    stripe_blur_var_px2: 0.42                # optional: the camera blur variance fitted by
                                             # the image calibration; measurement corrects
                                             # stripes at albedo steps with it
    model: paper                             # or opencv (then 'sensor' holds the calibration
    sensor: {...}                            # and 'parameters' may be absent):
                                             # hmlvs.models.opencv.OpenCvSensor.to_dict
    verdict:                                 # optional (older files have none): whether
      trustworthy: false                     # to trust it, hmlvs.diagnostics.verdict
      reasons: [...]                         # one sentence per failed check
      checks: [{name, value, limit, ok, unit, why}, ...]
      map_sigma_mm: {rms: 0.14, p95: 0.23}   # predicted 3D uncertainty, or null
      cross_validation_mm: {rms: .., p95: ..}  # two halves' maps apart, or null
      likely_mistake: null                   # the usual mistake that explains the data

A file without ``model`` is a paper-model file. Both models write every key (null where it
does not apply: ``sensor`` of a paper-model file, ``image_size`` of an opencv one, ...) but
``parameters``, which an opencv-model file leaves out; files without the optional keys (older
ones) still load.

See docs/file-formats.md for the full description.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import datetime
import hashlib
import math
import os
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .._io import read_document, write_document
from ..geometry.robot import Robot
from ..models.opencv import OpenCvSensor
from ..models.paper import hand_from_camera
from ..models.params import NAMES, UNITS, Parameters
from . import schema
from .dataset import Dataset, check_format

FORMAT = "hmlvs-calibration"
FORMAT_VERSION = 1
MODELS = ("paper", "opencv")


def _schema() -> "schema.Field":
    """The calibration file's shape (see the module doc); unknown keys are kept for newer
    writers' sake, known ones must have their type."""
    from . import schema as sc

    names = sc.Field("list", "a list of parameter names",
                     items=sc.text("a parameter name", choices=NAMES))
    return sc.Field("struct", "a calibration file", required=("format",), keys={
        **sc.header(FORMAT, FORMAT_VERSION),
        "model": sc.text("the sensor model", choices=MODELS),
        "units": sc.Field("map", "a mapping like {length: mm, angle: rad}",
                          items=sc.text("a unit")),
        "parameters": sc.Field("map", "a mapping of parameter names to numbers",
                               items=sc.number()),
        "std": sc.Field("map", "a mapping of names to standard deviations",
                        items=sc.number(nullable=True), nullable=True),
        "fixed": sc.Field("list", "a list of parameter names", items=names.items,
                          nullable=True),
        "fit_rms_mm": sc.number(nullable=True), "test_rms_mm": sc.number(nullable=True),
        "num_points": sc.integer(nullable=True, minimum=0),
        "method": sc.text(nullable=True), "data_sha256": sc.text(nullable=True),
        "created": sc.text(nullable=True), "hmlvs_version": sc.text(nullable=True),
        "hand_from_camera": sc.matrix(4, 4, "a 4x4 transform", nullable=True),
        "robot": sc.Field("any"), "sensor": sc.Field("map", "the opencv sensor", nullable=True),
        "stripe_blur_var_px2": sc.number("a blur variance in px^2", nullable=True),
        "image_size": sc.Field("any"),
        "verdict": sc.Field("struct", "a verdict (trustworthy, reasons, checks)",
                            required=("trustworthy",), nullable=True, keys={
                                "trustworthy": sc.Field("bool", "true or false"),
                                "reasons": sc.Field("list", "a list of sentences",
                                                    items=sc.text("a sentence")),
                                "checks": sc.Field("list", "a list of checks",
                                                   items=sc.Field("any")),
                                "map_sigma_mm": sc.Field("map", "{rms, p95} in mm",
                                                         items=sc.number(nullable=True),
                                                         nullable=True),
                                "cross_validation_mm": sc.Field(
                                    "map", "{rms, p95} in mm",
                                    items=sc.number(nullable=True), nullable=True),
                                "likely_mistake": sc.text(nullable=True)}),
    })


def dataset_hash(ds: Dataset) -> str:
    """SHA-256 of a data set's pixels, poses, reference points and ids (order matters)."""
    h = hashlib.sha256()
    for a in (ds.pixels, ds.poses, ds.points):
        h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    h.update("\n".join(map(str, ds.ids)).encode())
    return h.hexdigest()


class SolveOutcome(Protocol):
    """What a solver returns, as a :class:`Calibration` holds it (``solve``): the paper
    model's :class:`~hmlvs.calibration.result.CalibrationResult` or the general model's
    :class:`~hmlvs.calibration.joint_result.JointCalibration`."""

    warnings: list[str]

    def solve_figures(self) -> dict[str, Any]: ...

    def summary(self) -> str: ...


@dataclass
class Calibration:
    """A calibrated sensor: what :func:`hmlvs.calibrate` returns for either model, and what
    a calibration file holds (:meth:`save`, :meth:`load`; :meth:`to_dict` is the file's
    content).

    ``model`` is "paper" (the 14 ``params``) or "opencv" (``sensor``, an
    :class:`~hmlvs.models.opencv.OpenCvSensor`; ``params`` then may be None). A calibration
    just computed also holds the solver's whole outcome (``solve``) and the verdict's
    details (``judged``); neither is saved.
    """

    params: Parameters | None = None
    std: dict[str, float | None] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()
    fit_rms: float | None = None
    test_rms: float | None = None
    num_points: int | None = None
    method: str | None = None
    data_sha256: str | None = None
    created: str | None = None
    hmlvs_version: str | None = None
    robot: Robot | None = None
    sensor: OpenCvSensor | None = None
    model: str = "paper"
    #: the camera blur variance (px^2) the image calibration fitted (its stripes' correction
    #: at albedo steps, ``stripe_from_pair`` ``blur_var``); measurement from images uses it
    blur_var: float | None = None
    #: a paper-model calibration from images: the images' (width, height), which measuring
    #: from images holds them to (an opencv calibration's sensor carries its own)
    image_size: tuple[int, int] | None = None
    #: the verdict (:meth:`hmlvs.diagnostics.verdict.Verdict.to_dict`); None in files
    #: written before verdicts
    verdict: dict[str, Any] | None = None
    #: the solver's outcome (:class:`~hmlvs.calibration.result.CalibrationResult` or
    #: :class:`~hmlvs.calibration.joint_result.JointCalibration`: every figure of the solve,
    #: the uncertainty, the warnings) when this calibration was just computed; None when
    #: loaded from a file (it is not saved)
    solve: SolveOutcome | None = field(default=None, repr=False, compare=False)
    #: the :class:`~hmlvs.diagnostics.verdict.Verdict` behind ``verdict`` when it was just
    #: judged (with its uncertainty map over the image, which the report draws); not saved
    judged: Any = field(default=None, repr=False, compare=False)

    @property
    def trustworthy(self) -> bool | None:
        """The verdict's: True, False, or None when the file carries no verdict."""
        return None if self.verdict is None else bool(self.verdict["trustworthy"])

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"unknown sensor model {self.model!r}; the models are "
                             f"{', '.join(MODELS)}")
        if self.model == "paper" and self.params is None:
            raise ValueError("a paper-model calibration needs its 14 parameters")
        if self.model == "opencv" and self.sensor is None:
            raise ValueError("an opencv-model calibration needs its sensor "
                             "(hmlvs.models.opencv.OpenCvSensor)")

    @classmethod
    def from_result(cls, result: Any, dataset: Dataset | None = None,
                    robot: Robot | None = None) -> "Calibration":
        from .. import __version__

        std_src = result.parameter_std() if hasattr(result, "parameter_std") else {}
        std = {n: (None if n in result.fixed or std_src.get(n) is None
                   or not math.isfinite(std_src[n]) else float(std_src[n])) for n in NAMES}
        return cls(params=result.params, std=std, fixed=tuple(result.fixed),
                   fit_rms=float(result.fit_rms),
                   test_rms=None if result.test_rms is None else float(result.test_rms),
                   num_points=int(result.fit_errors.size), method=result.method,
                   data_sha256=None if dataset is None else dataset_hash(dataset),
                   created=datetime.datetime.now(datetime.timezone.utc).isoformat(
                       timespec="seconds"),
                   hmlvs_version=__version__, robot=robot,
                   blur_var=None if dataset is None else _blur_var_of(dataset.meta),
                   image_size=None if dataset is None else _image_size_of(dataset.meta),
                   solve=result)

    @classmethod
    def from_joint(cls, result: Any, robot: Robot | None = None,
                   blur_var: float | None = None) -> "Calibration":
        """The calibration file of a general-model (opencv) joint calibration
        (:class:`hmlvs.calibration.joint.JointCalibration`); ``blur_var``: the camera blur
        variance its image session was extracted with (the reports'
        :attr:`~hmlvs.image.accounts.ImageReport.blur_var`), if any."""
        from .. import __version__

        return cls(params=None, sensor=result.sensor, model="opencv", std=dict(result.std),
                   fit_rms=float(result.laser_rms_mm), test_rms=result.test_rms_mm,
                   num_points=int(sum(v["laser_pixels"] for v in result.per_view.values())),
                   method=f"joint-lm ({result.mode})",
                   created=datetime.datetime.now(datetime.timezone.utc).isoformat(
                       timespec="seconds"),
                   hmlvs_version=__version__, robot=robot, blur_var=blur_var, solve=result)

    def to_dict(self) -> dict[str, Any]:
        """The calibration file's content, either model: every key of the format (null where
        it does not apply), but ``parameters`` only for a calibration that has them (older
        readers refuse a null there)."""
        d: dict[str, Any] = {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "model": self.model,
            "units": {"length": "mm", "angle": "rad", "pixel": "px", "k": "1/mm^2"},
        }
        if self.params is not None:
            d["parameters"] = {n: float(getattr(self.params, n)) for n in NAMES}
            d["std"] = {n: self.std.get(n) for n in NAMES}
        else:
            # the joint solve's standard deviations: px, mm, rad (rotation vectors)
            d["std"] = {k: (None if v is None else float(v)) for k, v in self.std.items()}
        d.update({
            "fixed": list(self.fixed),
            "fit_rms_mm": self.fit_rms,
            "test_rms_mm": self.test_rms,
            "num_points": self.num_points,
            "method": self.method,
            "data_sha256": self.data_sha256,
            "created": self.created,
            "hmlvs_version": self.hmlvs_version,
            "hand_from_camera": (hand_from_camera(self.params) if self.sensor is None
                                 else self.sensor.hand_from_camera).tolist(),
            "robot": None if self.robot is None else self.robot.to_dict(),
            "stripe_blur_var_px2": None if self.blur_var is None else float(self.blur_var),
            "image_size": (None if self.image_size is None or self.sensor is not None
                           else [int(self.image_size[0]), int(self.image_size[1])]),
            "verdict": self.verdict,
            "sensor": None if self.sensor is None else self.sensor.to_dict(),
        })
        return d

    def solve_figures(self) -> dict[str, Any] | None:
        """The solve's figures in the form both models share (termination, iterations,
        seconds, what the data determine, the hand-eye rotation; ``hmlvs calibrate
        --json``'s ``solve``, docs/file-formats.md); None for a calibration loaded from a
        file."""
        return None if self.solve is None else self.solve.solve_figures()

    @property
    def warnings(self) -> list[str]:
        """The solve's warnings about the data or the solution (none for a loaded file)."""
        return [] if self.solve is None else list(self.solve.warnings)

    def summary(self) -> str:
        """A few lines a user reads: the verdict's first line, then the solve's summary
        (a loaded file: its parameter table)."""
        lines = []
        if self.verdict is not None:
            lines.append("verdict: " + ("trustworthy" if self.trustworthy else
                                        "NOT trustworthy: " + "; ".join(
                                            self.verdict.get("reasons") or [])))
        lines.append(self.table() if self.solve is None else self.solve.summary())
        return "\n".join(lines)

    def save(self, path: str | os.PathLike) -> Path:
        """Write atomically as YAML (.yaml/.yml) or JSON (.json)."""
        return write_document(path, self.to_dict(), "calibration")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Calibration":
        d = read_document(path, "calibration file")
        return cls.from_dict(d, source=str(path))

    @classmethod
    def from_dict(cls, d: Any, source: str = "calibration") -> "Calibration":
        from .schema import validate

        check_format(d, FORMAT, FORMAT_VERSION, source, "calibration file")
        validate(d, _schema(), str(source))
        units = d.get("units", {})
        if units and (units.get("length", "mm") != "mm" or units.get("angle", "rad") != "rad"):
            raise ValueError(f"{source}: units must be mm and rad, got {units}")
        model = d.get("model", "paper")
        if model not in MODELS:
            raise ValueError(f"{source}: unknown sensor model {model!r}; the models are "
                             f"{', '.join(MODELS)}")
        p = d.get("parameters")
        params = None
        if model == "paper" or p is not None:
            if not isinstance(p, dict):
                raise ValueError(f"{source}: 'parameters' must map the 14 parameter names to "
                                 "values")
            try:
                params = Parameters.from_dict(p)
            except ValueError as e:
                raise ValueError(f"{source}: {e}") from None
            zero = [n for n in ("f", "Su", "Sv") if getattr(params, n) == 0]
            if zero:
                raise ValueError(f"{source}: parameters: {', '.join(zero)} "
                                 f"{'is' if len(zero) == 1 else 'are'} 0; the focal length "
                                 "f and the pixel pitches Su, Sv scale every pixel to mm and "
                                 "must not be 0")
        sensor = None
        if model == "opencv" or d.get("sensor") is not None:
            if d.get("sensor") is None:
                raise ValueError(f"{source}: a calibration of model opencv needs a 'sensor' "
                                 "block (camera_matrix, dist_coeffs, image_size, laser_plane, "
                                 "hand_from_camera)")
            sensor = OpenCvSensor.from_dict(d["sensor"], source=f"{source}: sensor")
        stored = d.get("hand_from_camera")
        derived = (hand_from_camera(params) if params is not None
                   else None if sensor is None else sensor.hand_from_camera)
        if stored is not None and derived is not None:
            diff = float(np.abs(np.asarray(stored, float) - derived).max())
            if not diff <= 1e-6 * max(1.0, float(np.abs(derived).max())):
                raise ValueError(f"{source}: hand_from_camera contradicts the calibration's "
                                 f"{'parameters' if params is not None else 'sensor'} (they "
                                 f"differ by up to {diff:.3g}); it is derived from them: "
                                 "remove it or correct it")
        robot = None
        if d.get("robot"):
            from .robot_file import robot_from_dict

            robot = robot_from_dict(d["robot"], f"{source}: robot")
        blur_var = d.get("stripe_blur_var_px2")
        if blur_var is not None:
            from ..image.frames import MAX_BLUR_VAR

            if not 0.0 <= blur_var <= MAX_BLUR_VAR:
                raise ValueError(f"{source}: stripe_blur_var_px2 must lie in [0, "
                                 f"{MAX_BLUR_VAR:g}] px^2 (the camera blur's variance), got "
                                 f"{blur_var}")
        std = d.get("std") or {}
        if not isinstance(std, dict):
            raise ValueError(f"{source}: 'std' must map names to standard deviations")
        return cls(params=params, std={n: std.get(n) for n in NAMES} if params is not None
                   else dict(std),
                   fixed=tuple(d.get("fixed") or ()), fit_rms=d.get("fit_rms_mm"),
                   test_rms=d.get("test_rms_mm"), num_points=d.get("num_points"),
                   method=d.get("method"), data_sha256=d.get("data_sha256"),
                   created=d.get("created"), hmlvs_version=d.get("hmlvs_version"), robot=robot,
                   sensor=sensor, model=model,
                   blur_var=None if blur_var is None else float(blur_var),
                   image_size=_checked_size(d.get("image_size"), source),
                   verdict=d.get("verdict"))

    def table(self) -> str:
        if self.params is None:
            assert self.sensor is not None
            lines = [f"{'name':<7} {'value':>14} {'std':>11}"]
            for n, v in self.sensor.intrinsics().items():
                sd = self.std.get(n)
                lines.append(f"{n:<7} {v:>14.7g} {'-' if sd is None else f'{sd:.3g}':>11}")
            return "\n".join(lines)
        lines = [f"{'param':<7} {'unit':<7} {'value':>14} {'std':>11}"]
        for n in NAMES:
            s = self.std.get(n)
            s_txt = "fixed" if n in self.fixed else ("-" if s is None else f"{s:.3g}")
            lines.append(f"{n:<7} {UNITS[n]:<7} {getattr(self.params, n):>14.7g} {s_txt:>11}")
        return "\n".join(lines)


def _image_size_of(meta: dict[str, Any]) -> tuple[int, int] | None:
    """The (width, height) of the images a data set came from (its ``meta["image_size"]``),
    or None."""
    size = meta.get("image_size") if meta.get("source") == "images" else None
    return None if size is None else (int(size[0]), int(size[1]))


def _checked_size(size: Any, source: str) -> tuple[int, int] | None:
    """A calibration file's ``image_size``: two positive whole numbers, or absent."""
    if size is None:
        return None
    ok = isinstance(size, list) and len(size) == 2 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and float(v).is_integer()
        and v > 0 for v in size)
    if not ok:
        raise ValueError(f"{source}: image_size must be [width, height] in pixels, two "
                         f"positive whole numbers, got {size!r}")
    return int(size[0]), int(size[1])


def _blur_var_of(meta: dict[str, Any]) -> float | None:
    """The camera blur variance an image data set's stripes were corrected with (its
    ``meta["blur_var"]``; None for data not from images)."""
    v = meta.get("blur_var") if meta.get("source") == "images" else None
    return None if v is None else float(v)


def load_calibration(path: str | os.PathLike) -> Calibration:
    """Read a calibration file written by ``hmlvs calibrate`` (YAML or JSON)."""
    return Calibration.load(path)
