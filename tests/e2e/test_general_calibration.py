"""End to end on rendered images of a general sensor (OpenCV distortion, a laser plane 1.5
degrees off the paper's family, a camera turned 93 degrees on the flange, the board's pose not
given): `hmlvs calibrate DIR` picks the opencv model and recovers the sensor."""

from __future__ import annotations

import json

import cv2
from hmlvs.cli import main
from hmlvs.data.calibration_file import Calibration
from hmlvs.sim.general import general_session, render_general_session
import numpy as np
import pytest

pytestmark = pytest.mark.scene  # rendered images


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("general")
    session = general_session(views=12, seed=1)
    render_general_session(session, out)
    return session, out


def _map_error(sensor, session) -> np.ndarray:
    """3D error (mm) of every true stripe pixel mapped to the base with ``sensor`` against
    the true sensor: the calibration's error alone, without stripe noise."""
    errs = []
    for i in range(len(session)):
        px = session.stripe_pixels(i)
        poses = np.repeat(session.base_from_hand[i][None], len(px), axis=0)
        got, _ = sensor.points_in_base(px, poses, on_invalid="mask")
        true, _ = session.sensor.points_in_base(px, poses, on_invalid="mask")
        errs.append(np.linalg.norm(got - true, axis=1))
    return np.concatenate(errs)


def test_calibrate_from_images_alone_recovers_the_general_sensor(rendered, tmp_path, capsys):
    session, folder = rendered
    out = tmp_path / "cal.yaml"
    with pytest.raises(SystemExit) as e:
        main(["calibrate", str(folder), "--out", str(out), "--report",
              str(tmp_path / "r.html"), "--json"])
    assert e.value.code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["model"] == "opencv" and doc["solve"]["mode"] == "chain"
    assert doc["solve"]["rank"] == doc["solve"]["unknowns"] and doc["solve"]["not_determined"] == []
    cal = Calibration.load(out)
    s, t, sd = cal.sensor, session.sensor, cal.std
    # Every parameter within 4 of its reported standard deviations (3 sigma plus a margin
    # for the 30-odd numbers compared; measured here: all within 1.5).
    for name, true in t.intrinsics().items():
        assert abs(s.intrinsics()[name] - true) < 4 * sd[name], name
    assert abs(s.laser_plane[3] - t.laser_plane[3]) < 4 * sd["plane_d"]
    for i, c in enumerate("xyz"):
        assert abs(s.hand_from_camera[i, 3] - t.hand_from_camera[i, 3]) < 4 * sd[f"hand_t{c}"]
        assert abs(s.base_from_board[i, 3] - t.base_from_board[i, 3]) < 4 * sd[f"board_t{c}"]
    d_rot = cv2.Rodrigues(s.hand_from_camera[:3, :3] @ t.hand_from_camera[:3, :3].T)[0].ravel()
    for k, c in enumerate("xyz"):
        assert abs(d_rot[k]) < 4 * sd[f"hand_r{c}"], c
    # The laser plane's tilt out of the paper's family is found (1.5 degrees).
    assert abs(s.laser_plane[0] - t.laser_plane[0]) < 1e-3
    # Mapped to the base, the stripe lands within a few hundredths of a mm of the truth
    # (measured 0.02 mm RMS with 20 views; fewer views here).
    err = _map_error(s, session)
    assert np.sqrt(np.mean(err**2)) < 0.06
    assert (tmp_path / "r.html").read_text().count("data:image/png") == 3
    # The camera blur fitted to the session is kept for measurement: 0.6 px rendered, about
    # 0.44 px^2 with the pixel's area (fits on this renderer measured 0.25-0.61).
    assert cal.blur_var is not None and 0.15 < cal.blur_var < 1.0, cal.blur_var


def test_paper_model_can_start_from_the_opencv_calibration(rendered, tmp_path):
    from hmlvs.data.guess import read_initial

    session, folder = rendered
    out = tmp_path / "cal.yaml"
    with pytest.raises(SystemExit):
        main(["calibrate", str(folder), "--model", "opencv", "--out", str(out), "--quiet"])
    start = read_initial(out)
    # the paper's parameters of the calibrated sensor: its camera and laser (minus the
    # plane's 1.5-degree tilt, which the paper's model cannot hold)
    assert start.f / start.Su == pytest.approx(session.sensor.fx, rel=1e-3)
    assert start.Cu == pytest.approx(session.sensor.cx, abs=1.0)
    assert start.H > 0 and 0 < start.theta < np.pi / 2


@pytest.mark.slow
def test_the_paper_model_calibrates_the_session_from_the_opencv_calibration(rendered, tmp_path,
                                                                           capsys):
    """`--model paper --initial <opencv cal.yaml>` on a session whose manifest does not place
    the board: the board sits where the opencv calibration put it (so the corners are
    numbered), and the Table 2 ranges widen to hold the guess (a barrel lens has k < 0, the
    camera is turned 93 degrees on the flange), each said in a note. The paper's model does
    not fit this sensor, and the verdict says so."""
    _session, folder = rendered
    cal = tmp_path / "cal.yaml"
    with pytest.raises(SystemExit) as e:
        main(["calibrate", str(folder), "--out", str(cal), "--quiet"])
    assert e.value.code == 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(["calibrate", str(folder), "--model", "paper", "--initial", str(cal), "--mode",
              "homography", "--out", str(tmp_path / "paper.yaml"), "--json", "--quiet"])
    doc = json.loads(capsys.readouterr().out)
    # the paper's model cannot hold the plane's 1.5-degree tilt: its fit stays mm off
    # (measured 6.5-6.9 mm RMS), and the verdict says not to trust it (exit 3)
    assert e.value.code == 3
    assert not doc["verdict"]["trustworthy"]
    assert any("from their reference positions" in r for r in doc["verdict"]["reasons"])
    used = [im for im in doc["images"] if im["ok"]]
    assert len(used) >= len(doc["images"]) - 1, [im["reason"] for im in doc["images"]]
    assert any(n.startswith("the search range of k widened to [") for n in doc["notes"])
    assert any(n.startswith("the search range of varphi widened") or
               n.startswith("the search range of omega widened") for n in doc["notes"])
    assert 1.0 < doc["fit_rms_mm"] < 20.0
