"""The physical set-up: the robot arm's kinematics (``robot``) and the checkerboard (``board``)."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
