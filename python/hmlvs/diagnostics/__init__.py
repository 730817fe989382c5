"""What a calibration determines: identifiability, uncertainty and repeatability."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
