"""The renderer's board shading runs in the C++ core (``hmlvs._core._shade_board``): it must
be the NumPy shading it replaced (``reference_render.py``), so that every rendered test scene
is the image it was before."""

import dataclasses

import hmlvs
from hmlvs import _core
from hmlvs._arrays import as_params
from hmlvs.sim import general as G
from hmlvs.sim import render as R
import numpy as np
import pytest
from reference_render import board_exposures_of_plane as numpy_exposures

pytestmark = pytest.mark.scene  # simulated sessions or rendered images


def assert_same_exposures(rays, bfc, board, o, plane):
    got = R.board_exposures(rays, bfc, board, o, plane)
    ref = numpy_exposures(rays, bfc, board, o, plane)
    for name, a, b in zip(("ambient", "laser", "distance"), got, ref):
        assert a.shape == b.shape, name
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=name)
        # the same operations up to their order and exp's last bits: measured at most
        # 4e-11 grey levels and 1.3e-13 mm
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9, equal_nan=True, err_msg=name)
    return got


@pytest.mark.parametrize("options", [
    R.RenderOptions(),
    R.RenderOptions(supersample=1, stripe_sigma=0.8, white=1.0, black=0.0, table=0.2),
    R.RenderOptions(supersample=5, spurious=0.3, margin=0.5),
], ids=["default", "one-sample", "reflection"])
def test_the_paper_sensor_is_shaded_as_by_numpy(options):
    s = hmlvs.simulate.session(num_poses=3, seed=1)
    q = as_params(s.truth)
    rays = R._sample_rays(q, s.image_size, options.supersample)
    poses = s.robot.poses(s.joints)[:3 if options.supersample < 5 else 1]  # 25 samples/px: 1
    seen = 0
    for pose in poses:
        bfc = R._board_from_camera(q, pose, s.board)
        ambient, laser, _ = assert_same_exposures(rays, bfc, s.board, options, R._laser_plane(q))
        seen += laser.max() > 0.5 * options.laser * options.black  # the stripe is in view
        assert ambient.max() > 0
    assert seen == len(poses)


def test_the_general_sensor_is_shaded_as_by_numpy():
    gs = G.general_session(views=2, seed=4)
    o = dataclasses.replace(G.default_options(), supersample=1)  # 1024 x 768: kept cheap
    rays = G.pixel_rays(gs.sensor, o.supersample)
    for i in range(2):
        _, laser, distance = assert_same_exposures(rays, gs.board_from_camera[i], gs.board, o,
                                                   gs.sensor.laser_plane)
        assert laser.max() > 0 and np.isfinite(distance).any()


def test_rendered_frames_are_the_frames_numpy_rendered(monkeypatch):
    options = R.RenderOptions(noise=1.0, speckle=0.1, vignetting=0.2, glare=True)
    native = R.render_session(seed=2, num_poses=2, options=options)
    monkeypatch.setattr(R, "board_exposures", numpy_exposures)
    ref = R.render_session(seed=2, num_poses=2, options=options)
    differ, pixels = 0, 0
    for a, b in zip([*native.on, *native.off], [*ref.on, *ref.off]):
        d = np.abs(a.astype(int) - b.astype(int))
        assert d.max() <= 1
        differ, pixels = differ + np.count_nonzero(d), pixels + d.size
    # a grey level could flip only where an exposure lies within 1e-9 of a rounding edge:
    # measured: 0 of 21.5 million pixels (3 sessions of 4 poses, 3 general-sensor sessions of
    # 3 views, both frames)
    assert differ <= 1e-6 * pixels
    np.testing.assert_allclose(native.stripe_v, ref.stripe_v, rtol=0, atol=1e-9, equal_nan=True)


def test_shading_refuses_bad_rays():
    shading = _core._BoardShading()
    with pytest.raises(ValueError, match="rays must be a \\(rows, cols, 3\\) array"):
        _core._shade_board(np.zeros((30, 30, 2)), np.eye(4), np.array([0, 1, 0, 0.0]), shading)
    with pytest.raises(ValueError, match="supersample"):
        _core._shade_board(np.zeros((31, 30, 3)), np.eye(4), np.array([0, 1, 0, 0.0]), shading)
