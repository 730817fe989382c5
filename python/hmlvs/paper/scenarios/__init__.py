"""Measurement scenarios on rendered scenes: the paper's gauge-block check (Table 3) and a
cylinder scan, each from an honest calibration of a simulated sensor."""

from .common import HOME, PAPER_SENSOR, JointReadout, default_truth, simulated_calibration
from .cylinder import CylinderScan, HoleCheck, cylinder_scan, cylinder_scene, plot_cloud
from .gauge import (
    GAUGE_BLOCK,
    PAPER_TABLE3,
    CornerResult,
    GaugeBlockCheck,
    gauge_block,
    top_corners,
)

__all__ = [
    "CornerResult", "CylinderScan", "GAUGE_BLOCK", "GaugeBlockCheck", "HOME", "HoleCheck",
    "JointReadout", "PAPER_SENSOR", "PAPER_TABLE3", "cylinder_scan", "cylinder_scene",
    "default_truth", "gauge_block", "plot_cloud", "simulated_calibration", "top_corners"
]
