"""Simulated data: the random-pixel protocol and the checkerboard session."""

import numpy as np

import hmlvs


def test_simulate_defaults_and_seed():
    a = hmlvs.simulate(seed=3)
    b = hmlvs.simulate(seed=3)
    assert (len(a.fit), len(a.test)) == (50, 50)
    np.testing.assert_array_equal(a.dataset.points, b.dataset.points)
    assert not np.array_equal(a.dataset.points, hmlvs.simulate(seed=4).dataset.points)
    # noise-free: the truth reproduces every reference point
    e = hmlvs.residuals(a.truth, a.dataset.pixels, a.dataset.poses, a.dataset.points)
    assert np.abs(e).max() < 1e-9


def test_simulate_noise_levels():
    sim = hmlvs.simulate(n=4000, seed=5, pixel_noise=0.5, point_noise=0.2)
    clean = hmlvs.simulate(n=4000, seed=5)
    dpx = sim.dataset.pixels - clean.dataset.pixels
    assert abs(dpx.std() - 0.5) < 0.02 and abs(dpx.mean()) < 0.02


def test_session_puts_corners_on_the_stripe():
    s = hmlvs.simulate.session(num_poses=12, seed=2)
    ds = s.dataset
    assert ds.num_poses == 12 and len(ds) >= 12
    # poses are the forward kinematics of the stored joint readings
    np.testing.assert_allclose(ds.poses, s.robot.poses(ds.joints), atol=1e-12)
    # every reference point is a board corner, on the laser plane, seen at its stored pixel
    corners = s.board.corners()
    d = np.min(np.linalg.norm(ds.points[:, None, :] - corners[None], axis=2), axis=1)
    assert d.max() < 1e-9
    assert np.abs(hmlvs.laser_plane_distance(s.truth, ds.points, ds.poses)).max() < 1e-7
    e = hmlvs.residuals(s.truth, ds.pixels, ds.poses, ds.points)
    assert np.linalg.norm(e, axis=1).max() < 1e-6
    assert ((ds.pixels >= 0) & (ds.pixels <= [639, 479])).all()


def test_dataset_roundtrip(tmp_path):
    ds = hmlvs.simulate.session(num_poses=4, seed=1).dataset
    for suffix in (".npz", ".json"):
        path = ds.save(tmp_path / f"d{suffix}")
        back = hmlvs.Dataset.load(path)
        np.testing.assert_array_equal(back.ids, ds.ids)
        np.testing.assert_allclose(back.points, ds.points, rtol=0, atol=0)
        np.testing.assert_allclose(back.poses, ds.poses, rtol=0, atol=0)
        np.testing.assert_allclose(back.joints, ds.joints, rtol=0, atol=0)
        np.testing.assert_array_equal(back.pose_index, ds.pose_index)


def test_split_and_metres():
    ds = hmlvs.simulate(seed=0).dataset
    fit, test = ds.split(0.5)
    np.testing.assert_array_equal(fit.ids, ds.ids[:50])
    f2, t2 = ds.split(30, seed=1)
    assert len(f2) == 30 and len(t2) == 70 and not set(f2.ids) & set(t2.ids)
    poses_m = ds.poses.copy()
    poses_m[:, :3, 3] /= 1000
    in_m = hmlvs.Dataset(ds.pixels, poses_m, ds.points / 1000, length_unit="m")
    np.testing.assert_allclose(in_m.points, ds.points, rtol=1e-12)
