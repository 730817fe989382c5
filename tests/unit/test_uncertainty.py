"""Uncertainty: predicted standard deviations match Monte Carlo; combinations; no NaN."""

import warnings

import hmlvs
import numpy as np
import pytest

WELL_POSED = ("Su", "Sv", "Cu", "Cv")
GENERIC = dict(omega=0.1, phi=0.12, varphi=-0.07)


def _rotation_error(truth, est) -> np.ndarray:
    """Rotation vector (camera frame) of R_true^T R_est."""
    from scipy.spatial.transform import Rotation

    rt = hmlvs.models.paper.hand_from_camera(truth)[:3, :3]
    re = hmlvs.models.paper.hand_from_camera(est)[:3, :3]
    return Rotation.from_matrix(rt.T @ re).as_rotvec()


def _monte_carlo(truth, runs=200):
    """200 seeded simulations with 0.1 px pixel noise; LM from the truth, well-posed fixing.

    Returns the estimates, their rotation errors, and the per-run predicted variances with
    the noise estimated from the residuals (the default) and given (pixel_noise=0.1).
    """
    est, rot, comb = [], [], []
    var = {"estimated": [], "given": []}
    rvar = {"estimated": [], "given": []}
    cvar = {"estimated": [], "given": []}
    noise = []
    for i in range(runs):
        sim = hmlvs.simulate(truth, seed=1000 + i, pixel_noise=0.1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", hmlvs.HmlvsDataWarning)  # the gimbal lock
            # use_bounds=False: k = 0 is at its Table 2 bound, which would fold its errors
            r = hmlvs.calibrate(sim, method="lm", initial=truth, fixed=WELL_POSED, threads=1,
                                use_bounds=False, judge=False).solve
        u_est = r.uncertainty
        u_giv = hmlvs.uncertainty(sim.fit, r.params, fixed=WELL_POSED, pixel_noise=0.1)
        est.append(r.params.to_array())
        rot.append(_rotation_error(truth, r.params))
        noise.append(u_est.pixel_noise)
        for key, u in (("estimated", u_est), ("given", u_giv)):
            var[key].append([u.std[n] ** 2 for n in u.free])
            rvar[key].append(u.rotation_std ** 2)
            cvar[key].append({c.name: c.std ** 2 for c in u.combinations})
        comb.append({c.name: c.value for c in u_est.combinations})
    return u_est.free, np.array(est), np.array(rot), comb, var, rvar, cvar, np.array(noise)


@pytest.mark.parametrize("where", ["nominal", "generic rotation"])
def test_monte_carlo_predicted_std_within_25_percent(where):
    truth = hmlvs.Parameters.nominal()
    if where != "nominal":
        truth = truth.replace(**GENERIC)
    free, est, rot, comb, var, rvar, cvar, noise = _monte_carlo(truth)
    # the pixel noise estimated from each run's residuals averages to the true 0.1 px
    assert noise.mean() == pytest.approx(0.1, rel=0.1), noise.mean()
    # Well-determined: every free parameter, except at the gimbal lock omega, phi, varphi
    # (there only the rotation and omega + varphi are; checked below).
    names = [n for n in free if where != "nominal" or n not in ("omega", "phi", "varphi")]
    cols = [hmlvs.models.params.NAMES.index(n) for n in names]
    empirical = est[:, cols].std(axis=0, ddof=1)
    for key in ("estimated", "given"):
        pred = np.sqrt(np.mean(var[key], axis=0))[[free.index(n) for n in names]]
        ratio = empirical / pred
        # measured: 0.92..1.06 for every quantity, both rotations and both noise models
        assert np.all(np.abs(ratio - 1) < 0.25), (key, dict(zip(names, ratio.round(3))))
        rot_ratio = rot.std(axis=0, ddof=1) / np.sqrt(np.mean(rvar[key], axis=0))
        assert np.all(np.abs(rot_ratio - 1) < 0.25), (key, rot_ratio)
        for c in cvar[key][0]:
            emp = np.std([x[c] for x in comb], ddof=1)
            pred_c = np.sqrt(np.mean([x[c] for x in cvar[key]]))
            assert abs(emp / pred_c - 1) < 0.25, (key, c, emp, pred_c)
    if where == "nominal":
        assert "omega + varphi" in comb[0]
    else:
        assert "omega + varphi" not in comb[0]  # phi = 0.12 rad is not near the gimbal lock


def test_combinations_far_better_than_raw_parameters_with_the_gauge_free():
    # The principal point and H known, the scale gauge left free: LM from a perturbed start
    # ends somewhere on the gauge orbit; f, Su, Sv are off by that, the combinations are not.
    truth = hmlvs.Parameters.nominal()
    sim = hmlvs.simulate(truth, seed=4)
    fixed = ("Cu", "Cv", "H")
    start = truth.replace(f=8.3, Su=0.0071, Sv=0.0077, theta=0.44, tx=61.0, omega=0.02,
                          varphi=0.01)
    with pytest.warns(hmlvs.HmlvsDataWarning, match="scale gauge"):
        r = hmlvs.calibrate(sim, method="lm", initial=start, fixed=fixed, threads=1,
                            judge=False).solve
    assert r.test_rms < 1e-6  # a perfect fit ...
    raw = {n: abs(getattr(r.params, n) / getattr(truth, n) - 1) for n in ("f", "Su", "Sv")}
    assert min(raw.values()) > 1e-3, raw  # ... with f, Su, Sv off by 0.1 % or more
    u = r.uncertainty
    comb = {c.name: c for c in u.combinations}
    for name, true in (("f/Su", truth.f / truth.Su), ("f/Sv", truth.f / truth.Sv)):
        assert abs(comb[name].value / true - 1) < 1e-4 * min(raw.values()), (name, raw)
        assert comb[name].determined
    assert comb["k Su^2"].value == pytest.approx(0.0, abs=1e-12) and comb["k Su^2"].determined
    # the gimbal lock: omega and varphi moved, their sum did not
    assert abs(comb["omega + varphi"].value) < 1e-9  # measured 9e-17 ...
    assert abs(r.params.omega) > 1e-2 and abs(r.params.varphi) > 1e-2  # ... both 0.02 off
    assert comb["omega + varphi"].determined
    # the raw parameters along the gauge are flagged, with a warning naming the gauge
    assert not any(u.determined[n] for n in ("f", "Su", "Sv"))
    assert any("scale gauge" in w for w in u.warnings)


def test_combinations_with_noise_agree_with_truth_within_their_std():
    truth = hmlvs.Parameters.nominal()
    fixed = ("Cu", "Cv", "H")
    errs = []
    for seed in range(8):
        sim = hmlvs.simulate(truth, seed=seed, pixel_noise=0.1)
        start = truth.replace(f=8.3, Su=0.0071, Sv=0.0077)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", hmlvs.HmlvsDataWarning)
            r = hmlvs.calibrate(sim, method="lm", initial=start, fixed=fixed, threads=1,
                                use_bounds=False, judge=False).solve
        c = r.uncertainty.combination("f/Su")
        z_comb = (c.value - truth.f / truth.Su) / c.std
        # f's own std is the pseudo-inverse's (not meaningful): its error is far beyond it
        z_raw = (r.params.f - truth.f) / r.uncertainty.std["f"]
        errs.append((z_comb, z_raw))
    z = np.array(errs)
    assert np.all(np.abs(z[:, 0]) < 4), z[:, 0]  # 8 draws of a standard normal
    assert np.median(np.abs(z[:, 1])) > 10 * np.median(np.abs(z[:, 0])), z


def test_rank_deficient_gives_finite_numbers_and_a_warning():
    sim = hmlvs.simulate(seed=0, pixel_noise=0.1)
    u = hmlvs.uncertainty(sim.fit, sim.truth, fixed=())
    assert u.rank == 11 and len(u.free) == 14
    assert np.all(np.isfinite(u.covariance)) and np.all(np.isfinite(u.correlation))
    assert all(np.isfinite(v) for v in u.std.values())
    assert all(np.isfinite(c.std) for c in u.combinations)
    assert np.allclose(u.covariance, u.covariance.T)
    assert np.all(np.linalg.eigvalsh(u.covariance) > -1e-12 * np.abs(u.covariance).max())
    assert np.allclose(np.diag(u.correlation), 1.0) and np.abs(u.correlation).max() <= 1.0
    w = " ".join(u.warnings)
    assert "rank-deficient (11 of 14)" in w and "scale gauge" in w and "camera shift" in w
    assert "gimbal lock" in w
    assert not any(u.determined[n] for n in ("f", "Su", "Sv", "omega", "varphi", "Cv", "H"))
    assert u.combination("k Su^2").determined and u.combination("omega + varphi").determined


def test_noise_free_data_zero_std_no_nan():
    sim = hmlvs.simulate(seed=1)
    u = hmlvs.uncertainty(sim.fit, sim.truth, fixed=WELL_POSED)
    ref = hmlvs.uncertainty(sim.fit, sim.truth, fixed=WELL_POSED, pixel_noise=0.1)
    # residuals of 1e-14 mm (rounding) give noise levels and std of that order
    assert u.pixel_noise < 1e-12 and u.point_noise < 1e-12 and u.sigma < 1e-12
    assert all(u.std[n] < 1e-10 * ref.std[n] for n in u.free)
    assert np.all(np.isfinite(u.correlation)) and np.abs(u.correlation).max() <= 1.0
    assert np.abs(u.correlation - np.eye(len(u.free))).max() > 0.5  # still informative


def test_given_noise_scales_linearly_and_point_noise_adds():
    truth = hmlvs.Parameters.nominal().replace(**GENERIC)
    ds = hmlvs.simulate(truth, seed=6).fit
    u1 = hmlvs.uncertainty(ds, truth, fixed=WELL_POSED, pixel_noise=0.1)
    u2 = hmlvs.uncertainty(ds, truth, fixed=WELL_POSED, pixel_noise=0.2)
    assert u1.noise_model == "given"
    for n in u1.free:
        assert u2.std[n] == pytest.approx(2 * u1.std[n], rel=1e-12)
    u3 = hmlvs.uncertainty(ds, truth, fixed=WELL_POSED, pixel_noise=0.1, point_noise=0.05)
    assert all(u3.std[n] > u1.std[n] for n in u1.free)
    u4 = hmlvs.uncertainty(ds, truth, fixed=WELL_POSED, point_noise=0.05)
    np.testing.assert_allclose(u3.covariance, u1.covariance + u4.covariance, rtol=1e-10,
                               atol=1e-14 * np.abs(u3.covariance).max())


@pytest.mark.parametrize("pixel, point", [(0.1, 0.05), (0.0, 0.05), (0.3, 0.02)])
def test_noise_levels_estimated_from_residuals(pixel, point):
    est = []
    for seed in range(10):
        sim = hmlvs.simulate(seed=seed, n=400, fit=200, pixel_noise=pixel, point_noise=point)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", hmlvs.HmlvsDataWarning)
            r = hmlvs.calibrate(sim, method="lm", initial=sim.truth, fixed=WELL_POSED,
                                threads=1, use_bounds=False, judge=False).solve
        est.append((r.uncertainty.pixel_noise, r.uncertainty.point_noise))
    mean = np.mean(est, axis=0)
    # measured means: (0.093, 0.050), (0.021, 0.048), (0.285, 0.020). A zero pixel noise comes
    # out at 0.02 px: the estimate of the variance is unbiased (checked on the linearised
    # model), but its square root is not when the true level is 0 (0.01 px in the linear model
    # with 200 points; 0.02 px here). Hence abs=0.03 px, a tenth of a typical 0.3 px.
    assert mean[0] == pytest.approx(pixel, rel=0.1, abs=0.03)
    assert mean[1] == pytest.approx(point, rel=0.1)


def test_calibrate_passes_pixel_noise_and_rejects_bad_noise():
    truth = hmlvs.Parameters.nominal().replace(**GENERIC)
    sim = hmlvs.simulate(truth, seed=2, pixel_noise=0.1)
    r = hmlvs.calibrate(sim, method="lm", initial=truth, fixed=WELL_POSED, threads=1,
                        pixel_noise=0.1, judge=False).solve
    assert r.uncertainty.noise_model == "given" and r.uncertainty.pixel_noise == 0.1
    assert "f/Su" in str(r)
    with pytest.raises(ValueError, match="pixel_noise must be a finite number >= 0"):
        hmlvs.calibrate(sim, method="lm", initial=truth, pixel_noise=-0.1)
    with pytest.raises(ValueError, match="both 0"):
        hmlvs.uncertainty(sim.fit, truth, pixel_noise=0.0, point_noise=0.0)
    with pytest.raises(ValueError, match="point_noise must be a finite number"):
        hmlvs.uncertainty(sim.fit, truth, point_noise="small")
    with pytest.raises(ValueError, match="no combination 'f/H'"):
        r.uncertainty.combination("f/H")


def _session_with_pose_errors(seed: int, sigma_mm: float, sigma_deg: float):
    """A simulated checkerboard session (0.1 px pixel noise) whose robot poses are each off
    by a random pose error (hand frame), the same for all the points of a pose."""
    import math

    from hmlvs.data.dataset import Dataset
    from hmlvs.sim.features import transform
    from hmlvs.sim.sessions import session

    truth = hmlvs.Parameters.nominal()
    ds = session(truth, pixel_noise=0.1, seed=seed, num_poses=30).dataset
    rng = np.random.default_rng(100 + seed)
    err = [transform(rng.normal(0, math.radians(sigma_deg), 3), rng.normal(0, sigma_mm, 3))
           for _ in range(int(ds.pose_index.max()) + 1)]
    poses = np.array([p @ err[k] for p, k in zip(ds.poses, ds.pose_index)])
    moved = Dataset(ds.pixels, poses, ds.points, ids=ds.ids, pose_index=ds.pose_index)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", hmlvs.HmlvsDataWarning)  # the gimbal lock
        r = hmlvs.calibrate(moved, method="lm", initial=truth, fixed=WELL_POSED, threads=1,
                            use_bounds=False, judge=False).solve
    return truth, r


def test_robot_pose_errors_are_told_from_the_noise_and_counted():
    """Poses off by 0.3 mm and 0.1 degrees per axis, shared by the points of each pose: the
    noise estimate sees through them (0.085-0.096 px pixel noise, the truth 0.1; without
    the pose errors' share it read 0-0.56 px and 0.37-0.47 mm of point noise), reports the
    pose errors (0.30-0.38 mm and 0.065-0.085 degrees on these seeds), and the parameters'
    errors spread like their standard deviations (z-scores' RMS 0.9 over six seeds; 1.2
    without the pose errors' share). Euler angles are compared through the rotation vector:
    near the nominal sensor's gimbal lock omega and varphi alone are not linear."""
    zs = []
    for seed in range(4):
        truth, r = _session_with_pose_errors(seed, 0.3, 0.1)
        u = r.uncertainty
        mm, deg = u.pose_errors
        assert 0.15 < mm < 0.6 and 0.05 < deg < 0.2, u.pose_errors
        assert u.pixel_noise == pytest.approx(0.1, rel=0.25)
        assert u.point_noise < 0.01
        assert "robot pose errors of about" in u.summary()
        zs += [(getattr(r.params, n) - getattr(truth, n)) / u.std[n] for n in u.free
               if n not in ("omega", "phi", "varphi")]
        zs += list(_rotation_error(truth, r.params) / u.rotation_std)
    zs = np.array(zs)
    assert 0.5 < np.sqrt(np.mean(zs ** 2)) < 1.5, zs
    assert np.abs(zs).max() < 4, zs


def test_exact_poses_show_no_robot_pose_errors():
    for seed in range(3):
        _, r = _session_with_pose_errors(seed, 0.0, 0.0)
        assert r.uncertainty.pose_errors is None
        assert r.uncertainty.pixel_noise == pytest.approx(0.1, rel=0.25)


def test_robot_pose_errors_are_not_counted_beyond_the_memory_bound(monkeypatch):
    """A data set too large for the poses' error columns keeps the white-noise covariance
    (and its noise estimate) rather than allocating them."""
    from hmlvs.diagnostics import uncertainty as unc

    monkeypatch.setattr(unc, "MAX_POSE_ENTRIES", 100)
    _, r = _session_with_pose_errors(0, 0.3, 0.1)
    assert r.uncertainty.pose_errors is None
    assert r.uncertainty.point_noise > 0.1  # the pose errors read as point noise again
