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
- ``hmlvs.sim``: simulated sessions and rendered images; ``hmlvs.paper``: the paper's studies

The names below are loaded on first use, so ``import hmlvs`` stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

from . import _core

__version__ = _core.__version__

# public name -> module (relative to hmlvs) that defines it
_EXPORTS = {
    # sensor model and parameters
    "NAMES": "models.params", "Bounds": "models.params", "Parameters": "models.params",
    "hand_from_camera": "models.paper", "laser_plane_distance": "models.paper",
    "objective": "models.paper", "pixels_from_points": "models.paper",
    "points_in_base": "models.paper", "points_in_camera": "models.paper",
    "project": "models.paper", "residuals": "models.paper",
    # set-up
    "DHLink": "geometry.robot", "Robot": "geometry.robot", "Checkerboard": "geometry.board",
    # data and files
    "Dataset": "data.dataset", "Calibration": "data.calibration_file",
    "load_calibration": "data.calibration_file",
    # identification and diagnostics
    "CalibrationResult": "calibration.solvers", "calibrate": "calibration.solvers",
    "initial_candidates": "calibration.solvers",
    "PsoOptions": "calibration.options", "LmOptions": "calibration.options",
    "RandomSearchOptions": "calibration.options",
    "Termination": "calibration.result", "PsoStage": "calibration.result",
    "LmStage": "calibration.result", "RandomSearchStage": "calibration.result",
    "Direction": "diagnostics.identifiability", "HmlvsDataWarning": "diagnostics.identifiability",
    "FlatDirectionWarning": "diagnostics.identifiability",
    "TooFewPointsWarning": "diagnostics.identifiability",
    "PoseVarietyWarning": "diagnostics.identifiability",
    "GimbalLockWarning": "diagnostics.identifiability",
    "AtBoundWarning": "diagnostics.identifiability",
    "DiagnosticsFailedWarning": "diagnostics.identifiability",
    "SetupWarning": "diagnostics.identifiability",
    "warning_category": "diagnostics.identifiability",
    "IdentifiabilityReport": "diagnostics.identifiability",
    "identifiability": "diagnostics.identifiability",
    "Combination": "diagnostics.uncertainty", "Uncertainty": "diagnostics.uncertainty",
    "uncertainty": "diagnostics.uncertainty",
    "RepeatabilityReport": "diagnostics.repeatability", "Spread": "diagnostics.repeatability",
    "repeatability": "diagnostics.repeatability",
    # image pipeline
    "StripeResult": "image.stripe", "StripeStatus": "image.stripe",
    "StripeOptions": "image.stripe",
    "difference_image": "image.stripe", "extract_stripe": "image.stripe",
    "Corners": "image.corners", "find_corners": "image.corners",
    "CalibrationPoints": "image.points", "calibration_points": "image.points",
    "ImageReport": "image.session", "dataset_from_images": "image.session",
    # measurement
    "PointCloud": "measurement.measure", "measure": "measurement.measure",
    "MeasureResult": "measurement.measure",
    # simulation and the paper's studies
    "simulate": "sim", "study": "paper.study",
}
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
