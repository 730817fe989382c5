"""The general sensor's simulated sessions and rendered images (hmlvs.sim.general).

The truth (corner pixels, stripe rows) comes from cv2.projectPoints; the images from pixel
rays by cv2.undistortPoints. The image pipeline must recover the truth from the images."""

from __future__ import annotations

import math

import cv2
import hmlvs
from hmlvs.data.manifest import read_manifest
from hmlvs.geometry.board import Checkerboard
from hmlvs.image.corners import detect_board, flip_board_numbering
from hmlvs.sim import RenderOptions
from hmlvs.sim.general import (
    RAY_TOLERANCE,
    example_sensor,
    general_session,
    pixel_rays,
    render_general_session,
    render_general_view,
)
import numpy as np
import pytest

pytestmark = pytest.mark.slow  # the module's shared sessions take long to make

SEEDS = (0, 1, 2)
VIEWS = 3  # per seed: 9 rendered views in all


@pytest.fixture(scope="module")
def rendered() -> list:
    """(session, view, on, off) for VIEWS views of each seed."""
    out = []
    for seed in SEEDS:
        s = general_session(views=VIEWS, seed=seed)
        for i in range(VIEWS):
            on, off = render_general_view(s, i)
            out.append((s, i, on, off))
    return out


def test_example_sensor_is_the_specified_test_sensor():
    s = example_sensor()
    assert s.image_size == (1024, 768)
    assert s.fx == pytest.approx(1100.0, rel=0.01) and s.fy == pytest.approx(1100.0, rel=0.01)
    np.testing.assert_allclose(s.dist_coeffs[:2], [-0.165, 0.05])
    # the laser plane's normal is 1.5 degrees out of the camera's y-z plane
    assert math.degrees(math.asin(abs(s.laser_plane[0]))) == pytest.approx(1.5, abs=0.01)
    # hand_from_camera: ~90 degrees (+3) about the flange z axis, translation (60, 0, -45)
    r = s.hand_from_camera[:3, :3]
    assert math.degrees(math.atan2(r[1, 0], r[0, 0])) == pytest.approx(93.0, abs=0.1)
    np.testing.assert_allclose(s.hand_from_camera[:3, 3], [60.0, 0.0, -45.0])


def test_pixel_rays_reproject_within_a_thousandth_of_a_pixel():
    s = example_sensor()
    rays = pixel_rays(s, 1)
    h, w = s.image_size[1], s.image_size[0]
    assert rays.shape == (h, w, 3)
    # every pixel of the outer rows and columns, where the distortion is strongest
    sel = np.zeros((h, w), bool)
    sel[[0, -1], :] = True
    sel[:, [0, -1]] = True
    vv, uu = np.nonzero(sel)
    back, _ = cv2.projectPoints(rays[sel].reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                s.camera_matrix, s.dist_coeffs)
    err = np.abs(back.reshape(-1, 2) - np.stack([uu, vv], axis=1)).max()
    assert err < RAY_TOLERANCE
    # and the distortion is not negligible there: the corner pixel moves by ~38 px
    corner = rays[0, 0, :2] * [s.fx, s.fy] + [s.cx, s.cy]
    assert np.linalg.norm(corner) > 30


@pytest.mark.parametrize("seed", [0, 5])
def test_session_geometry(seed):
    s = general_session(views=20, seed=seed)
    assert len(s) == 20
    w, h = s.sensor.image_size
    hfc = s.sensor.hand_from_camera
    bfb = s.sensor.base_from_board
    for i in range(len(s)):
        # the robot pose closes the loop base -> hand -> camera -> board -> base
        np.testing.assert_allclose(s.base_from_hand[i] @ hfc, bfb @ s.board_from_camera[i],
                                   atol=1e-9)
        # tilt of the optical axis from the board normal within 10-40 degrees
        z = s.board_from_camera[i][:3, 2]
        assert 10.0 - 1e-9 <= math.degrees(math.acos(-z[2])) <= 40.0 + 1e-9
        # every corner inside the image, with margin
        c = s.corners[i]
        assert (c.min(axis=0) > 20).all() and c[:, 0].max() < w - 21 and c[:, 1].max() < h - 21
        # the laser line lies inside the image and crosses the board
        on = s.stripe_on_board[i]
        v = s.stripe_v[i][on]
        assert on.sum() > 200
        assert np.isfinite(v).all() and v.min() > 20 and v.max() < h - 21
        px = s.stripe_pixels(i)
        assert len(px) == on.sum() and np.all(px[:, 0] == np.nonzero(on)[0])
    # the views differ: roll about the optical axis spans a wide range
    rolls = [math.degrees(math.atan2(c[0, 1] - c[1, 1], c[1, 0] - c[0, 0]))
             for c in s.corners]
    assert np.ptp(rolls) > 60
    # the board's corners in the base frame agree with base_from_board
    np.testing.assert_allclose(s.board.corners()[0], bfb[:3, 3])
    np.testing.assert_allclose(s.board.corners()[-1], bfb[:3, :3] @ np.array(
        [(s.board.rows - 1) * s.board.square, (s.board.cols - 1) * s.board.square, 0]) +
        bfb[:3, 3])


def test_true_stripe_lies_on_the_laser_plane_and_the_board():
    """Independent check of the truth: back-project each stripe pixel with
    cv2.undistortPoints onto the board plane; the point must lie on the laser plane."""
    s = general_session(views=4, seed=3)
    plane = s.sensor.laser_plane
    crit = (cv2.TERM_CRITERIA_COUNT, 30, 0.0)
    for i in range(len(s)):
        u = np.nonzero(np.isfinite(s.stripe_v[i]))[0]
        px = np.stack([u, s.stripe_v[i][u]], axis=1).astype(float)
        xy = cv2.undistortPoints(px.reshape(-1, 1, 2), s.sensor.camera_matrix,
                                 s.sensor.dist_coeffs, None, None, None, crit).reshape(-1, 2)
        ray = np.hstack([xy, np.ones((len(xy), 1))])
        bfc = s.board_from_camera[i]
        rb = ray @ bfc[:3, :3].T
        t = -bfc[2, 3] / rb[:, 2]
        cam = ray * t[:, None]
        assert np.abs(cam @ plane[:3] + plane[3]).max() < 1e-6


def test_opencv_corners_agree_with_the_truth(rendered):
    for s, i, _, off in rendered:
        ok, found = cv2.findChessboardCornersSB(
            off, (s.board.cols, s.board.rows),
            flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
        assert ok, (s.seed, i)
        found = found.reshape(-1, 2)
        truth = s.corners[i]
        d = np.linalg.norm(found[:, None] - truth[None], axis=2).min(axis=1)
        assert len(found) == len(truth)
        # measured: 0.03-0.06 px RMS
        assert np.sqrt(np.mean(d ** 2)) < 0.3, (s.seed, i)


def test_detect_board_numbers_rendered_views_like_the_truth(rendered):
    """Views rolled by up to +-60 degrees: the top-left rule numbers every one as the board
    does, and the refined corners are within 0.3 px RMS (measured 0.03-0.05)."""
    for s, i, _, off in rendered:
        c = detect_board(off, s.board)
        assert len(c) == s.board.rows * s.board.cols
        err = np.linalg.norm(c.pixels - s.corners[i][c.index], axis=1)
        assert np.sqrt(np.mean(err ** 2)) < 0.3, (s.seed, i)


def test_stripe_centres_agree_with_the_truth(rendered):
    """All board columns count, square edges included: the albedo steps under the stripe
    (and the speckle) cost 0.10-0.22 px RMS, at most ~1 px in a column."""
    for s, i, on, off in rendered:
        st = hmlvs.extract_stripe(hmlvs.difference_image(on, off))
        board_cols = s.stripe_on_board[i]
        found = board_cols & st.found
        assert found.sum() >= 0.95 * board_cols.sum(), (s.seed, i)
        err = st.centre[found] - s.stripe_v[i][found]
        assert np.sqrt(np.mean(err ** 2)) < 0.3, (s.seed, i)
        assert np.median(np.abs(err)) < 0.15, (s.seed, i)
        # dividing by the laser-off frame removes the albedo steps' pull: 0.09-0.12 px RMS
        # remain (speckle, noise)
        st = hmlvs.extract_stripe(hmlvs.difference_image(on, off, normalize=True))
        found = board_cols & st.found
        assert found.sum() >= 0.95 * board_cols.sum(), (s.seed, i)
        err = st.centre[found] - s.stripe_v[i][found]
        assert np.sqrt(np.mean(err ** 2)) < 0.2, (s.seed, i)


def test_laser_light_depends_on_the_albedo(rendered):
    s, i, on, off = rendered[0]
    d = hmlvs.difference_image(on, off).astype(float)
    st = hmlvs.extract_stripe(d.astype(np.uint8))
    cols = np.nonzero(s.stripe_on_board[i] & st.found)[0]
    rows = np.rint(s.stripe_v[i][cols]).astype(int)
    peak = d[rows, cols]
    dark = off[rows, cols] < np.median(off[rows, cols])
    # black squares (albedo 0.25) return far less laser light than white ones (0.85)
    assert peak[dark].mean() < 0.6 * peak[~dark].mean()


def test_same_seed_gives_identical_images_and_another_seed_does_not():
    a = general_session(views=2, seed=7)
    b = general_session(views=2, seed=7)
    np.testing.assert_array_equal(a.base_from_hand, b.base_from_hand)
    on1, off1 = render_general_view(a, 1)
    on2, off2 = render_general_view(b, 1)
    assert on1.tobytes() == on2.tobytes() and off1.tobytes() == off2.tobytes()
    c = general_session(views=2, seed=8)
    assert not np.allclose(c.base_from_hand, a.base_from_hand)


def test_written_session_reads_back(tmp_path):
    s = general_session(views=2, seed=4, board=Checkerboard(rows=6, cols=8, square=20.0))
    r = render_general_session(s, tmp_path / "gen")
    entries, doc, folder = read_manifest(r.manifest)
    assert doc["board"] == {"rows": 6, "cols": 8, "square": 20.0}
    assert doc["image_size"] == [1024, 768]
    assert [e["id"] for e in entries] == r.ids
    for k, e in enumerate(entries):
        np.testing.assert_allclose(np.array(e["pose"]), s.base_from_hand[k], atol=1e-9)
        assert "joints" not in e
        img = cv2.imread(str(folder / e["on"]), cv2.IMREAD_UNCHANGED)
        assert img.tobytes() == r.on[k].tobytes()
    assert (folder / "truth.json").is_file()


def test_a_view_rolled_past_90_degrees_is_numbered_turned_and_flip_restores_it():
    """detect_board's top-left rule is only consistent while views roll by less than ~90
    degrees: a camera rolled ~170 degrees sees r0c0 at the bottom right and gets the
    numbering turned by 180 degrees; flip_board_numbering restores it."""
    s = general_session(views=1, seed=11, roll_deg=(160.0, 175.0))
    _, off = render_general_view(s, 0)
    c = detect_board(off, s.board)
    wrong = np.linalg.norm(c.pixels - s.corners[0][c.index], axis=1)
    assert np.median(wrong) > 20  # labels off by whole squares
    f = flip_board_numbering(c)
    err = np.linalg.norm(f.pixels - s.corners[0][f.index], axis=1)
    assert np.sqrt(np.mean(err ** 2)) < 0.3


def test_speckle_modulates_the_laser_light_only():
    s = general_session(views=1, seed=2)
    plain = RenderOptions(noise=0.0, speckle=0.0)
    speckled = RenderOptions(noise=0.0, speckle=0.3)
    on0, off0 = render_general_view(s, 0, plain)
    on1, off1 = render_general_view(s, 0, speckled)
    assert off0.tobytes() == off1.tobytes()  # the ambient frame has no speckle
    d0 = hmlvs.difference_image(on0, off0).astype(float)
    d1 = hmlvs.difference_image(on1, off1).astype(float)
    lit = d0 > 20
    ratio = d1[lit] / d0[lit]
    assert ratio.std() > 0.1  # a grainy stripe ...
    assert abs(np.median(ratio) - 1.0) < 0.1  # ... of about the same brightness
    with pytest.raises(ValueError, match="speckle must be a finite number >= 0"):
        RenderOptions(speckle=-0.1)
