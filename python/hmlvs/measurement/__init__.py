"""Measuring with a calibrated sensor: stripes + poses -> point clouds."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
