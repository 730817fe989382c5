"""hmlvs: calibrate and use a hand-mounted laser-vision sensor (camera + laser stripe on a
robot arm's last link), turning stripe pixels and joint readings into 3D points in the robot
base frame."""

from . import _core
from . import design
from . import simulate
from . import study
from .board import Checkerboard
from .identify import CalibrationResult, calibrate, initial_candidates
from .dataset import Dataset
from .model import (
    hand_from_camera,
    laser_plane_distance,
    objective,
    pixels_from_points,
    points_in_base,
    points_in_camera,
    project,
    residuals,
)
from .params import NAMES, Bounds, Parameters
from .robot import DHLink, Robot

__version__ = _core.__version__

__all__ = [
    "Bounds", "CalibrationResult", "Checkerboard", "DHLink", "Dataset", "NAMES", "Parameters",
    "Robot", "__version__", "calibrate", "design", "hand_from_camera", "initial_candidates",
    "laser_plane_distance", "objective",
    "pixels_from_points", "points_in_base", "points_in_camera", "project", "residuals",
    "simulate", "study",
]
