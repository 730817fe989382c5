"""Measurement from rendered laser on/off images, end to end."""

import json

import numpy as np
import pytest

import hmlvs
from hmlvs.cli import main as cli_main
from hmlvs.measure import measure_images


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("scan")
    session = hmlvs.simulate.session(num_poses=4, seed=5)
    r = hmlvs.simulate.render_session(session, out)
    return session, out, r


def test_board_scan_lies_on_the_board_plane(rendered):
    session, out, _ = rendered
    cloud, info = measure_images(session.truth, out)
    assert info["used"] == 4 and not info["rejected"]
    z = cloud.valid_points()[:, 2]  # the board is the plane z = 0 of the base frame
    assert cloud.num_valid > 4 * 300
    assert np.sqrt(np.mean(z**2)) < 0.05, np.sqrt(np.mean(z**2))
    assert set(np.unique(cloud.pose_index)) == {0, 1, 2, 3}


def test_bad_pair_is_reported_and_the_rest_goes_through(rendered, tmp_path):
    session, out, _ = rendered
    doc = json.loads((out / "manifest.json").read_text())
    doc["poses"][1]["off"] = "missing.png"
    (out / "manifest2.json").write_text(json.dumps(doc))
    cloud, info = measure_images(session.truth, out / "manifest2.json")
    assert info["used"] == 3 and list(info["rejected"]) == ["p001"]
    assert "missing.png does not exist" in info["rejected"]["p001"]
    assert set(np.unique(cloud.pose_index)) == {0, 2, 3}  # the manifest's indices, no shift


def test_cli_measure_images(rendered, tmp_path, capsys):
    session, out, _ = rendered
    cal = hmlvs.Calibration(params=session.truth).save(tmp_path / "cal.yaml")
    with pytest.raises(SystemExit) as e:
        cli_main(["measure", str(cal), str(out), "--out", str(tmp_path / "c.ply"), "--json"])
    assert e.value.code == 0
    s = json.loads(capsys.readouterr().out)
    assert s["used"] == 4 and s["points"] > 1000 and (tmp_path / "c.ply").exists()
