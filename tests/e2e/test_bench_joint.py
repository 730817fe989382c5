"""bench/bench_joint.py on a tiny problem: the comparison's code path runs and gives finite
results, and its accuracy metrics are right on known cases. vision-calibration is optional
(the bench extra): its part is skipped when it is not installed. No timing checks."""

from __future__ import annotations

import math
import os
from pathlib import Path
import subprocess
import sys

import cv2
from hmlvs.models.opencv import OpenCvSensor
from hmlvs.sim.features import synthetic_views, transform
import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
sys.path.insert(0, str(BENCH))

import bench_joint as bj  # noqa: E402


@pytest.fixture(scope="module")
def tiny() -> bj.Problem:
    return bj.make_problem(3, n_fit=6, n_test=2, stripe_samples=100)


def _with(sensor: OpenCvSensor, **changes) -> OpenCvSensor:
    d = {"camera_matrix": sensor.camera_matrix, "dist_coeffs": sensor.dist_coeffs,
         "image_size": sensor.image_size, "laser_plane": sensor.laser_plane,
         "hand_from_camera": sensor.hand_from_camera, "base_from_board": sensor.base_from_board}
    d.update(changes)
    return OpenCvSensor(**d)


def test_stripe_samples_sets_the_stripe_density():
    dense = synthetic_views(1, n_views=3, stripe_samples=800)[0]
    default = synthetic_views(1, n_views=3)[0]
    assert all(len(v.laser_pixels) <= 400 for v in default)
    assert all(len(v.laser_pixels) <= 800 for v in dense)
    # the first view's pose does not depend on it; its stripe is twice as dense
    np.testing.assert_allclose(dense[0].base_from_hand, default[0].base_from_hand)
    np.testing.assert_allclose(dense[0].corner_pixels, default[0].corner_pixels)
    assert len(dense[0].laser_pixels) > 1.9 * len(default[0].laser_pixels)


def test_truth_has_zero_error():
    p = bj.make_problem(2, n_fit=2, n_test=2, stripe_samples=60, laser_noise=0.0)
    acc = bj.accuracy(bj.truth_sensor(p.truth), p.truth, p.test, p.test_base)
    assert set(acc) == set(bj.METRICS)
    for name in bj.METRICS:
        assert acc[name] < 1e-6, (name, acc[name])


def test_metrics_on_known_errors():
    p = bj.make_problem(2, n_fit=2, n_test=1, stripe_samples=60)
    truth = bj.truth_sensor(p.truth)
    k = truth.camera_matrix.copy()
    k[0, 0] += 2.0
    k[1, 1] -= 1.0
    k[0, 2] += 3.0
    k[1, 2] += 4.0
    acc = bj.accuracy(_with(truth, camera_matrix=k), p.truth)
    assert acc["focal_px"] == pytest.approx(2.0)
    assert acc["principal_px"] == pytest.approx(5.0)
    assert "map_rms_mm" not in acc  # no held-out views given

    # the hand-eye transform turned by 0.5 degrees and moved by (0, 3, 4) mm
    hfc = truth.hand_from_camera @ transform([0, 0, math.radians(0.5)], [0, 0, 0])
    hfc[:3, 3] += [0.0, 3.0, 4.0]
    acc = bj.accuracy(_with(truth, hand_from_camera=hfc), p.truth)
    assert acc["handeye_mm"] == pytest.approx(5.0)
    assert acc["handeye_deg"] == pytest.approx(0.5)
    assert acc["focal_px"] == 0 and acc["plane_deg"] == 0

    # the plane turned by 0.2 degrees, its distance 0.3 mm larger; the sign of (n, d) is free
    n, d = p.truth.plane[:3], p.truth.plane[3]
    axis = np.cross(n, [1.0, 0.0, 0.0])
    n2 = cv2.Rodrigues(axis / np.linalg.norm(axis) * math.radians(0.2))[0] @ n
    for sign in (1.0, -1.0):
        acc = bj.accuracy(_with(truth, laser_plane=sign * np.r_[n2, d - 0.3]), p.truth)
        assert acc["plane_deg"] == pytest.approx(0.2, rel=1e-9)
        assert acc["plane_mm"] == pytest.approx(0.3, rel=1e-9)


def test_map_error_sees_a_wrong_hand_eye_translation():
    p = bj.make_problem(2, n_fit=2, n_test=2, stripe_samples=60, laser_noise=0.0)
    truth = bj.truth_sensor(p.truth)
    hfc = truth.hand_from_camera.copy()
    hfc[:3, 3] += [1.0, 0.0, 0.0]
    d = bj.map_errors(_with(truth, hand_from_camera=hfc), p.test, p.test_base)
    np.testing.assert_allclose(d, 1.0, atol=1e-6)


def test_replace_section():
    other = "# results\n\n## Stripe extraction\n\nrows\n"
    one = bj.SECTION + "\n\nfirst\n"
    two = bj.SECTION + "\n\nsecond\n"
    text = bj.replace_section(other, one)
    assert text.startswith(other) and text.endswith(one)
    again = bj.replace_section(text + "\n## Later\n\nkept\n", two)
    assert "first" not in again and "second" in again
    assert again.startswith(other) and again.endswith("## Later\n\nkept\n")


def test_hmlvs_calibration_is_finite(tiny):
    acc = bj.accuracy(bj.run_hmlvs(tiny), tiny.truth, tiny.test, tiny.test_base)
    assert all(np.isfinite(v) for v in acc.values()), acc
    assert acc["map_rms_mm"] < 1.0


def test_vision_calibration_is_finite(tiny):
    vc = pytest.importorskip("vision_calibration")
    m = transform([0.3, -0.2, 1.0], [100.0, -20.0, 500.0])
    np.testing.assert_allclose(bj.pose_from_vc(bj.pose_to_vc(m)), m, atol=1e-12)
    quarter = bj.pose_to_vc(transform([0, 0, math.pi / 2], [1000.0, 0, 0]))
    np.testing.assert_allclose(quarter.rotation_xyzw, [0, 0, math.sqrt(0.5), math.sqrt(0.5)])
    assert quarter.translation_xyz == pytest.approx((1.0, 0.0, 0.0))  # metres

    res, payload = bj.run_vc_joint(tiny, raw=True)
    assert isinstance(res, vc.RigHandeyeLaserlineResult)
    acc = bj.accuracy(bj.vc_sensor(res), tiny.truth, tiny.test, tiny.test_base)
    assert all(np.isfinite(v) for v in acc.values()), acc
    # the conversion of its estimate agrees with its own pixel -> gripper mapping
    assert bj.vc_native_check(res, payload, tiny, n=5) < 1e-6

    acc = bj.accuracy(bj.vc_pipeline_sensor(bj.run_vc_pipeline(tiny)), tiny.truth, tiny.test,
                      tiny.test_base)
    assert all(np.isfinite(v) for v in acc.values()), acc


def test_section_without_vision_calibration():
    """Without vision-calibration the section says so and still has hmlvs' numbers."""
    env = dict(os.environ, HMLVS_BENCH_NO_VC="1")
    out = subprocess.run([sys.executable, str(BENCH / "bench_joint.py"), "--seeds", "1",
                          "--reps", "1"], env=env, check=True, capture_output=True,
                         text=True).stdout
    assert out.startswith(bj.SECTION)
    assert "vision-calibration is not installed" in out
    assert "| hmlvs, seed 1 |" in out and "| hmlvs `calibrate_joint` |" in out
    assert "vc joint" not in out.split("| calibration |")[1]
