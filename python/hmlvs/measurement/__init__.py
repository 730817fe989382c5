"""Measuring with a calibrated sensor: stripes + poses -> point clouds."""
