"""The one interface every sensor model offers to measurement, export and reports.

Two models implement it: :class:`hmlvs.models.paper.PaperSensor` (the paper's 14 parameters)
and :class:`hmlvs.models.opencv.OpenCvSensor` (OpenCV intrinsics, a 3-DoF laser plane, any
hand-eye rotation). Both evaluate in the C++ core.
"""

from __future__ import annotations

from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

OnInvalid = Literal["raise", "mask"]
MODEL_NAMES = ("opencv", "paper")


def check_on_invalid(on_invalid: str) -> bool:
    """True for "raise", False for "mask"; a ValueError otherwise."""
    if on_invalid not in ("raise", "mask"):
        raise ValueError(f"on_invalid must be 'raise' or 'mask', got {on_invalid!r}")
    return on_invalid == "raise"


@runtime_checkable
class SensorModel(Protocol):
    """A calibrated sensor: stripe pixels -> laser points, in the camera or the robot base.

    ``points_in_camera`` / ``points_in_base`` return ``(points (m, 3) mm, valid (m,) bool)``.
    A pixel whose ray misses the laser plane raises a ValueError naming it, or with
    ``on_invalid="mask"`` gets ``valid=False`` and a NaN row.
    """

    model: str

    def points_in_camera(self, pixels: Any, on_invalid: OnInvalid = "raise"
                         ) -> tuple[np.ndarray, np.ndarray]: ...

    def points_in_base(self, pixels: Any, poses: Any, on_invalid: OnInvalid = "raise"
                       ) -> tuple[np.ndarray, np.ndarray]: ...

    def hand_from_camera_matrix(self) -> np.ndarray: ...
