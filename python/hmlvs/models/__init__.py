"""Sensor models: the paper's 14-parameter model (``paper``) and its parameters (``params``).

Every model maps stripe pixels seen at hand poses to points in the robot base frame through
one C++ formulation (``hmlvs._core``); this package is its typed Python face."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
