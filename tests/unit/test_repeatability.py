"""Repeatability: bootstrap re-calibration, deterministic, shows flat directions (issue 4)."""

import warnings

import hmlvs
import numpy as np
import pytest

pytestmark = pytest.mark.scene  # simulated sessions or rendered images

WELL_POSED = ("Su", "Sv", "Cu", "Cv")
GENERIC = dict(omega=0.1, phi=0.12, varphi=-0.07)


@pytest.fixture(scope="module")
def noisy():
    return hmlvs.simulate(hmlvs.Parameters.nominal().replace(**GENERIC), seed=0, pixel_noise=0.1)


def test_deterministic_for_a_seed(noisy):
    kw = dict(runs=20, fixed=WELL_POSED, use_bounds=False)
    a = hmlvs.repeatability(noisy, seed=3, threads=1, **kw)
    b = hmlvs.repeatability(noisy, seed=3, threads=2, **kw)
    np.testing.assert_array_equal(a.params, b.params)
    np.testing.assert_array_equal(a.heldout_rms, b.heldout_rms)
    c = hmlvs.repeatability(noisy, seed=4, threads=1, **kw)
    assert not np.array_equal(a.params, c.params)
    assert a.runs == 20 and a.params.shape == (20, 14) and a.failures == []
    assert a.heldout_kind == "test" and not a.by_pose


def test_well_posed_spread_matches_the_predicted_std(noisy):
    rep = hmlvs.repeatability(noisy, runs=100, fixed=WELL_POSED, threads=1, use_bounds=False)
    unc = rep.reference.uncertainty
    ratio = {n: rep.parameters[n].std / unc.std[n] for n in unc.free}
    # Bootstrap spread over the linearised prediction, measured 0.80..1.03 on this data set
    # (0.5..1.4 over other seeds: resampling 50 points is a rough estimate of the spread,
    # hence 40 %, not the Monte Carlo test's 25 %).
    assert all(0.6 < r < 1.4 for r in ratio.values()), ratio
    assert set(rep.parameters) == set(unc.free)
    assert rep.heldout.std < 0.15 * rep.heldout.mean  # held-out RMS 0.167 +- 0.011 mm
    assert rep.heldout.mean == pytest.approx(np.mean(rep.heldout_rms))
    assert "run std" in rep.summary() and "predicted" in rep.summary()


def test_flat_directions_wander_while_heldout_rms_does_not():
    # The paper's nominal data with only Su fixed: the camera-y shift and the tilt are exact
    # null directions, and phi = 0 is the gimbal lock.
    sim = hmlvs.simulate(seed=0, pixel_noise=0.1)
    with pytest.warns(hmlvs.HmlvsDataWarning):  # the reference fit's flat directions
        rep = hmlvs.repeatability(sim, runs=40, threads=1, fixed=("Su",))  # Su alone held
    unc = rep.reference.uncertainty
    for n in ("Cv", "H", "ty"):
        assert not unc.determined[n]
        assert rep.parameters[n].std > 10 * unc.std[n], (n, rep.parameters[n].std, unc.std[n])
    assert rep.parameters["H"].max - rep.parameters["H"].min > 10.0  # mm, of a 30 mm range
    # ... yet every run measures equally well
    assert rep.heldout.std < 0.1 * rep.heldout.mean
    # the gimbal lock: omega and varphi swing by radians, their sum by microradians
    assert rep.parameters["omega"].std > 1e3 * rep.combinations["omega + varphi"].std
    assert rep.combinations["k Su^2"].std < 1e-8


def test_by_pose_resampling_on_a_session():
    """By-pose bootstrap on sessions of 12 poses, over 5 seeds. 15 resamples estimate a
    standard deviation to about +-20 %, and resampling whole poses adds pose-to-pose spread
    the linearised prediction does not hold: measured on seeds 0-7, run std of f over its
    predicted std 0.83-1.59 (mean 1.23). Bounds: each seed within [0.5, 2], the mean of the
    five within [0.8, 1.6]."""
    ratios = []
    for seed in range(5):
        s = hmlvs.simulate.session(num_poses=12, pixel_noise=0.1, seed=seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", hmlvs.HmlvsDataWarning)
            rep = hmlvs.repeatability(s.dataset, runs=15, fixed=WELL_POSED, initial=s.truth,
                                      threads=1, use_bounds=False)
        assert rep.by_pose and rep.heldout_kind == "out-of-bag" and rep.runs == 15
        assert np.all(np.isfinite(rep.heldout_rms)) and np.all(rep.heldout_rms < 1.0)
        ratios.append(rep.parameters["f"].std / rep.reference.uncertainty.std["f"])
    assert all(0.5 < r < 2.0 for r in ratios), ratios
    assert 0.8 < np.mean(ratios) < 1.6, ratios


@pytest.mark.parametrize("kwargs, match", [
    ({"runs": 1}, "runs must be an integer >= 2, got 1"),
    ({"runs": 2.5}, "runs must be an integer >= 2"),
    ({"test": "held-out.npz"}, "test must be an hmlvs.Dataset"),
    ({"by_pose": True}, "by_pose=True needs a data set with a pose_index"),
    ({"seed": 1, "calibrate_seed": 2}, "unknown option"),
])
def test_repeatability_bad_input(noisy, kwargs, match):
    with pytest.raises(ValueError, match=match):
        hmlvs.repeatability(noisy.fit, **kwargs)
