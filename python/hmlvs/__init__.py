"""hmlvs: calibrate and use a hand-mounted laser-vision sensor (camera + laser stripe on a
robot arm's last link), turning stripe pixels and joint readings into 3D points in the robot
base frame."""

from . import _core
from . import simulate
from .board import Checkerboard
from .dataset import Dataset
from .image import (
    CalibrationPoints,
    Corners,
    ImageReport,
    StripeResult,
    StripeStatus,
    calibration_points,
    dataset_from_images,
    difference_image,
    extract_stripe,
    find_corners,
)
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
    "Bounds", "CalibrationPoints", "Checkerboard", "Corners", "DHLink", "Dataset",
    "ImageReport", "NAMES", "Parameters", "Robot", "StripeResult", "StripeStatus",
    "calibration_points", "dataset_from_images", "difference_image", "extract_stripe",
    "find_corners",
    "__version__", "hand_from_camera", "laser_plane_distance", "objective",
    "pixels_from_points", "points_in_base", "points_in_camera", "project", "residuals",
    "simulate",
]
