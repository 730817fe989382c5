"""Reports: the self-contained HTML calibration report."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
