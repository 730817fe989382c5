"""A user's initial guess and bounds for the paper model, and the opencv -> paper start."""

from __future__ import annotations

import math

from conftest import run_cli
from hmlvs import Bounds, Parameters
from hmlvs.data.export import sensor_of
from hmlvs.data.guess import read_bounds, read_initial
from hmlvs.models.convert import euler_zyz, paper_params_of
from hmlvs.models.paper import hand_from_camera, points_in_camera
import numpy as np
import pytest


def _generic() -> Parameters:
    d = Parameters.nominal().to_dict()
    d.update(k=0.004, omega=0.05, phi=0.1, varphi=-0.03, ty=2.0)
    return Parameters(**d)


def test_paper_params_of_inverts_sensor_of():
    p = _generic()
    q = paper_params_of(sensor_of(p, (640, 480)), su=p.Su)
    for name, v in p.to_dict().items():
        assert getattr(q, name) == pytest.approx(v, rel=1e-5, abs=1e-8), name
    px = np.c_[np.linspace(0, 639, 50), np.linspace(250, 479, 50)]
    a, _ = points_in_camera(p, px)
    b, _ = points_in_camera(q, px)
    assert np.abs(a - b).max() < 1e-4  # mm


def test_euler_zyz_round_trip_and_gimbal_lock():
    p = _generic()
    r = hand_from_camera(p)[:3, :3]
    assert euler_zyz(r) == pytest.approx((p.omega, p.phi, p.varphi), abs=1e-12)
    d = Parameters.nominal().to_dict()
    d.update(omega=0.2, phi=0.0, varphi=0.1)
    om, ph, va = euler_zyz(hand_from_camera(Parameters(**d))[:3, :3])
    assert ph == 0.0 and om + va == pytest.approx(0.3)


def test_plus_minus_bounds_are_absolute(tmp_path):
    guess = Parameters(**{**Parameters.nominal().to_dict(), "tx": 2.0, "phi": 0.08})
    f = tmp_path / "bounds.yaml"
    f.write_text("tx: {plus_minus: 5}\nphi: {plus_minus: 0.1}\nf: [7, 9]\n")
    b = read_bounds(f, guess)
    i = list(Parameters.nominal().to_dict()).index
    assert (b.lower[i("tx")], b.upper[i("tx")]) == (-3.0, 7.0)  # not 1.5-2.5 (a fraction)
    assert b.lower[i("phi")] == pytest.approx(-0.02) and b.upper[i("phi")] == pytest.approx(0.18)
    assert (b.lower[i("f")], b.upper[i("f")]) == (7.0, 9.0)
    assert b.lower[i("H")] == Bounds.table2().lower[i("H")]


@pytest.mark.parametrize("text, message", [
    ("tx: 5\n", r"tx must be \[lower, upper\] or \{plus_minus: h\}"),
    ("tq: [1, 2]\n", "'tq' is not a parameter"),
    ("tx: {plus_minus: -1}\n", "plus_minus must be a number >= 0"),
    ("f: [9, 7]\n", "lower 9 > upper 7"),
    ("f: [9, 10]\n", "initial value of f lies outside its bounds"),
    ("- 1\n", "must be a mapping"),
])
def test_bad_bounds_files_are_named(tmp_path, text, message):
    f = tmp_path / "b.yaml"
    f.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_bounds(f, Parameters.nominal())


def test_initial_from_a_mapping_and_from_an_opencv_calibration(tmp_path):
    f = tmp_path / "guess.yaml"
    f.write_text("f: 8.2\nH: 135\n")
    g = read_initial(f)
    assert g.f == 8.2 and g.H == 135 and g.Cu == Parameters.nominal().Cu
    f.write_text("f: eight\n")
    with pytest.raises(ValueError, match="f must be a number"):
        read_initial(f)
    from hmlvs.data.calibration_file import Calibration

    p = _generic()
    cal = Calibration(params=None, sensor=sensor_of(p, (640, 480)), model="opencv")
    path = cal.save(tmp_path / "cal.yaml")
    q = read_initial(path)
    assert q.H == pytest.approx(p.H) and q.theta == pytest.approx(p.theta)
    assert math.isclose(q.f, p.f, rel_tol=1e-9)


def test_cli_takes_initial_and_bounds_files(tmp_path, capsys):
    import json

    sim = tmp_path / "sim.npz"
    assert run_cli(["simulate", str(sim), "--poses", "12", "--seed", "3"], capsys)[0] == 0
    guess = tmp_path / "guess.yaml"
    guess.write_text("H: 138\n")
    bounds = tmp_path / "bounds.yaml"
    bounds.write_text("H: {plus_minus: 10}\ntheta: [0.3, 0.6]\n")
    code, out, _ = run_cli(["calibrate", str(sim), "--method", "lm", "--initial", str(guess),
                         "--bounds", str(bounds), "--out", str(tmp_path / "cal.yaml"),
                         "--json"], capsys)
    assert code == 0
    assert 128 <= json.loads(out)["parameters"]["H"] <= 148
    # a bounds file the guess falls outside of is refused before any solve
    bounds.write_text("H: [100, 110]\n")
    code, _, err = run_cli(["calibrate", str(sim), "--method", "lm", "--initial", str(guess),
                         "--bounds", str(bounds), "--out", str(tmp_path / "cal2.yaml")], capsys)
    assert code != 0 and "initial value of H lies outside its bounds" in err
    assert not (tmp_path / "cal2.yaml").exists()


@pytest.mark.parametrize("text", ["f: 0\n", "Su: -0.0074\n", "Sv: 0\nf: 0\n"])
def test_an_initial_guess_without_a_positive_focal_length_or_pitch_is_refused(tmp_path, text):
    # before, f: 0 was taken and the search range widened to [-0.4, 10] to hold it
    from hmlvs.data.guess import read_initial

    f = tmp_path / "i.yaml"
    f.write_text(text)
    with pytest.raises(ValueError, match=r"i.yaml: .* must be > 0"):
        read_initial(f)
