"""Files and data sets: calibration data sets, image manifests, calibration files."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
