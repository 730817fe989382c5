"""Real captures as people take them: colour laser-on frames alone (a lit room and a dark
one, saturated stripe cores), the stripe kept to its one line, the board's corners on the
whole image, laser-only views, and robot poses that disagree with the images."""

from __future__ import annotations

from dataclasses import replace
import math

import cv2
from hmlvs.calibration.joint import calibrate_joint
from hmlvs.image.colour import colour_stripe, laser_feature
from hmlvs.image.corners import detect_board, flip_board_numbering, prefer_detected, sb_positions
from hmlvs.image.session import laser_channel, stripe_from_pair
from hmlvs.image.views import stripe_on_one_line
from hmlvs.sim.features import synthetic_views, transform
from hmlvs.sim.general import default_options, general_session, render_general_view
import numpy as np
import pytest

pytestmark = pytest.mark.scene


def _colour_frame(on: np.ndarray, off: np.ndarray, dark: bool, gain: float = 3.0) -> np.ndarray:
    """A BGR laser-on frame from a rendered pair: the board neutral (the laser-off frame in
    every channel, or black for a dark room), a red laser ``gain`` times the rendered
    stripe, whose core saturates the red channel and bleeds into green and blue there (a
    white core, as a colour camera shows an over-exposed red line)."""
    laser = np.clip(on.astype(float) - off, 0, None) * gain
    base = np.zeros_like(off, float) if dark else off.astype(float)
    red = base + laser
    bleed = np.clip(red - 255.0, 0, None) * 0.8  # light past the red top reaches G and B
    img = np.stack([base + 0.1 * laser + bleed, base + bleed, red], axis=2)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def rendered():
    s = general_session(views=3, seed=3)
    return s, [render_general_view(s, i, replace(default_options(), noise=1.0))
               for i in range(3)]


@pytest.mark.parametrize("dark", [False, True])
def test_colour_laser_on_frame_alone_gives_the_stripe(rendered, dark):
    s, frames = rendered
    for i, (on, off) in enumerate(frames):
        img = _colour_frame(on, off, dark)
        assert (img[..., 2] == 255).sum() > 200  # the core saturates ...
        assert laser_channel(img) == 2  # ... and the red channel is still the laser's
        st = stripe_from_pair(img, None)  # the colour path (no laser-off frame)
        assert np.array_equal(st.status, colour_stripe(img).status)
        truth = s.stripe_v[i]
        both = st.found & np.isfinite(truth) & s.stripe_on_board[i]
        assert both.sum() > 0.8 * s.stripe_on_board[i].sum()
        err = st.centre[both] - truth[both]
        # the rendered stripe's own centres are within 0.05 px RMS (test_stripe_quality);
        # the saturated, bleeding core costs more, but no bias between lit and dark rooms
        assert np.sqrt(np.mean(err ** 2)) < 0.3 and abs(err.mean()) < 0.1


def test_the_laser_feature_peaks_on_the_stripe(rendered):
    # what the opening leaves of the board (bits of white squares next to their corners) is
    # fainter than the laser: each column's brightest feature pixel is the stripe's
    s, frames = rendered
    on, off = frames[0]
    f = laser_feature(_colour_frame(on, off, dark=False)).astype(float)
    cols = np.nonzero(s.stripe_on_board[0])[0]
    near = np.abs(np.argmax(f[:, cols], axis=0) - s.stripe_v[0][cols]) < 3
    assert near.mean() > 0.95


def test_stripe_on_one_line_drops_stray_light():
    u = np.arange(100, 900, dtype=float)
    v = 300 + 0.05 * (u - 500) + 2e-5 * (u - 500) ** 2  # a line bent by distortion
    px = np.c_[u, v + np.random.default_rng(0).normal(0, 0.2, u.size)]
    assert stripe_on_one_line(px).all()
    stray = np.c_[np.arange(600, 700, dtype=float), np.full(100, 520.0)]  # a lit edge
    keep = stripe_on_one_line(np.vstack([px, stray]))
    assert keep[:len(px)].all() and not keep[len(px):].any()


def test_renders_keep_the_refined_corners_and_flips_carry_the_detected_ones(rendered):
    s, frames = rendered
    # the detector's own full-size positions, searched for as prefer_detected would
    corners = [sb_positions(off, detect_board(off, s.board)) for _, off in frames]
    n = s.board.rows * s.board.cols
    for c, truth in zip(corners, s.corners):
        assert c.detected is not None and np.isfinite(c.detected).all()
        back = flip_board_numbering(c).as_detected()
        # the flipped numbering's detected corner k is the original's n - 1 - k
        np.testing.assert_array_equal(back.pixels, c.detected[n - 1 - back.index])
        # on a render the refined corners are nearer the truth than the detector's own
        ref = np.linalg.norm(c.pixels - truth[c.index], axis=1)
        raw = np.linalg.norm(c.detected - truth, axis=1)
        assert np.sqrt(np.mean(ref ** 2)) < np.sqrt(np.mean(raw ** 2))
    # and the session's choice, by one camera's fit over the views, agrees
    pick, refined, raw, _ = prefer_detected(corners, s.sensor.image_size)
    assert not pick and refined < raw


def _noisy_poses(views, sigma_mm, sigma_rad, seed):
    rng = np.random.default_rng(seed)
    out = []
    for v in views:
        e = transform(rng.normal(0, sigma_rad, 3), rng.normal(0, sigma_mm, 3))
        out.append(replace(v, base_from_hand=v.base_from_hand @ e))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_uncertain_robot_poses_are_estimated_and_keep_the_camera(seed):
    views, board, truth, _ = synthetic_views(seed, n_views=16, corner_noise=0.1,
                                             laser_noise=0.1)
    noisy = _noisy_poses(views, 0.3, math.radians(0.1), seed + 10)
    exact = calibrate_joint(noisy, board, (1024, 768))
    soft = calibrate_joint(noisy, board, (1024, 768), robot_poses="uncertain")
    sig_mm, sig_deg = soft.robot_pose_sigma
    assert 0.15 < sig_mm < 0.6 and 0.05 < sig_deg < 0.2  # drawn with 0.3 mm and 0.1 deg
    f_true = truth.camera_matrix[0, 0]
    # the focal length: the exact chain bends it to absorb the poses' errors
    assert abs(soft.sensor.fx - f_true) < abs(exact.sensor.fx - f_true) + 0.5
    assert soft.corner_rms_px < 0.5 * exact.corner_rms_px
    # the exact chain says the poses disagree with the images; exact poses say nothing
    assert any("robot poses disagree with the images" in w for w in exact.warnings)
    assert not any("robot poses disagree" in w for w in soft.warnings)
    clean = calibrate_joint(views, board, (1024, 768))
    assert not any("robot poses disagree" in w for w in clean.warnings)
    assert all("robot_pose_error_mm" in pv for pv in soft.per_view.values())


def test_robot_poses_option_is_checked():
    views, board, _, _ = synthetic_views(2, n_views=4)
    assert calibrate_joint(views, board, (1024, 768)).robot_pose_sigma is None
    with pytest.raises(ValueError, match="robot_poses must be exact or uncertain"):
        calibrate_joint(views, board, (1024, 768), robot_poses="auto")


def test_a_laser_only_view_whose_stripe_is_all_dropped_does_not_stop_the_solve():
    views, board, _, _ = synthetic_views(3, n_views=6)
    far = np.c_[np.linspace(10, 1000, 50), np.full(50, 5.0)]  # nowhere near the laser plane
    dark = replace(views[0], id="dark", corner_pixels=np.zeros((0, 2)),
                   corner_index=np.zeros(0, int), laser_pixels=far)
    r = calibrate_joint(views + [dark], board, (1024, 768))
    assert r.per_view["dark"]["laser_pixels"] == 0


def test_colour_frames_find_corners_on_the_whole_image(rendered):
    """A red laser-on frame alone: the board's corners on the whole image in grey, not on
    the laser's channel, whose background estimate (an opening) eats the squares' corners."""
    s, frames = rendered
    on, off = frames[0]
    img = cv2.cvtColor(off, cv2.COLOR_GRAY2BGR)
    img[..., 2] = np.clip(img[..., 2].astype(int) + (on.astype(int) - off), 0, 255)
    from hmlvs.image.colour import board_gray

    c = detect_board(board_gray(img), s.board)
    assert len(c) == s.board.rows * s.board.cols
    assert np.median(np.linalg.norm(c.pixels - s.corners[0][c.index], axis=1)) < 0.2
