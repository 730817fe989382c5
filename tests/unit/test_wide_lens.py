"""Lenses beyond the five-term Brown-Conrady model: OpenCV's rational model (k4, k5, k6: the
denominator wide lenses need) and thin prism (s1 to s4), in the general model's projection,
undistortion and calibration, checked against OpenCV itself."""

from __future__ import annotations

from conftest import assert_lens_matches_opencv
import cv2
from hmlvs.calibration.joint import calibrate_joint
from hmlvs.data.export import export_text
from hmlvs.diagnostics.checks import LENS_RATIO_MIN, lens_check
from hmlvs.geometry.board import BoardSpec
from hmlvs.models.opencv import CLASSIC_DISTORTION, OpenCvSensor
from hmlvs.sim.features import Truth, default_truth, synthetic_views
import numpy as np
import pytest
import yaml

K = np.array([[350.0, 0, 512], [0, 352, 384], [0, 0, 1.0]])
#: a wide lens of the rational model, a strong barrel: a point seen at the image's left or right
#: edge lies 355-362 px further out through a pinhole
RATIONAL = np.array([1.2, 0.3, 0.0005, -0.0003, 0.0, 1.6, 0.6, 0.0])
#: the same with the thin prism's four terms
PRISM = np.r_[RATIONAL, 0.002, -0.001, 0.0015, 0.0008]
RATIONAL_TERMS = (*CLASSIC_DISTORTION, "k4", "k5", "k6")


def _sensor(dist) -> OpenCvSensor:
    t = default_truth()
    return OpenCvSensor(K, dist, (1024, 768), t.plane, t.hand_from_camera)


@pytest.mark.parametrize("dist", [RATIONAL, PRISM], ids=["rational", "thin_prism"])
def test_projection_and_undistortion_match_opencv(dist):
    assert_lens_matches_opencv(_sensor(dist), 0.9, 3)


def test_a_sensor_holds_opencv_s_lengths():
    assert _sensor(np.r_[RATIONAL[:5], np.zeros(7)]).dist_coeffs.size == 5
    assert _sensor(RATIONAL).dist_coeffs.size == 8
    assert _sensor(PRISM).dist_coeffs.size == 12
    s = _sensor(PRISM)
    np.testing.assert_array_equal(OpenCvSensor.from_dict(s.to_dict()).dist_coeffs, PRISM)
    assert s.intrinsics()["s4"] == PRISM[11]
    np.testing.assert_array_equal(s.intrinsics_vector()[4:], np.r_[PRISM, 0.0, 0.0])
    with pytest.raises(ValueError, match="4, 5, 8, 12 or 14 numbers"):
        _sensor(np.zeros(6))
    with pytest.raises(ValueError, match="dist_coeffs must be finite"):
        _sensor(np.r_[RATIONAL[:7], np.nan])


def test_exports_name_the_lens_model():
    rational = yaml.safe_load(export_text(_sensor(RATIONAL), "ros"))
    assert rational["distortion_model"] == "rational_polynomial"
    assert rational["distortion_coefficients"]["data"] == pytest.approx(RATIONAL.tolist())
    assert yaml.safe_load(export_text(_sensor(RATIONAL[:5]), "ros"))["distortion_model"] == \
        "plumb_bob"
    with pytest.raises(ValueError, match="no distortion model for the thin prism"):
        export_text(_sensor(PRISM), "ros")
    fs = cv2.FileStorage(export_text(_sensor(PRISM), "opencv"),
                         cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    np.testing.assert_allclose(fs.getNode("distortion_coefficients").mat().ravel(), PRISM)


def test_a_wide_lens_is_calibrated_with_the_rational_model():
    """Boards spread towards the image's edges (x up to ~880 of 1024 px) seen through a wide
    lens: the five-term lens cannot follow it there, the rational model fits the corners to
    their noise (0.1 px a coordinate, 0.141 px RMS) and the stripe to its points."""
    t = default_truth()
    truth = Truth(K, RATIONAL, t.hand_from_camera, t.base_from_board, t.plane)
    for seed in (0, 3):  # the two seeds of 0-3 whose boards reach furthest out
        views, board, _, laser_base = synthetic_views(seed, n_views=20, truth=truth,
                                                      board=BoardSpec(7, 11, 25.0), spread=200)
        fits = {}
        for terms in (CLASSIC_DISTORTION, RATIONAL_TERMS):
            r = calibrate_joint(views, board, (1024, 768), distortion=terms)
            errs = [np.linalg.norm(r.sensor.points_in_base(
                v.laser_pixels, np.repeat(v.base_from_hand[None], len(v.laser_pixels), 0))[0]
                - pts, axis=1) for v, pts in zip(views, laser_base)]
            fits[len(terms)] = (r.corner_rms_px, float(np.sqrt(np.mean(np.concatenate(errs)
                                                                          ** 2))), r)
        # measured: five terms 0.333 / 0.397 px and 0.61 / 0.83 mm; rational 0.141 px and
        # 0.25 / 0.26 mm (the stripe's 0.1 px noise alone gives ~0.2 mm here)
        assert fits[8][0] < 0.16, fits[8][:2]
        assert fits[8][1] < 0.35, fits[8][:2]
        assert fits[5][0] > 2 * fits[8][0] and fits[5][1] > 2 * fits[8][1], (fits[5][:2],
                                                                             fits[8][:2])
        assert fits[8][2].sensor.dist_coeffs.size == 8
        assert "k4" in fits[8][2].summary() and "k4" not in fits[5][2].summary()
        # the verdict's lens check names the terms to add to the five; a calibration that has
        # them is checked against the tilted sensor alone, and passes (measured 1.0)
        (check,) = lens_check(fits[5][2], views, board)
        assert not check.ok and check.value < LENS_RATIO_MIN
        assert "--distortion k1,k2,p1,p2,k3,k4,k5,k6" in check.problem
        (check,) = lens_check(fits[8][2], views, board)
        assert check.ok and check.value > 0.95 and "tilted sensor's" in check.problem


def test_a_five_term_lens_passes_the_lens_check():
    for seed in (0, 1):
        views, board, _, _ = synthetic_views(seed, n_views=12)
        (check,) = lens_check(calibrate_joint(views, board, (1024, 768)), views, board)
        # the rational terms only fit the corners' noise: measured 0.99-1.0 of the RMS
        assert check.ok and check.value > 0.95, check


def test_a_wide_lens_held_from_an_earlier_calibration_is_used_whole():
    """A robot session started from a bench calibration of a wide lens (`--initial`): the
    held camera's rational terms are used (not dropped with the five-term lens's shortcut),
    so the corners fit to their noise through the chain."""
    t = default_truth()
    truth = Truth(K, RATIONAL, t.hand_from_camera, t.base_from_board, t.plane)
    views, board, _, laser_base = synthetic_views(0, n_views=12, truth=truth,
                                                  board=BoardSpec(7, 11, 25.0), spread=200)
    held = OpenCvSensor(K, RATIONAL, (1024, 768), t.plane, np.eye(4))
    r = calibrate_joint(views, board, (1024, 768), camera=held)
    assert r.corner_rms_px < 0.16, r.corner_rms_px  # 0.1 px a coordinate: 0.141 px RMS
    np.testing.assert_allclose(r.sensor.dist_coeffs, RATIONAL)
    assert np.abs(r.sensor.hand_from_camera[:3, 3] - t.hand_from_camera[:3, 3]).max() < 0.5
