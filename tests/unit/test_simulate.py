"""Simulated data: the random-pixel protocol and the checkerboard session."""

import hmlvs
import numpy as np
import pytest

pytestmark = pytest.mark.scene  # simulated sessions or rendered images


def test_simulate_defaults_and_seed():
    a = hmlvs.simulate(seed=3)
    b = hmlvs.simulate(seed=3)
    assert (len(a.fit), len(a.test)) == (50, 50)
    np.testing.assert_array_equal(a.dataset.points, b.dataset.points)
    assert not np.array_equal(a.dataset.points, hmlvs.simulate(seed=4).dataset.points)
    # noise-free: the truth reproduces every reference point
    e = hmlvs.models.paper.residuals(a.truth, a.dataset.pixels, a.dataset.poses, a.dataset.points)
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
    plane = hmlvs.models.paper.laser_plane_distance(s.truth, ds.points, ds.poses)
    assert np.abs(plane).max() < 1e-7
    e = hmlvs.models.paper.residuals(s.truth, ds.pixels, ds.poses, ds.points)
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


# What the subprocesses below compute: sessions, and IK solves with a stripe direction as the
# scenes use them, written to an .npy file.
_SESSIONS_SCRIPT = """
import sys
import numpy as np
import hmlvs
from hmlvs.sim.sessions import ik_look_at
out = []
for seed in range(3):
    s = hmlvs.simulate.session(num_poses=6, seed=seed, pixel_noise=0.1)
    out += [s.joints.ravel(), s.dataset.pixels.ravel(), s.dataset.poses.ravel()]
robot = hmlvs.Robot.scorbot_er7()
hfc = hmlvs.models.paper.hand_from_camera(hmlvs.Parameters.nominal())
home = np.array([0.0, -0.8, 1.2, 0.0, 0.0])
for x, y in [(650.0, 0.0), (700.0, 60.0), (600.0, -80.0)]:
    j = ik_look_at(robot, hfc, np.array([x, y, 300.0]), np.array([0.0, 0.0, -1.0]), [home],
                    cam_x=np.array([0.0, 1.0, 0.0]))
    out.append(np.full(5, np.nan) if j is None else j)
np.save(sys.argv[1], np.concatenate(out))
"""


def _blas_kernels():
    """Two OpenBLAS kernels this CPU can run: Prescott (SSE3) and Haswell (AVX2) where the
    CPU has AVX2, else Nehalem."""
    try:
        flags = open("/proc/cpuinfo").read()
    except OSError:
        flags = ""
    return ["Prescott", "Haswell" if " avx2" in flags else "Nehalem"]


def test_session_is_the_same_under_every_blas_kernel(tmp_path):
    """The session generator solves IK; BLAS results differ in the last bits between CPUs
    (the kernel OpenBLAS picks), and a decision that flips on one changes the scene. The
    generator must give the same poses, pixels and IK solutions under every kernel."""
    import os
    import subprocess
    import sys

    runs = {}
    procs = []
    for kernel in _blas_kernels() + [None]:
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if kernel:
            env["OPENBLAS_CORETYPE"] = kernel
        path = tmp_path / f"{kernel or 'default'}.npy"
        procs.append((kernel, path, subprocess.Popen(
            [sys.executable, "-c", _SESSIONS_SCRIPT, str(path)], env=env,
            stderr=subprocess.PIPE, text=True)))
    for kernel, path, p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, (kernel, err)
        runs[kernel] = np.load(path)
    ref = runs[None]
    assert np.isfinite(ref).all() and ref.size > 300
    for kernel, got in runs.items():
        assert got.shape == ref.shape, kernel
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9, err_msg=str(kernel))


@pytest.mark.parametrize("limits", [True, False])
def test_look_at_solve_is_the_numpy_solve_bit_for_bit(limits):
    """The session generator's look-at IK runs in C++; it must be the generic NumPy solve
    (``_damped_solve``, which the stripe snap still uses) on the same residual, to the last bit:
    any difference could move a simulated scene on another machine."""
    from hmlvs import _core
    from reference_ik import solve_look_at

    robot = hmlvs.Robot.scorbot_er7()
    if not limits:
        robot = hmlvs.Robot.from_dict({**robot.to_dict(), "joint_limits": None})
    assert (robot.joint_limits is not None) == limits
    lim = robot.joint_limits
    lo = lim[:, 0] if limits else np.full(robot.dof, -np.inf)
    hi = lim[:, 1] if limits else np.full(robot.dof, np.inf)
    hfc = hmlvs.models.paper.hand_from_camera(hmlvs.Parameters.nominal())
    rng = np.random.default_rng(7)
    exact = 0
    for trial in range(24):
        pos = np.array([rng.uniform(450, 800), rng.uniform(-250, 250), rng.uniform(150, 400)])
        axis = rng.normal(size=3)
        axis[2] = -abs(axis[2]) - 1.0
        axis /= np.linalg.norm(axis)
        cam_x = None
        if trial % 2:
            cam_x = np.cross(axis, [0.0, 0.0, 1.0])
            cam_x /= np.linalg.norm(cam_x)
        start = rng.uniform(-0.5, 0.5, robot.dof)
        want = solve_look_at(robot, hfc, pos, axis, cam_x, start, lo, hi)
        got = _core._solve_look_at(robot._native(), hfc, pos, axis, cam_x, start, lo, hi,
                                   0.2, 200)
        np.testing.assert_array_equal(got[0], want[0], err_msg=f"trial {trial}")
        assert got[1] == want[1], trial
        exact += want[1] < 1e-6
    # both kinds of end are compared: exact solutions and least-squares ones (the 5-joint arm
    # cannot reach every view, nor any stripe direction)
    assert 0 < exact < 24


def test_look_at_solve_bad_input():
    from hmlvs import _core

    robot = hmlvs.Robot.scorbot_er7()
    hfc = hmlvs.models.paper.hand_from_camera(hmlvs.Parameters.nominal())
    args = (robot._native(), hfc, np.array([600.0, 0.0, 300.0]), np.array([0.0, 0.0, -1.0]), None)
    inf = np.full(5, np.inf)
    with pytest.raises(ValueError, match="one value per joint"):
        _core._solve_look_at(*args, np.zeros(4), -inf, inf, 0.2, 200)
    with pytest.raises(ValueError, match="not finite"):
        _core._solve_look_at(*args, np.full(5, np.nan), -inf, inf, 0.2, 200)
