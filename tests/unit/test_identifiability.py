"""Identifiability: the Jacobian SVD finds and names docs/model.md's degeneracies (issue 4)."""

import math
import warnings

import hmlvs
from hmlvs.diagnostics.identifiability import (
    NULL_TOL,
    WEAK_TOL,
    camera_y_tangent,
    euler_rate_map,
    gimbal_tangent,
    rotation_jacobian,
    scale_gauge_tangent,
)
from hmlvs.models.paper import residual_jacobian
import numpy as np
import pytest

GENERIC = dict(omega=0.1, phi=0.12, varphi=-0.07, Cu=318.0, Cv=247.0, ty=3.0)
KNOWN = {"scale_gauge", "gimbal_lock", "camera_y_shift"}


@pytest.fixture(scope="module")
def paper():
    """The paper's simulated data (section 4) at the Table 2 nominal values."""
    return hmlvs.simulate(seed=0)


def test_paper_data_all_three_known_degeneracies_found_and_named(paper):
    rep = hmlvs.identifiability(paper.fit, paper.truth, fixed=())
    rel = rep.relative_singular_values
    assert rep.num_free == 14 and rep.rank == 11 and rep.euler_rank == 11
    assert np.all(rel[11:] < 1e-15) and rel[10] > 1e-3  # 3 exact nulls, then a wide gap
    assert not rep.full_rank and rep.condition_number > 1e15
    by_kind = {d.kind: d for d in rep.directions}
    assert KNOWN <= set(by_kind)
    for kind in KNOWN:
        d = by_kind[kind]
        assert d.status == "null" and d.gain < 1e-15 and d.in_flat > 1 - 1e-9, d
    assert by_kind["gimbal_lock"].parametrization_only
    assert by_kind["gimbal_lock"].loadings["omega"] == pytest.approx(-by_kind["gimbal_lock"]
                                                                     .loadings["varphi"])
    # The gauge, in range-scaled coordinates: proportional to (f/8, Su/0.005, Sv/0.005) / norm
    g = np.array([8.0 / 4.0, 0.0074 / 0.005, 0.0074 / 0.005])
    got = [by_kind["scale_gauge"].loadings[n] for n in ("f", "Su", "Sv")]
    np.testing.assert_allclose(got, g / np.linalg.norm(g), rtol=1e-9)
    # In the data's coordinates (rotation on SO(3)) the gimbal lock is no flat direction, but
    # a camera tilt about its own x axis with Cv and tz is: the SVD finds it as a fourth one,
    # shown as it is with Su and Sv fixed (unmixed with the gauge and the camera shift).
    unnamed = [d for d in rep.directions if d.kind == "unnamed"]
    assert len(unnamed) == 1 and unnamed[0].status == "null"
    assert [n for n, _ in unnamed[0].top(3)] == ["Cv", "tz", "rot_x"]
    assert unnamed[0].loadings["Su"] == pytest.approx(0, abs=1e-9)
    assert unnamed[0].loadings["Sv"] == pytest.approx(0, abs=1e-9)
    tilt = hmlvs.identifiability(paper.fit, paper.truth, fixed=("Su", "Sv")).directions
    tilt = next(d for d in tilt if d.kind == "unnamed")
    assert abs(sum(unnamed[0].loadings[n] * v for n, v in tilt.loadings.items())) == \
        pytest.approx(1.0, abs=1e-9)  # the same direction
    text = rep.summary()
    for name in ("scale gauge", "gimbal lock", "camera shift along its y axis"):
        assert name in text
    assert rep.suggested_fixed == ("Su", "Sv", "Cv")


def test_paper_data_full_rank_after_fixing_su_sv_cu_cv(paper):
    rep = hmlvs.identifiability(paper.fit, paper.truth, fixed=("Su", "Sv", "Cu", "Cv"))
    assert rep.full_rank and rep.rank == rep.num_free == 10
    assert rep.condition_number < 1e3  # 452 on this data set
    assert rep.relative_singular_values[-1] > 1e-3
    # Only the Euler chart's gimbal lock remains: the rotation is determined, omega and varphi
    # separately are not.
    assert rep.euler_rank == 9
    assert [d.kind for d in rep.directions] == ["gimbal_lock"]
    assert rep.directions[0].parametrization_only
    status = {d.kind: d.status for d in rep.known}
    assert status == {"scale_gauge": "removed", "camera_y_shift": "removed",
                      "gimbal_lock": "null"}
    assert rep.suggested_fixed == ()
    assert "full rank" in rep.summary()


@pytest.mark.parametrize("fixed, rank, kinds, suggested", [
    (("Su",), 11, {"gimbal_lock", "camera_y_shift", "unnamed"}, ("Sv", "Cv")),
    (("Su", "Sv"), 11, {"gimbal_lock", "unnamed"}, ("Cv",)),
    # Sv fixed, Su free: neither the gauge nor the camera shift alone, but their combination
    (("Sv",), 11, {"gimbal_lock", "scale_gauge+camera_y_shift", "unnamed"}, ("Su", "Cv")),
    (("Cu", "Cv", "H"), 10, {"gimbal_lock", "scale_gauge"}, ("Su",)),
])
def test_paper_data_fixings(paper, fixed, rank, kinds, suggested):
    rep = hmlvs.identifiability(paper.fit, paper.truth, fixed=fixed)
    assert rep.rank == rank
    assert {d.kind for d in rep.directions} == kinds
    assert all(d.status == "null" for d in rep.directions)
    assert rep.suggested_fixed == suggested
    # fixing the suggested ones too leaves the data full rank
    assert hmlvs.identifiability(paper.fit, paper.truth, fixed=fixed + suggested).full_rank


def test_known_tangents_are_exact_null_vectors_and_exact_finite_moves():
    truth = hmlvs.Parameters.nominal().replace(**GENERIC)
    ds = hmlvs.simulate(truth, seed=3).fit
    q = truth.to_array()
    _, j = residual_jacobian(q, ds.pixels, ds.poses, ds.points)
    j = j.reshape(-1, 14)
    scale = np.abs(j).max()
    for t in (scale_gauge_tangent(q), camera_y_tangent(q)):
        assert np.abs(j @ t).max() < 1e-12 * scale * np.abs(t).max()
    # finite moves along them leave every residual at 0 (the tangents are not just first
    # order): camera 2 mm along its y axis; gauge l = 1.3 with k != 0
    d = 2.0
    q2 = q.copy()
    q2[6], q2[2] = q[6] - d, q[2] * (1 - d / q[6])
    q2[4] = q[4] + q[0] / q2[2] * d / q[6] * math.tan(q[7])
    q2[11:14] = q[11:14] + d * hmlvs.models.paper.hand_from_camera(q)[:3, 1]
    assert np.abs(hmlvs.models.paper.residuals(q2, ds.pixels, ds.poses, ds.points)).max() < 1e-9
    qk = truth.replace(k=0.003).to_array()
    dsk = hmlvs.simulate(hmlvs.Parameters.from_array(qk), seed=3).fit
    q3 = qk.copy()
    q3[[0, 1, 2]] *= 1.3
    q3[5] /= 1.3**2
    assert np.abs(hmlvs.models.paper.residuals(q3, dsk.pixels, dsk.poses, dsk.points)).max() < 1e-9
    # the gimbal tangent is null exactly at phi = 0 and far from null at phi = 0.12
    q0 = truth.replace(phi=0.0).to_array()
    _, j0 = residual_jacobian(q0, ds.pixels, ds.poses, ds.points)
    assert np.abs(j0.reshape(-1, 14) @ gimbal_tangent()).max() < 1e-12 * scale
    assert np.abs(j @ gimbal_tangent()).max() > 1e-2 * np.abs(j[:, 8]).max()


def test_rotation_jacobian_matches_autodiff_euler_jacobian():
    # dE/d(Euler) = dE/d(delta) B, with B the Euler-rate map: checks both against C++ autodiff
    truth = hmlvs.Parameters.nominal().replace(k=0.004, **GENERIC)
    ds = hmlvs.simulate(truth, seed=5).fit
    _, j = residual_jacobian(truth, ds.pixels, ds.poses, ds.points)
    jd = rotation_jacobian(truth, ds)
    np.testing.assert_allclose(jd @ euler_rate_map(truth), j[:, :, 8:11], rtol=0,
                               atol=1e-11 * np.abs(j[:, :, 8:11]).max())
    # at phi = 0 the first and last columns of B coincide (the gimbal lock)
    b0 = euler_rate_map(truth.replace(phi=0.0))
    np.testing.assert_allclose(b0[:, 0], b0[:, 2], atol=1e-15)


def test_with_distortion_the_exact_directions_become_weak():
    # docs/model.md: with k != 0 the camera shift (and the tilt) are only weakly determined.
    truth = hmlvs.Parameters.nominal().replace(k=0.002, omega=0.1, phi=0.12, varphi=-0.07)
    ds = hmlvs.simulate(truth, seed=3).fit
    rep = hmlvs.identifiability(ds, truth, fixed=("Su",))
    assert rep.full_rank and rep.rank == 13
    rel = rep.relative_singular_values
    assert NULL_TOL < rel[-1] < rel[-2] < WEAK_TOL < 10 * WEAK_TOL < rel[-3]
    by_kind = {d.kind: d for d in rep.directions}
    assert set(by_kind) == {"camera_y_shift", "unnamed"}
    cam = by_kind["camera_y_shift"]
    assert cam.status == "weak" and cam.in_flat > 0.99 and cam.gain > WEAK_TOL
    # away from the gimbal lock the Euler angles are fine
    assert {d.kind: d.status for d in rep.known}["gimbal_lock"] == "determined"
    # with k = 0.02 the data determine them well enough (relative singular values > 1e-4)
    truth2 = truth.replace(k=0.02)
    rep2 = hmlvs.identifiability(hmlvs.simulate(truth2, seed=3).fit, truth2, fixed=("Su",))
    assert rep2.directions == () and rep2.relative_singular_values[-1] > WEAK_TOL


def test_data_warnings_too_few_points_one_pose_one_line(paper):
    few = paper.dataset.subset(range(20))
    rep = hmlvs.identifiability(few, paper.truth, fixed=("Su",))
    assert any(w.startswith("too few points: 20 calibration points for 13 free") for w in
               rep.warnings)
    # one pose: the same base_from_hand for every point, pixels spread over the image
    pose = paper.fit.poses[0]
    pts, _ = hmlvs.models.paper.points_in_base(paper.truth, paper.fit.pixels,
                                               np.repeat(pose[None], 50, 0))
    one = hmlvs.Dataset(paper.fit.pixels, np.repeat(pose[None], 50, 0), pts)
    rep = hmlvs.identifiability(one, paper.truth)
    assert any("nearly the same hand pose" in w for w in rep.warnings)
    assert any("pose variety" in r for r in rep.recommendations)
    assert not any("one image line" in w for w in rep.warnings)
    # one stripe line in the image (v = 200 + u / 10), seen from varied poses
    u = np.linspace(10, 630, 50)
    line_px = np.column_stack([u, 200 + u / 10])
    pts, _ = hmlvs.models.paper.points_in_base(paper.truth, line_px, paper.fit.poses)
    line = hmlvs.Dataset(line_px, paper.fit.poses, pts)
    rep = hmlvs.identifiability(line, paper.truth, fixed=("Su", "Sv", "Cu", "Cv"))
    assert any("one image line" in w for w in rep.warnings)
    assert not rep.full_rank  # and indeed the pixel-to-plane map is not determined
    assert not any("too few" in w or "same hand pose" in w for w in
                   hmlvs.identifiability(paper.fit, paper.truth).warnings)


def test_calibrate_warns_about_flat_directions_and_stores_the_report(paper):
    with pytest.warns(hmlvs.HmlvsDataWarning) as rec:
        # Su alone held (the default gauge would remove the flat directions looked for)
        r = hmlvs.calibrate(paper, method="lm", initial=paper.truth, threads=1, fixed=("Su",),
                            judge=False).solve
    messages = [str(w.message) for w in rec if issubclass(w.category, hmlvs.HmlvsDataWarning)]
    assert any("camera shift along its y axis" in m for m in messages)
    assert any("gimbal lock" in m for m in messages)
    assert all(m in r.warnings for m in messages)
    assert r.identifiability is not None and r.identifiability.rank == 11
    assert r.uncertainty is not None
    # a well-posed fit away from the gimbal lock: no warning at all
    truth = hmlvs.Parameters.nominal().replace(**GENERIC)
    sim = hmlvs.simulate(truth, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", hmlvs.HmlvsDataWarning)
        r2 = hmlvs.calibrate(sim, method="lm", initial=truth, fixed=("Su", "Sv", "Cu", "Cv"),
                             threads=1, judge=False).solve
    assert r2.warnings == [] and r2.identifiability.full_rank


def test_calibrate_warns_about_too_few_points(paper):
    ds = paper.dataset.subset(range(20))
    with pytest.warns(hmlvs.HmlvsDataWarning, match="too few points: 20 calibration points"):
        hmlvs.calibrate(ds, method="lm", initial=paper.truth, fixed=("Su", "Sv", "Cu", "Cv"),
                        threads=1)


@pytest.mark.parametrize("kwargs, match", [
    ({"fixed": ("Su", "focal")}, "'focal' is not a parameter"),
    ({"fixed": hmlvs.models.params.NAMES}, "every parameter is fixed"),
    ({"params": [1.0, 2.0]}, "params must be 14 finite values"),
    ({"null_tol": 1e-3, "weak_tol": 1e-4}, "need 0 < null_tol < weak_tol < 1"),
    ({"dataset": "points.npz"}, "dataset must be an hmlvs.Dataset, got str"),
])
def test_identifiability_bad_input(paper, kwargs, match):
    args = {"dataset": paper.fit, "params": paper.truth, **kwargs}
    with pytest.raises(ValueError, match=match):
        hmlvs.identifiability(**args)
