"""bench/bench_tilt.py's metrics on known cases: hmlvs' row on exact corners of a tilted
sensor is the truth (its reprojection recomputed by OpenCV), and vision-calibration's row
(optional, the bench extra) runs and gives finite figures. No timing checks."""

from __future__ import annotations

from pathlib import Path
import sys

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
sys.path.insert(0, str(BENCH))

import bench_tilt as bt  # noqa: E402


def test_hmlvs_row_on_exact_corners_is_the_truth():
    got = bt.run_hmlvs(*bt._views(1, (0.1, 0.05), 0.0))
    assert got["mean_px"] < 1e-6, got
    assert abs(got["taux"] - 0.1) < 1e-6 and abs(got["tauy"] - 0.05) < 1e-6, got
    assert abs(got["fx"] - 1100) < 1e-3 and abs(got["cy"] - 384) < 1e-3, got
    # with noise the corners fit to it (0.1 px a coordinate: a mean distance of ~0.125 px)
    noisy = bt.run_hmlvs(*bt._views(1, (0.1, 0.05), 0.1))
    assert 0.1 < noisy["mean_px"] < 0.15, noisy


def test_vision_calibration_row_runs():
    if bt.vc is None:
        pytest.skip("vision-calibration is not installed (the bench extra)")
    got = bt.run_vc(*bt._views(1, (0.05, 0.02), 0.0))
    assert all(np.isfinite(v) for v in got.values()), got
