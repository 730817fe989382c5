"""The views of a joint calibration (model "opencv"): per image, the board corners found,
the stripe pixels and the robot pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ViewData:
    """What one view contributes: its corners, its stripe pixels and (optionally) its pose.

    corner_pixels : (k, 2) detected corners; corner_index : (k,) their board indices
    laser_pixels : (m, 2) stripe pixels (any that miss the board are dropped by the solve's
        set-up); base_from_hand : the robot's 4x4 pose, None without a robot
    """

    id: str
    corner_pixels: np.ndarray
    corner_index: np.ndarray
    laser_pixels: np.ndarray
    base_from_hand: np.ndarray | None = None
