"""Live measurement: one camera frame and the robot pose it was taken at -> the stripe's 3D
points, frame after frame, from one or several threads.

``Measurer(calibration).points(frame, base_from_hand)`` extracts the stripe as the session
pipeline does (:func:`hmlvs.image.session.stripe_from_pair`: a laser-on frame alone, or with
its laser-off frame) and maps every found centre through the calibration to the camera and the
robot base, as the sensor model's ``points_in_camera`` does: for a grey frame all in one C++
call (cpp/hmlvs/measure/profile.h), which fills the profile's arrays. Nothing is shared
between calls but the calibration and the options, which are read only: one ``Measurer``
serves several threads, and the C++ kernels release the GIL.
"""

from __future__ import annotations

from dataclasses import dataclass
import enum
import os
from typing import Any

import numpy as np

from .. import _core
from .._arrays import as_matrix, as_params
from ..data.calibration_file import Calibration
from ..image.colour import feature_stripe, is_colour
from ..image.frames import alone_way, frames_options
from ..image.session import stripe_from_pair, with_direction
from ..image.stripe import as_gray
from ..models.opencv import OpenCvSensor
from ..models.paper import PaperSensor
from .measure import require_hand_eye, sensor_model


class PointStatus(enum.IntEnum):
    """Per scan line of a frame: what :meth:`Measurer.points` made of it."""

    MEASURED = 0    #: a stripe centre, mapped to a 3D point
    NO_STRIPE = 1   #: no usable stripe centre on this scan line (see ``stripe_status``)
    NO_POINT = 2    #: a centre whose ray misses the laser plane (or meets it behind the camera)


@dataclass(frozen=True)
class Profile:
    """One frame's measurement, one entry per scan line (image column for a roughly
    horizontal stripe).

    Attributes
    ----------
    pixels : (n, 2) the stripe centre (u, v) of each scan line, NaN where none
    points : (n, 3) the point in the robot base frame (mm), NaN unless MEASURED (and all NaN
        for a frame measured without a robot pose)
    camera_points : (n, 3) the same point in the camera frame (mm)
    status : (n,) :class:`PointStatus` codes
    stripe_status : (n,) the stripe extractor's :class:`hmlvs.image.StripeStatus` codes
    """

    pixels: np.ndarray
    points: np.ndarray
    camera_points: np.ndarray
    status: np.ndarray
    stripe_status: np.ndarray

    @property
    def measured(self) -> np.ndarray:
        """(n,) bool: scan lines that gave a point."""
        return self.status == PointStatus.MEASURED

    def __len__(self) -> int:
        return int(self.status.shape[0])


class Measurer:
    """A calibrated sensor, ready to measure frames (see the module's documentation).

    Parameters
    ----------
    calibration : a :class:`hmlvs.Calibration` of either model (:func:`hmlvs.calibrate`'s,
        or a file's) or the path of a calibration file; a bench session's calibration (no
        hand-eye transform) measures in the camera frame only (frames without a pose)
    stripe_options : options of :func:`hmlvs.image.session.stripe_from_pair`; without
        ``blur_var`` the camera blur the calibration's session fitted is used; without
        ``direction`` the first frame's (:func:`hmlvs.image.session.stripe_direction`), kept
        for the frames after it
    """

    def __init__(self, calibration: Any, **stripe_options: Any) -> None:
        if isinstance(calibration, (str, os.PathLike)):
            calibration = Calibration.load(calibration)
        try:
            require_hand_eye(calibration)
            self._bench_only: str | None = None
        except ValueError as e:  # a bench calibration: camera-frame profiles only
            self._bench_only = str(e)
        self._model = sensor_model(calibration)
        size = getattr(self._model, "image_size", None)
        if size is None:
            size = getattr(calibration, "image_size", None)
        self.image_size: tuple[int, int] | None = (
            None if size is None else (int(size[0]), int(size[1])))
        options = dict(stripe_options)
        if options.get("blur_var") is None and getattr(calibration, "blur_var", None):
            options["blur_var"] = calibration.blur_var
        # a typo in the options is the caller's error, found now rather than at frame one
        try:
            stripe_from_pair(np.zeros((16, 16), np.uint8), np.zeros((16, 16), np.uint8),
                             **_checked_only(options))
        except TypeError as e:  # an unknown keyword
            raise ValueError(f"stripe options {sorted(options)}: {e}") from None
        self._options = options
        # grey frames (or a colour frame's channel) go straight to the C++ pipeline with its
        # options built once, its direction the first frame's unless given; colour frames
        # first pick the laser's channel (stripe_from_pair)
        self._channel = options.get("channel")
        self._core = None if options.get("direction") in (None, "auto") else \
            frames_options(**{k: v for k, v in options.items() if k != "channel"})
        self._sensor = _laser_sensor(self._model)
        # a grey frame alone: the way its stripe is found (alone_way), the first such
        # frame's, kept for the frames after it
        self._alone_way: str | None = None

    def points(self, frame: np.ndarray, base_from_hand: Any = None,
               off: np.ndarray | None = None) -> Profile:
        """The stripe of ``frame`` (laser on; ``off``: the laser-off frame at the same pose,
        if taken) measured at the robot pose ``base_from_hand`` (4 x 4, mm). Without a pose
        the profile's ``points`` are NaN and its ``camera_points`` the measurement (the
        camera frame: a sensor on a bench, or a bench session's calibration)."""

        frame = _image(frame, "the frame")
        if self.image_size is not None and (frame.shape[1], frame.shape[0]) != self.image_size:
            raise ValueError(f"the frame is {frame.shape[1]} x {frame.shape[0]} pixels but the "
                             f"calibration's images are {self.image_size[0]} x "
                             f"{self.image_size[1]}")
        if off is not None and _image(off, "the laser-off frame").shape != frame.shape:
            raise ValueError("the laser-on and laser-off frames differ in size")
        if base_from_hand is not None and self._bench_only:
            raise ValueError(f"{self._bench_only}; Measurer.points(frame) without a pose "
                             "measures in the camera frame")
        pose = np.eye(4) if base_from_hand is None else \
            as_matrix(base_from_hand, 4, "base_from_hand")
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ValueError(f"base_from_hand must be a finite 4 x 4 transform, got shape "
                             f"{pose.shape}")
        if self._core is None:  # the stripe's direction from the first frame, then kept
            self._options = with_direction(self._options, frame, off)
            self._core = frames_options(**{k: v for k, v in self._options.items()
                                           if k != "channel"})
        if self._channel is None and is_colour(frame):
            arrays = self._colour_profile(frame, off, pose)
        else:
            on_g = as_gray(frame, "the laser-on image", self._channel)
            off_g = None if off is None else as_gray(off, "the laser-off image", self._channel)
            if off_g is None and self._alone_way is None:  # the first frame alone decides
                try:
                    self._alone_way = alone_way(on_g, self._core, self._options,
                                                background=False)[1]
                except ValueError:  # no stripe either way: the C++ pipeline's own
                    self._alone_way = "frames"
            if off_g is None and self._alone_way == "feature":
                arrays = self._feature_profile(on_g, pose)
            else:
                arrays = _core._measure_frames(on_g, off_g, self._core, self._sensor, pose)
        pixels, points, camera_points, status, stripe_status = arrays
        if base_from_hand is None:  # the camera frame only
            points = np.full_like(camera_points, np.nan)
        return Profile(pixels, points, camera_points, status, stripe_status)

    def _colour_profile(self, frame: np.ndarray, off: np.ndarray | None,
                        pose: np.ndarray) -> tuple[np.ndarray, ...]:
        """A colour frame's profile arrays: its stripe from stripe_from_pair (which picks the
        laser's channel), measured in C++."""
        return self._profile_of(lambda: stripe_from_pair(frame, off, **self._options),
                                frame.shape, pose)

    def _feature_profile(self, on_g: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, ...]:
        """A grey frame alone's profile arrays when the first frame's stripe was found on
        the laser feature (hmlvs.image.session.alone_way): its stripe found there."""
        return self._profile_of(lambda: feature_stripe(on_g, **self._options), on_g.shape,
                                pose)

    def _profile_of(self, stripe_of: Any, shape: tuple[int, ...], pose: np.ndarray
                    ) -> tuple[np.ndarray, ...]:
        """The profile arrays of the stripe ``stripe_of()`` finds, measured in C++ (empty
        when no pixel is above its threshold)."""
        try:
            stripe = stripe_of()
        except ValueError as e:
            if "leaves no pixel" not in str(e):
                raise
            return _core._empty_profile(shape[1 if self._options["direction"] == "columns"
                                              else 0])
        direction = (_core._StripeDirection.columns if stripe.direction == "columns"
                     else _core._StripeDirection.rows)
        return _core._measure_stripe(self._sensor, stripe.centre, stripe.status, direction,
                                     pose)


def _laser_sensor(model: Any) -> Any:
    """The C++ measurement kernel's sensor (cpp/hmlvs/measure/profile.h) of either model."""
    if isinstance(model, PaperSensor):
        return _core._LaserSensor.paper(as_params(model.params))
    if isinstance(model, OpenCvSensor):
        width, height = model.image_size
        return _core._LaserSensor.opencv(model.intrinsics_vector(), model.laser_plane,
                                         model.hand_from_camera_matrix(), width, height)
    raise ValueError(f"Measurer measures with the paper or the opencv model, not a "
                     f"{type(model).__name__}")


def _checked_only(options: dict[str, Any]) -> dict[str, Any]:
    """The options as stripe_from_pair checks them on a blank grey pair (no automatic
    threshold to trip over: a fixed one; no channel, which each frame's check takes)."""
    out = {k: v for k, v in options.items() if k != "channel"}
    out.setdefault("threshold", 1.0)
    return out


def _image(image: Any, what: str) -> np.ndarray:
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3) or image.size == 0:
        raise ValueError(f"{what} must be an image (a 2D or colour numpy array)")
    return image
