"""hmlvs: calibrate and use a hand-mounted laser-vision sensor (camera + laser stripe on a
robot arm's last link), turning stripe pixels and joint readings into 3D points in the robot
base frame."""

from . import _core
from . import design
from . import scenes
from . import simulate
from ._identifiability import Direction, HmlvsDataWarning, IdentifiabilityReport, identifiability
from ._repeatability import RepeatabilityReport, Spread, repeatability
from ._uncertainty import Combination, Uncertainty, uncertainty
from . import study
from .board import Checkerboard
from .calibration_file import Calibration, load_calibration
from .dataset import Dataset
from .identify import CalibrationResult, calibrate, initial_candidates
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
from .measure import PointCloud, measure
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
    "NAMES", "Bounds", "Calibration", "CalibrationPoints", "CalibrationResult", "Checkerboard",
    "Combination", "Corners", "DHLink", "Dataset", "Direction", "HmlvsDataWarning",
    "IdentifiabilityReport", "ImageReport", "Parameters", "PointCloud", "RepeatabilityReport",
    "Robot", "Spread", "StripeResult", "StripeStatus", "Uncertainty", "__version__",
    "calibrate", "calibration_points", "dataset_from_images", "design", "difference_image",
    "extract_stripe", "find_corners", "hand_from_camera", "identifiability",
    "initial_candidates", "laser_plane_distance", "load_calibration", "measure", "objective",
    "pixels_from_points", "points_in_base", "points_in_camera", "project", "repeatability",
    "residuals", "scenes", "simulate", "study", "uncertainty",
]
