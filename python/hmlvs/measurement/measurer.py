"""Live measurement: one camera frame and the robot pose it was taken at -> the stripe's 3D
points, frame after frame, from one or several threads.

``Measurer(calibration).points(frame, base_from_hand)`` extracts the stripe as the session
pipeline does (:func:`hmlvs.image.session.stripe_from_pair`: a laser-on frame alone, or with
its laser-off frame; one C++ call per frame) and maps every found centre through the
calibration to the camera and the robot base. Nothing is shared between calls but the
calibration and the options, which are read only: one ``Measurer`` serves several threads, and
the heavy parts (the C++ kernels) release the GIL.
"""

from __future__ import annotations

from dataclasses import dataclass
import enum
import os
from typing import Any

import numpy as np

from .._arrays import as_matrix
from ..data.calibration_file import Calibration
from ..image.stripe import StripeStatus
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
    points : (n, 3) the point in the robot base frame (mm), NaN unless MEASURED
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
        hand-eye transform) is refused
    stripe_options : options of :func:`hmlvs.image.session.stripe_from_pair`; without
        ``blur_var`` the camera blur the calibration's session fitted is used
    """

    def __init__(self, calibration: Any, **stripe_options: Any) -> None:
        if isinstance(calibration, (str, os.PathLike)):
            calibration = Calibration.load(calibration)
        require_hand_eye(calibration)
        self._model = sensor_model(calibration)
        size = getattr(self._model, "image_size", None)
        if size is None:
            size = getattr(calibration, "image_size", None)
        self.image_size: tuple[int, int] | None = (
            None if size is None else (int(size[0]), int(size[1])))
        options = dict(stripe_options)
        if options.get("blur_var") is None and getattr(calibration, "blur_var", None):
            options["blur_var"] = calibration.blur_var
        from ..image.session import frames_options, stripe_from_pair

        # a typo in the options is the caller's error, found now rather than at frame one
        try:
            stripe_from_pair(np.zeros((16, 16), np.uint8), np.zeros((16, 16), np.uint8),
                             **_checked_only(options))
        except TypeError as e:  # an unknown keyword
            raise ValueError(f"stripe options {sorted(options)}: {e}") from None
        self._options = options
        # grey frames (or a colour frame's channel) go straight to the C++ pipeline with its
        # options built once; colour frames first pick the laser's channel (stripe_from_pair)
        fast = {k: v for k, v in options.items() if k != "channel"}
        self._channel = options.get("channel")
        self._core = frames_options(**fast)
        self._hand_from_camera = np.asarray(self._model.hand_from_camera_matrix(), float)

    def points(self, frame: np.ndarray, base_from_hand: Any,
               off: np.ndarray | None = None) -> Profile:
        """The stripe of ``frame`` (laser on; ``off``: the laser-off frame at the same pose,
        if taken) measured at the robot pose ``base_from_hand`` (4 x 4, mm)."""

        frame = _image(frame, "the frame")
        if self.image_size is not None and (frame.shape[1], frame.shape[0]) != self.image_size:
            raise ValueError(f"the frame is {frame.shape[1]} x {frame.shape[0]} pixels but the "
                             f"calibration's images are {self.image_size[0]} x "
                             f"{self.image_size[1]}")
        if off is not None and _image(off, "the laser-off frame").shape != frame.shape:
            raise ValueError("the laser-on and laser-off frames differ in size")
        pose = as_matrix(base_from_hand, 4, "base_from_hand")
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ValueError(f"base_from_hand must be a finite 4 x 4 transform, got shape "
                             f"{pose.shape}")
        try:
            stripe = self._stripe(frame, off)
        except ValueError as e:
            if "leaves no pixel" not in str(e):
                raise
            stripe = None  # nothing above the automatic threshold: no stripe in this frame
        n = frame.shape[1]
        pixels = np.full((n, 2), np.nan)
        points = np.full((n, 3), np.nan)
        camera = np.full((n, 3), np.nan)
        status = np.full(n, PointStatus.NO_STRIPE, np.uint8)
        stripe_status = np.full(n, StripeStatus.NONE, np.uint8)
        if stripe is None:
            return Profile(pixels, points, camera, status, stripe_status)
        if stripe.direction != "columns":
            raise ValueError("Measurer measures a roughly horizontal stripe (scan lines are "
                             "image columns)")
        cols = np.asarray(stripe.position, np.intp)
        stripe_status[cols] = stripe.status
        is_found = stripe.status == StripeStatus.FOUND
        found = cols[is_found]
        if found.size:
            px = np.empty((found.size, 2))  # stripe.pixels: (u, v) of the found centres
            px[:, 0] = found
            px[:, 1] = stripe.centre[is_found]
            cam, ok = self._model.points_in_camera(px, on_invalid="mask")
            base_from_camera = pose @ self._hand_from_camera
            pixels[found] = px
            good, cam_ok = found[ok], cam[ok]
            camera[good] = cam_ok
            points[good] = cam_ok @ base_from_camera[:3, :3].T + base_from_camera[:3, 3]
            status[found] = np.where(ok, PointStatus.MEASURED, PointStatus.NO_POINT)
        return Profile(pixels, points, camera, status, stripe_status)

    def _stripe(self, frame: np.ndarray, off: np.ndarray | None) -> Any:
        """The frame's stripe: grey frames (or with a given channel) through the C++ options
        built once, colour ones through stripe_from_pair (which picks the laser's channel)."""
        from ..image.colour import is_colour
        from ..image.session import frames_stripe, stripe_from_pair
        from ..image.stripe import as_gray

        if self._channel is None and is_colour(frame):
            return stripe_from_pair(frame, off, **self._options)
        on_g = as_gray(frame, "the laser-on image", self._channel)
        off_g = None if off is None else as_gray(off, "the laser-off image", self._channel)
        return frames_stripe(on_g, off_g, self._core)[0]


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
