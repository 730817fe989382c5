"""The C++ sensor model against the independent NumPy oracle, its inverse and its Jacobian."""

from conftest import random_params
import hmlvs
import numpy as np
import pytest
import reference_model as ref


@pytest.mark.parametrize("trial", range(5))
def test_base_points_match_numpy_oracle(rng, trial):
    q = random_params(rng)
    m = 2000
    pixels = rng.uniform([0, 0], [640, 480], size=(m, 2))
    poses = ref.random_poses(rng, m)
    expected = ref.base_points(q, pixels, poses)
    _, ok = ref.camera_points(q, pixels)
    got, valid = hmlvs.models.paper.points_in_base(q, pixels, poses, on_invalid="mask")
    np.testing.assert_array_equal(valid, ok)
    scale = np.abs(expected[ok]).max()
    assert np.abs(got[ok] - expected[ok]).max() <= 1e-12 * scale
    assert np.isnan(got[~ok]).all()


def test_camera_points_match_numpy_oracle(rng):
    q = random_params(rng)
    pixels = rng.uniform([0, 0], [640, 480], size=(5000, 2))
    expected, ok = ref.camera_points(q, pixels)
    got, valid = hmlvs.models.paper.points_in_camera(q, pixels, on_invalid="mask")
    np.testing.assert_array_equal(valid, ok)
    rel = np.abs(got[ok] - expected[ok]).max() / np.abs(expected[ok]).max()
    assert rel <= 1e-12


def test_camera_points_lie_on_laser_plane(rng):
    q = random_params(rng)
    pts, ok = hmlvs.models.paper.points_in_camera(q, rng.uniform([0, 0], [640, 480], (500, 2)),
                                                  "mask")
    plane = pts[ok, 1] + pts[ok, 2] * np.tan(q[7]) - q[6]
    assert np.abs(plane).max() < 1e-10 * q[6]


def test_residuals_and_objective(rng):
    q = random_params(rng)
    pixels = rng.uniform([100, 100], [500, 400], size=(50, 2))
    poses = ref.random_poses(rng, 50)
    refs = ref.base_points(q, pixels, poses) + rng.normal(0, 0.5, (50, 3))
    e = hmlvs.models.paper.residuals(q, pixels, poses, refs)
    np.testing.assert_allclose(e, refs - ref.base_points(q, pixels, poses), rtol=0, atol=1e-9)
    assert hmlvs.models.paper.objective(q, pixels, poses, refs) == pytest.approx(
        0.5 * np.sum(e**2), rel=1e-12)


def test_inverse_recovers_pixels(rng):
    q = random_params(rng)
    m = 1000
    pixels = rng.uniform([0, 0], [640, 480], size=(m, 2))
    poses = ref.random_poses(rng, m)
    pts, ok = hmlvs.models.paper.points_in_base(q, pixels, poses, on_invalid="mask")
    back, valid = hmlvs.models.paper.pixels_from_points(q, pts[ok], poses[ok])
    assert valid.all()
    assert np.abs(back - pixels[ok]).max() < 1e-7


def test_inverse_rejects_points_off_the_plane(rng):
    q = hmlvs.Parameters.nominal()
    pixels = np.array([[320.0, 240.0], [100.0, 300.0]])
    poses = ref.random_poses(rng, 2)
    pts, _ = hmlvs.models.paper.points_in_base(q, pixels, poses)
    pts[1] += poses[1, :3, :3] @ hmlvs.models.paper.hand_from_camera(q)[:3, :3] @ np.array(
        [0, 1.0, 0])
    _, valid = hmlvs.models.paper.pixels_from_points(q, pts, poses, on_invalid="mask")
    assert valid.tolist() == [True, False]
    with pytest.raises(ValueError, match="point 1 .*laser plane"):
        hmlvs.models.paper.pixels_from_points(q, pts, poses)
    # a plain projection accepts any point in front of the camera
    px, ok = hmlvs.models.paper.project(q, pts, poses)
    assert ok.all() and np.abs(px[0] - pixels[0]).max() < 1e-8


def test_jacobian_matches_central_differences(rng):
    q = random_params(rng)
    m = 30
    pixels = rng.uniform([50, 50], [590, 430], size=(m, 2))
    poses = ref.random_poses(rng, m)
    refs = ref.base_points(q, pixels, poses)
    _, jac = hmlvs.models.paper.residual_jacobian(q, pixels, poses, refs)
    for i in range(14):
        h = 1e-6 * max(1.0, abs(q[i]))
        qp, qm = q.copy(), q.copy()
        qp[i] += h
        qm[i] -= h
        num = (ref.base_points(qm, pixels, poses) - ref.base_points(qp, pixels, poses)) / (2 * h)
        scale = max(np.abs(num).max(), 1e-3)
        assert np.abs(jac[:, :, i] - num).max() < 1e-5 * scale, hmlvs.models.params.NAMES[i]


def test_least_squares_functions_give_the_residuals_and_back_off_where_unmeasured(rng):
    """The functions for a general least-squares solver: the flattened residuals and their
    Jacobian where the model measures; where a ray misses the laser plane (f < 0) the large
    residual and a zero Jacobian that make an unbounded solver back off."""
    from types import SimpleNamespace

    q = random_params(rng)
    pixels = rng.uniform([50, 50], [590, 430], size=(12, 2))
    poses = ref.random_poses(rng, 12)
    points = ref.base_points(q, pixels, poses) + rng.normal(0, 0.1, (12, 3))
    fun, jac = hmlvs.models.paper.least_squares_functions(
        SimpleNamespace(pixels=pixels, poses=poses, points=points), unmeasured=1e5)
    np.testing.assert_allclose(fun(q), (points - ref.base_points(q, pixels, poses)).ravel(),
                               atol=1e-9)
    assert jac(q).shape == (36, 14)
    np.testing.assert_array_equal(
        jac(q), hmlvs.models.paper.residual_jacobian(q, pixels, poses, points)[1].reshape(36, 14))
    bad = q.copy()
    bad[0] = -abs(bad[0])  # f < 0: no ray meets the plane in front of the camera
    with pytest.raises(ValueError):
        hmlvs.models.paper.residuals(bad, pixels, poses, points)
    np.testing.assert_array_equal(fun(bad), np.full(36, 1e5))
    np.testing.assert_array_equal(jac(bad), np.zeros((36, 14)))


def test_hand_from_camera_is_zyz_euler():
    q = hmlvs.Parameters.nominal().replace(omega=0.1, phi=-0.2, varphi=0.3, tx=1, ty=2, tz=3)
    t = hmlvs.models.paper.hand_from_camera(q)
    np.testing.assert_allclose(t[:3, :3], ref.rot_z(0.1) @ ref.rot_y(-0.2) @ ref.rot_z(0.3),
                               atol=1e-15)
    np.testing.assert_allclose(t[:3, 3], [1, 2, 3])


def test_one_million_points_evaluate(rng):
    # Correctness on a large batch (the speed figure is in bench/, not asserted here).
    q = hmlvs.Parameters.nominal()
    m = 1_000_000
    pixels = rng.uniform([0, 0], [640, 480], size=(m, 2))
    poses = np.tile(np.eye(4), (m, 1, 1))
    pts, ok = hmlvs.models.paper.points_in_base(q, pixels, poses)
    assert ok.all() and pts.shape == (m, 3)
    i = rng.integers(0, m, 100)
    np.testing.assert_allclose(pts[i], ref.base_points(q.to_array(), pixels[i], poses[i]),
                               rtol=1e-12)


def test_rays_pass_through_the_triangulated_points(rng):
    q = random_params(rng)
    pixels = rng.uniform([0, 0], [640, 480], size=(300, 2))
    rays = hmlvs.models.paper.rays_in_camera(q, pixels)
    pts, ok = hmlvs.models.paper.points_in_camera(q, pixels, on_invalid="mask")
    np.testing.assert_allclose(rays[:, 2], q[0])
    t = pts[ok, 2] / rays[ok, 2]
    np.testing.assert_allclose(pts[ok], t[:, None] * rays[ok], rtol=1e-12)
    # base frame == camera frame
    camera_as_base = np.linalg.inv(hmlvs.models.paper.hand_from_camera(q))
    back, valid = hmlvs.models.paper.pixels_from_points(q, pts[ok],
                                                 np.tile(camera_as_base, (ok.sum(), 1, 1)))
    assert np.abs(back - pixels[ok]).max() < 1e-7


def test_a_ray_at_a_grazing_angle_to_the_laser_plane_has_no_measurement():
    import hmlvs

    p = hmlvs.Parameters.nominal()
    # Rays just below the row where Yu + f tan(theta) = 0 meet the plane, but at a grazing
    # angle and thousands of mm away: invalid, with a reason.
    v0 = p.Cv - p.f * np.tan(p.theta) / p.Sv
    px = np.array([[320.0, v0 + 0.5], [320.0, 400.0]])
    # the model itself keeps them (the design analysis and the solvers need the raw model) ...
    _, ok = hmlvs.models.paper.points_in_camera(p, px, on_invalid="mask")
    assert ok.tolist() == [True, True]
    # ... measurement refuses them
    from hmlvs.models.paper import PaperSensor

    pts, ok = PaperSensor(p).points_in_camera(px, on_invalid="mask")
    assert ok.tolist() == [False, True]
    with pytest.raises(ValueError, match="grazing angle"):
        PaperSensor(p).points_in_camera(px[:1])
    cloud = hmlvs.measure(p, [px], np.eye(4))
    assert cloud.valid.tolist() == [False, True]
