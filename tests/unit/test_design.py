"""Sensor design analysis (hmlvs.paper.design) against hand-computed values.

The paper's design: f = 8 mm, 7.4 um pixels, 640 x 480 px, H = 100 mm, theta = 25 deg,
principal point at the image centre (319.5, 239.5), k = 0. By hand (docs/model.md, step 3):

    f tan(theta) = 8 * 0.4663077 = 3.730461 mm
    row 0:   Yd = -239.5 * 0.0074 = -1.7723 mm, D = Yd + f tan(theta) = 1.958161 mm,
             z = H f / D = 800 / 1.958161 = 408.5465 mm   (the farthest row)
    row 479: D = 1.7723 + 3.730461 = 5.502761 mm, z = 800 / 5.502761 = 145.3816 mm (nearest)
    column 0 / 639: Xd = -/+ 319.5 * 0.0074 = -/+ 2.3643 mm
    stripe length on a row at depth z: (639 * 0.0074 / 8) z = 0.591075 z

Every literal below was worked out from these lines; the comments show how.
"""

import json
import math

from hmlvs.paper import design
import numpy as np
import pytest
import reference_model as ref

TAN25 = math.tan(math.radians(25.0))
Z_FAR = 800 / 1.958161265239989   # 408.5465
Z_NEAR = 800 / 5.502761265239989  # 145.3816


@pytest.fixture(scope="module")
def paper():
    return design.analyze()


def test_import_hmlvs_is_light():
    """``import hmlvs`` loads the C++ core and nothing heavy: SciPy's optimizers, matplotlib
    and OpenCV come with the functions that need them (hmlvs.paper.design among them)."""
    import subprocess
    import sys

    code = ("import sys, hmlvs; heavy = ['scipy.optimize', 'matplotlib', 'cv2', 'scipy']; "
            "print([m for m in heavy if m in sys.modules]); hmlvs.paper.design.analyze; "
            "print(hmlvs.paper.design.__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split("\n")
    assert out[0] == "[]" and out[1] == "hmlvs.paper.design"


def test_points_at_pixels(paper):
    # (0, 0): rho = 100 / 1.958161 = 51.06833; P = rho (Xd, Yd, f)
    np.testing.assert_allclose(paper.points[0, 0], [-120.740822, -90.508378, 408.546535],
                               rtol=1e-8)
    # (639, 479): rho = 100 / 5.502761 = 18.17269
    np.testing.assert_allclose(paper.points[479, 639], [42.9657019, 32.2074667, 145.3815569],
                               rtol=1e-8)
    assert paper.usable.all() and paper.usable_fraction == 1.0
    assert paper.usable_rows == (0, 479)


def test_ranges(paper):
    r = paper.ranges
    assert r.z_far == pytest.approx(408.546535, rel=1e-8)
    assert r.z_near == pytest.approx(145.381557, rel=1e-8)
    assert r.z == pytest.approx(263.164978, rel=1e-8)          # 408.5465 - 145.3816
    assert r.y == pytest.approx(263.164978 * TAN25, rel=1e-8)  # 122.7158: on y + z tan = H
    assert (r.row_far, r.row_near) == (0, 479)
    assert r.x_width_far == pytest.approx(0.591075 * 408.546535, rel=1e-8)   # 241.4816
    assert r.x_width_near == pytest.approx(0.591075 * 145.381557, rel=1e-8)  # 85.9314
    assert r.x_growth == pytest.approx(155.550239, rel=1e-8)   # 0.591075 * 263.1650
    assert r.x_extent == pytest.approx(r.x_width_far, rel=1e-12)  # k = 0: far row is widest
    # mid depth (408.5465 + 145.3816) / 2 = 276.964 is nearest row 126:
    # D = (126 - 239.5) 0.0074 + 3.730461 = 2.890561, z = 276.7629, length 163.5876
    assert r.row_mid == 126
    assert r.x_width_mid == pytest.approx(163.587607, rel=1e-8)


def test_paper_numbers_need_rows_239_px_either_side():
    # 478 row pitches about Cv (rows -239..239) instead of 479: z_far = 800 / 1.961861
    # = 407.7760, z_near = 800 / 5.499061 = 145.4794, and x, y, z = 155.0, 122.3, 262.3.
    r = design.analyze(image_size=(640, 479), principal_point=(319.5, 239.0)).ranges
    assert r.z == pytest.approx(262.296655, rel=1e-8)
    assert (round(r.x_growth, 1), round(r.y, 1), round(r.z, 1)) == (155.0, 122.3, 262.3)


def test_principal_point_of_table2_moves_the_range():
    # Cv = 240: row 0 has Yd = -1.776, D = 1.954461, z = 409.3200; row 479 has
    # Yd = 239 * 0.0074 = 1.7686, D = 5.499061, z = 145.4794
    r = design.analyze(principal_point=(320.0, 240.0)).ranges
    assert r.z == pytest.approx(800 / 1.954461265239989 - 800 / 5.499061265239989, rel=1e-10)
    assert r.z == pytest.approx(263.840581, rel=1e-8)


def test_resolution_at_pixels(paper):
    ru, rv = paper.resolution_u, paper.resolution_v
    # along u (k = 0): rho Su, constant along a row
    assert ru[0, 0] == pytest.approx(0.0074 * 100 / 1.958161265, rel=1e-8)  # 0.3779055
    assert ru[479, 0] == pytest.approx(0.0074 * 100 / 5.502761265, rel=1e-8)  # 0.1344779
    # along v: the half-row steps have D +- 0.0037; |dP| = H Sv / (D+ D-) *
    # sqrt(Xd^2 + f^2 / cos^2 theta)
    # (0, 0): 0.74 / (1.961861 * 1.954461) * sqrt(2.3643^2 + 77.9157) = 1.763583
    assert rv[0, 0] == pytest.approx(1.763582842, rel=1e-8)
    # (320, 479): Xd = 0.0037: 0.74 / (5.506461 * 5.499061) * sqrt(0.0037^2 + 77.9157)
    assert rv[479, 320] == pytest.approx(0.215717256, rel=1e-8)
    q = paper.resolution
    assert q.u_max == pytest.approx(0.377905545, rel=1e-8)
    assert q.u_min == pytest.approx(0.134477940, rel=1e-8)
    assert q.v_max == pytest.approx(1.763582842, rel=1e-8)
    assert q.v_min == pytest.approx(0.215717256, rel=1e-8)
    # centre pixel (320, 240): D = 0.0037 + 3.730461 = 3.734161, rho Su = 0.1981703
    assert q.u_center == pytest.approx(0.198170338, rel=1e-8)
    # per axis at row 0: dz = H f Sv / (D+ D-) = 5.92 / 3.834400 = 1.543926, dy = tan * dz
    assert q.dz_dv_max == pytest.approx(1.543925522, rel=1e-8)
    assert q.dy_dv_max == pytest.approx(1.543925522 * TAN25, rel=1e-8)
    assert q.dx_du_max == pytest.approx(q.u_max, rel=1e-12)


def oracle_maps(q: np.ndarray, w: int, h: int):
    """Resolution maps by the independent NumPy model of tests/oracles/reference_model.py."""
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))

    def pts(du, dv):
        px = np.stack([u.ravel() + du, v.ravel() + dv], axis=1)
        p, ok = ref.camera_points(q, px)
        p[~ok] = np.nan
        return p.reshape(h, w, 3)

    return (pts(0, 0), np.linalg.norm(pts(0.5, 0) - pts(-0.5, 0), axis=2),
            np.linalg.norm(pts(0, 0.5) - pts(0, -0.5), axis=2))


def test_maps_and_limit_fraction_match_numpy_oracle(paper):
    q = paper.sensor.params().to_array()
    p, ru, rv = oracle_maps(q, 640, 480)
    np.testing.assert_allclose(paper.points, p, rtol=1e-12)
    np.testing.assert_allclose(paper.resolution_u, ru, rtol=1e-9)
    np.testing.assert_allclose(paper.resolution_v, rv, rtol=1e-9)
    fine = np.mean((ru <= 1.0) & (rv <= 1.0))
    assert paper.resolution.within_limit == pytest.approx(fine, abs=1e-12)
    assert 0.82 < fine < 0.83  # the far rows (v < ~85) are coarser than 1 mm/px


def test_distortion_and_odd_design_match_numpy_oracle():
    r = design.analyze(f=6.0, pixel_pitch=(0.005, 0.006), image_size=(200, 150), H=130.0,
                       theta=math.radians(20.0), k=0.02, principal_point=(90.0, 80.0))
    q = r.sensor.params().to_array()
    p, ru, rv = oracle_maps(q, 200, 150)
    np.testing.assert_allclose(r.points, p, rtol=1e-12)
    np.testing.assert_allclose(r.resolution_u, ru, rtol=1e-9)
    np.testing.assert_allclose(r.resolution_v, rv, rtol=1e-9)
    z = p[..., 2]
    assert r.ranges.z == pytest.approx(z.max() - z.min(), rel=1e-12)


@pytest.mark.parametrize("H, theta_deg", [(60.0, 15.0), (100.0, 25.0), (140.0, 40.0)])
def test_y_range_is_tan_theta_times_z_range(H, theta_deg):
    r = design.analyze(H=H, theta=math.radians(theta_deg), image_size=(64, 48),
                       pixel_pitch=0.074)
    assert r.ranges.y == pytest.approx(math.tan(math.radians(theta_deg)) * r.ranges.z,
                                       rel=1e-10)


def test_rows_past_the_horizon_are_reported():
    # theta = 10 deg: f tan = 1.410615 mm; a row sees the laser if (v - 239.5) 0.0074 >
    # -1.410615, i.e. v > 48.876: rows 49..479 (431 of 480)
    r = design.analyze(theta=math.radians(10.0))
    assert r.usable_rows == (49, 479)
    assert r.usable_fraction == pytest.approx(431 / 480, abs=1e-15)
    assert not r.usable[48].any() and r.usable[49].all()
    assert np.isnan(r.points[:49]).all()
    # row 49: D = -190.5 * 0.0074 + 1.410615 = 0.000916 mm: z = 800 / 0.000916 = 873,510 mm
    assert r.ranges.z_far == pytest.approx(873509.6187, rel=1e-7)
    assert r.ranges.row_far == 49
    # the half-row step above row 49 (v = 48.5) misses the plane: no v-resolution there
    assert np.isnan(r.resolution_v[49]).all() and np.isfinite(r.resolution_v[50]).all()
    assert "rows 49-479" in str(r)


def test_sweeps():
    s = design.sweep("H", [50.0, 100.0, 150.0])
    # P is proportional to H: ranges and resolution scale with it
    np.testing.assert_allclose(s.z, [263.164978 * h / 100 for h in (50, 100, 150)], rtol=1e-8)
    np.testing.assert_allclose(s.x_growth / s.values, 1.55550239, rtol=1e-8)
    np.testing.assert_allclose(s.res_v_max, [1.763582842 * h / 100 for h in (50, 100, 150)],
                               rtol=1e-8)
    t = design.sweep("theta", np.radians([-80.0, 25.0, 40.0]))
    # theta = -80 deg: f tan = -45.4 mm < -|Yd| everywhere: nothing seen, NaN not an error
    assert t.usable_fraction.tolist() == [0.0, 1.0, 1.0]
    assert np.isnan(t.z[0]) and t.z[1] == pytest.approx(263.164978, rel=1e-8)
    # theta = 40 deg: f tan = 6.712797; z = 800/(6.712797 - 1.7723) - 800/(6.712797 + 1.7723)
    assert t.z[2] == pytest.approx(800 / 4.940497 - 800 / 8.485097, rel=1e-7)  # 67.64407
    assert t.display_values[1] == pytest.approx(25.0)
    d = t.to_dict()
    assert d["z"][0] is None and d["unit"] == "deg"
    json.dumps(d)  # JSON-ready: NaN became None


def test_default_sweep_values():
    s = design.Sensor.make()
    np.testing.assert_allclose(design.default_sweep_values("H", s), np.arange(50, 151, 5.0))
    deg = np.degrees(design.default_sweep_values("theta", s.replace(theta=math.radians(22.5))))
    assert deg[0] == pytest.approx(15) and deg[-1] == pytest.approx(45) and len(deg) == 32


def test_error_from_wrong_H():
    # true H = 99, computed with 100: P_used - P_true = P_used / 100 = |(Xd, Yd, f)| / D
    # (0, 0): sqrt(2.3643^2 + 1.7723^2 + 64) / 1.958161 = 8.528187 / 1.958161 = 4.355231
    e = design.error_from_wrong(H=100.0, H_true=99.0)
    assert e.max == pytest.approx(4.355231151, rel=1e-8)
    assert e.worst_pixel == (0, 0)
    p, _, _ = oracle_maps(e.used.params().to_array(), 640, 480)
    np.testing.assert_allclose(e.vectors, p / 100, rtol=1e-9)
    assert e.mean == pytest.approx(np.linalg.norm(p, axis=2).mean() / 100, rel=1e-9)
    assert 2.38 < e.mean < 2.39


def test_error_from_wrong_theta():
    # true theta = 22.5 deg: D_true = -1.7723 + 8 tan(22.5) = 1.541417 at row 0;
    # (0, 0): 100 * 8.528187 * (1 / 1.541417 - 1 / 1.958161) = 117.7530 mm
    e = design.error_from_wrong(theta_true=math.radians(22.5))
    assert e.max == pytest.approx(117.752992, rel=1e-7)
    assert e.worst_pixel == (0, 0)
    pu, _, _ = oracle_maps(e.used.params().to_array(), 640, 480)
    pt, _, _ = oracle_maps(e.true.params().to_array(), 640, 480)
    assert e.mean == pytest.approx(np.linalg.norm(pu - pt, axis=2).mean(), rel=1e-9)
    assert "theta 25 deg used, true 22.5 deg" in str(e)
    cases = design.paper_errors(e.used)
    assert [c.true.H for c in cases] == [99.0, 100.0]
    assert math.degrees(cases[1].true.theta) == pytest.approx(22.5)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"theta": math.radians(95)}, r"theta must lie in \(-pi/2, pi/2\)"),
        ({"H": -5.0}, r"H must be a finite number > 0 \(mm\), got -5.0"),
        ({"H": 0.0}, "H must be a finite number > 0"),
        ({"image_size": (0, 480)}, "image width must be an integer >= 2"),
        ({"image_size": (640, 480.5)}, "image height must be an integer >= 2"),
        ({"image_size": (640,)}, r"image_size must be \(width, height\)"),
        ({"image_size": (100000, 100000)}, "too large"),
        ({"pixel_pitch": 0.0}, "pixel pitch Su must be a finite number > 0"),
        ({"pixel_pitch": (0.0074, -1)}, "pixel pitch Sv must be"),
        ({"f": float("nan")}, "f must be a finite number > 0"),
        ({"k": float("inf")}, "k must be finite"),
        ({"principal_point": (1.0,)}, r"principal_point must be \(Cu, Cv\)"),
        ({"principal_point": 320.0}, r"principal_point must be \(Cu, Cv\)"),
        ({"principal_point": (320.0, "x")}, "principal point Cv must be a number"),
        ({"resolution_limit": 0.0}, "resolution_limit must be"),
        ({"theta": math.radians(-80)}, "no pixel of the 640 x 480 image sees the laser"),
    ],
)
def test_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        design.analyze(**kwargs)


def test_bad_input_other_functions(tmp_path):
    with pytest.raises(ValueError, match="give H_true and/or theta_true"):
        design.error_from_wrong()
    with pytest.raises(ValueError, match="true value is invalid: H must be"):
        design.error_from_wrong(H_true=-1.0)
    with pytest.raises(ValueError, match="cannot sweep 'Cu'"):
        design.sweep("Cu")
    with pytest.raises(ValueError, match="at least one value"):
        design.sweep("H", [])
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("x")
    with pytest.raises(ValueError, match="is not a folder"):
        design.plot(design.analyze(image_size=(64, 48), pixel_pitch=0.074), not_a_dir,
                    sweeps=[], errors=[])


@pytest.mark.slow
def test_plot_writes_readable_pngs(tmp_path):
    import matplotlib.image

    # top rows unusable (the masked path); a 160 x 120 image of the same sensor area, for speed
    r = design.analyze(theta=math.radians(12.0), image_size=(160, 120), pixel_pitch=0.0296)
    sweeps = [design.sweep("H", [80.0, 100.0, 120.0], sensor=r.sensor),
              design.sweep("theta", np.radians([15.0, 25.0, 35.0]), sensor=r.sensor)]
    files = design.plot(r, tmp_path / "out", sweeps=sweeps,
                        errors=design.paper_errors(r.sensor))
    assert [p.name for p in files] == [
        "design_resolution.png", "design_footprint.png", "design_sweep_H.png",
        "design_sweep_theta.png", "design_error_H.png", "design_error_theta.png"]
    shapes = [matplotlib.image.imread(p).shape[:2] for p in files]
    # figure size (inches) x 100 dpi, to 1 px: matplotlib 3.7 (the lower bound) rounds
    # 4.6 in x 100 dpi down to 459 px, later releases to 460
    want = [(460, 1200), (600, 750), (460, 1200), (460, 1200), (460, 1200), (460, 1200)]
    assert np.abs(np.array(shapes) - np.array(want)).max() <= 1, shapes
    assert not list((tmp_path / "out").glob(".*.tmp"))  # atomic writes left no temporaries


def test_text_and_dict_summaries(paper):
    text = str(paper)
    assert "155.55   paper 155.0" in text and "263.16   paper 262.3" in text
    d = paper.to_dict()
    assert d["paper_ranges_mm"] == {"x": 155.0, "y": 122.3, "z": 262.3}
    assert d["ranges_mm"]["x_growth"] == pytest.approx(155.550239, rel=1e-8)
    other = design.analyze(H=120.0, image_size=(64, 48), pixel_pitch=0.074)
    assert other.to_dict()["paper_ranges_mm"] is None and "paper" not in str(other)
    md = paper.markdown(errors=design.paper_errors(paper.sensor))
    assert "| z, extent over the usable image | 263.16 | 262.3 |" in md
    assert "| H 100 mm used, true 99 mm | 4.355 | 2.387 | (0, 0) |" in md
