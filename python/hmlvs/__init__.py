"""hmlvs: calibrate and use a hand-mounted laser-vision sensor (camera + laser stripe on a
robot arm's last link), turning stripe pixels and joint readings into 3D points in the robot
base frame.

The pipeline and where each stage lives:

- ``hmlvs.image``: laser on/off images -> stripe centres, board corners, calibration points
- ``hmlvs.data``: data sets, image manifests, calibration files
- ``hmlvs.models`` / ``hmlvs.geometry``: the sensor model (C++ core), robot kinematics, board
- ``hmlvs.calibration``: identification (PSO, Levenberg-Marquardt, random search)
- ``hmlvs.diagnostics``: identifiability, uncertainty, repeatability
- ``hmlvs.measurement``: stripes + poses -> point clouds
- ``hmlvs.report``: the HTML report; ``hmlvs.cli``: the command line
- ``hmlvs.errors``: the warnings and errors it raises
- ``hmlvs.sim``: simulated sessions and rendered images; ``hmlvs.paper``: the paper's studies

The names below are loaded on first use, so ``import hmlvs`` stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

from . import _core

__version__ = _core.__version__

# module (relative to hmlvs) -> the public names it defines
_PUBLIC = {
    "models.params": ("NAMES", "Bounds", "Parameters"),
    "models.paper": ("hand_from_camera", "laser_plane_distance", "objective", "pixels_from_points",
        "points_in_base", "points_in_camera", "project", "residuals"),
    "geometry.robot": ("DHLink", "Robot"),
    "data.dataset": ("Dataset",),
    "data.calibration_file": ("Calibration", "load_calibration"),
    "calibration.solvers": ("CalibrationResult", "initial_candidates"),
    "pipeline": ("calibrate", "calibrate_views"),
    "calibration.options": ("PsoOptions", "LmOptions", "RandomSearchOptions"),
    "calibration.result": ("Termination", "PsoStage", "LmStage", "RandomSearchStage"),
    "calibration.joint": ("JointCalibration", "calibrate_joint"),
    "models.opencv": ("OpenCvSensor",),
    "models.base": ("SensorModel",),
    "geometry.board": ("Checkerboard", "BoardSpec"),
    "data.views": ("ViewData",),
    "errors": ("BoardNotFoundError", "HmlvsDataWarning", "FlatDirectionWarning",
        "TooFewPointsWarning", "PoseVarietyWarning", "GimbalLockWarning", "AtBoundWarning",
        "DiagnosticsFailedWarning", "SetupWarning", "warning_category"),
    "diagnostics.identifiability": ("Direction", "IdentifiabilityReport", "identifiability"),
    "diagnostics.uncertainty": ("Combination", "Uncertainty", "uncertainty"),
    "diagnostics.repeatability": ("RepeatabilityReport", "Spread", "repeatability"),
    "image.stripe": ("StripeResult", "StripeStatus", "StripeOptions", "difference_image",
        "extract_stripe"),
    "image.corner_base": ("Corners", "CornerOptions"),
    "image.corners": ("find_corners",
        "detect_board", "flip_board_numbering"),
    "image.points": ("CalibrationPoints", "calibration_points"),
    "image.accounts": ("ImageReport",),
    "image.paper_session": ("dataset_from_images",),
    "measurement.measure": ("PointCloud", "measure", "MeasureResult"),
    "measurement.measurer": ("Measurer", "Profile", "PointStatus"),
    "sim": ("simulate",),
    "paper.study": ("study",),
}
_EXPORTS = {name: module for module, names in _PUBLIC.items() for name in names}
# modules reached as attributes: hmlvs.design.analyze(...), hmlvs.scenarios.cylinder_scan(...)
_MODULES = {"design": "paper.design", "scenarios": "paper.scenarios"}
_SUBPACKAGES = {"calibration", "data", "diagnostics", "geometry", "image", "measurement",
                "models", "paper", "report", "sim"}

__all__ = sorted([*_EXPORTS, *_MODULES, "__version__"])


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    elif name in _MODULES:
        value = importlib.import_module(f".{_MODULES[name]}", __name__)
    elif name in _SUBPACKAGES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module 'hmlvs' has no attribute '{name}'")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__, *_SUBPACKAGES])
