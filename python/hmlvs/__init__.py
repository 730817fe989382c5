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

# module (relative to hmlvs) -> the public names it defines. Everything else is reached through
# its subpackage (``hmlvs.models.paper.residuals``, ``hmlvs.errors.FlatDirectionWarning``);
# the paper's studies live under ``hmlvs.paper``.
_PUBLIC = {
    "pipeline": ("calibrate",),
    "data.calibration_file": ("Calibration",),
    "measurement.measurer": ("Measurer",),
    "measurement.measure": ("measure", "PointCloud"),
    "models.params": ("Parameters", "Bounds"),
    "models.opencv": ("OpenCvSensor",),
    "geometry.robot": ("Robot",),
    "geometry.board": ("Checkerboard", "BoardSpec"),
    "data.dataset": ("Dataset",),
    "calibration.options": ("PsoOptions", "LmOptions", "RandomSearchOptions"),
    "diagnostics.identifiability": ("identifiability",),
    "diagnostics.uncertainty": ("uncertainty",),
    "diagnostics.repeatability": ("repeatability",),
    "image.corners": ("detect_board",),
    "image.stripe": ("StripeOptions", "difference_image", "extract_stripe"),
    "errors": ("HmlvsDataWarning",),
    "sim": ("simulate",),
}
_EXPORTS = {name: module for module, names in _PUBLIC.items() for name in names}
_SUBPACKAGES = {"calibration", "data", "diagnostics", "errors", "geometry", "image",
                "measurement", "models", "paper", "pipeline", "report", "sim"}

__all__ = sorted([*_EXPORTS, "__version__"])


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    elif name in _SUBPACKAGES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module 'hmlvs' has no attribute '{name}'")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__, *_SUBPACKAGES])
