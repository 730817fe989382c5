"""Measurement from rendered laser on/off images, end to end."""

import json

import hmlvs
from hmlvs.cli import main as cli_main
from hmlvs.measurement.measure import measure_images
import numpy as np
import pytest

pytestmark = pytest.mark.scene  # simulated sessions or rendered images


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("scan")
    session = hmlvs.simulate.session(num_poses=4, seed=5)
    r = hmlvs.simulate.render_session(session, out)
    return session, out, r


def test_board_scan_lies_on_the_board_plane(rendered):
    session, out, _ = rendered
    m = measure_images(session.truth, out)
    cloud = m.cloud
    assert m.images == 4 and m.used == 4 and m.rejected == ()
    assert m.ids == ["p000", "p001", "p002", "p003"]
    z = cloud.valid_points()[:, 2]  # the board is the plane z = 0 of the base frame
    assert cloud.num_valid > 4 * 300
    assert np.sqrt(np.mean(z**2)) < 0.05, np.sqrt(np.mean(z**2))
    assert set(np.unique(cloud.pose_index)) == {0, 1, 2, 3}


def test_bad_pair_is_reported_and_the_rest_goes_through(rendered, tmp_path):
    session, out, _ = rendered
    doc = json.loads((out / "manifest.json").read_text())
    doc["poses"][1]["off"] = "missing.png"
    (out / "manifest2.json").write_text(json.dumps(doc))
    m = measure_images(session.truth, out / "manifest2.json")
    cloud = m.cloud
    assert m.images == 4 and m.used == 3 and m.ids == ["p000", "p002", "p003"]
    assert [r.id for r in m.rejected] == ["p001"]
    assert "missing.png does not exist" in m.rejected[0].reason
    assert m.summary()["rejected"] == {"p001": m.rejected[0].reason}
    assert set(np.unique(cloud.pose_index)) == {0, 2, 3}  # the manifest's indices, no shift


def test_cli_measure_images(rendered, tmp_path, capsys):
    session, out, _ = rendered
    cal = hmlvs.Calibration(params=session.truth).save(tmp_path / "cal.yaml")
    with pytest.raises(SystemExit) as e:
        cli_main(["measure", str(cal), str(out), "--out", str(tmp_path / "c.ply"), "--json"])
    assert e.value.code == 0
    s = json.loads(capsys.readouterr().out)
    assert s["used"] == 4 and s["points"] > 1000 and (tmp_path / "c.ply").exists()


def _write(path, doc):
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda d: d["poses"][2].pop("id"), r"manifest2.json: entry 2 has no id"),
        (lambda d: d["poses"][3].update(id="p000"), r"entry 3 \(id p000\) repeats the id of "
                                                    "entry 0"),
        (lambda d: d["poses"][1].pop("joints"), r"entry 1 \(id p001\) has neither 'joints' nor "
                                                "'pose', but other entries do"),
        (lambda d: d["poses"][0].update(stripe="x.csv"), r"entry 0 \(id p000\) must name either "
                                                         "an image pair"),
        # (an entry with 'on' and no 'off' is a laser-on image alone, issue 14: valid)
        (lambda d: d["poses"][0].pop("on"), r"entry 0 \(id p000\) names a laser-off image but "
                                            "no laser-on image"),
        (lambda d: d.update(format="other"), "not an hmlvs image manifest"),
        (lambda d: d["poses"][0].update(pose=[[1, 0], [0, 1]], joints=None) or
         d["poses"][0].pop("joints"), r"entry 0 \(id p000\): pose: must be a 4x4 "
         "base_from_hand matrix of 4 items, got 2"),
    ],
)
def test_malformed_manifests_name_file_and_entry(rendered, change, match):
    session, out, _ = rendered
    doc = json.loads((out / "manifest.json").read_text())
    change(doc)
    with pytest.raises(ValueError, match=match):
        measure_images(session.truth, _write(out / "manifest2.json", doc))


def test_pose_entries_and_stripe_lists(rendered, tmp_path):
    session, out, _ = rendered
    doc = json.loads((out / "manifest.json").read_text())
    poses = session.robot.poses(session.joints)
    ref = measure_images(session.truth, out).cloud
    # entry 0 by pose instead of joints: the same points
    e0 = doc["poses"][0]
    e0["pose"] = poses[0].tolist()
    del e0["joints"]
    # entry 1 as a stripe list (u, v, intensity) written from the true stripe of that pose
    pts = session.dataset.points[session.dataset.pose_index == 1]
    px, _ = hmlvs.models.paper.pixels_from_points(session.truth, pts,
                                                  np.repeat(poses[1:2], len(pts), 0))
    np.savetxt(out / "p001.csv", np.c_[px, np.ones(len(px))], delimiter=",",
               header="u,v,intensity", comments="")
    doc["poses"][1] = {"id": "p001", "stripe": "p001.csv", "joints": session.joints[1].tolist()}
    m = measure_images(session.truth, _write(out / "manifest3.json", doc))
    cloud = m.cloud
    assert m.used == 4
    np.testing.assert_allclose(cloud.points[cloud.pose_index == 0],
                               ref.points[ref.pose_index == 0], atol=1e-9)
    np.testing.assert_allclose(cloud.points[cloud.pose_index == 1], pts, atol=1e-6)
    # a stripe list that is not numbers only rejects its own entry
    (out / "p001.csv").write_text("u,v\n1,abc\n")
    m = measure_images(session.truth, out / "manifest3.json")
    assert m.rejected_reasons.keys() == {"p001"} and "p001.csv" in m.rejected_reasons["p001"]
    assert m.used == 3 and len(m.cloud) < len(cloud)


def test_measure_accepts_image_pairs(rendered):
    import cv2

    session, out, _ = rendered
    poses = session.robot.poses(session.joints)
    pairs = [(cv2.imread(str(out / f"p{i:03d}_on.png"), cv2.IMREAD_UNCHANGED),
              cv2.imread(str(out / f"p{i:03d}_off.png"), cv2.IMREAD_UNCHANGED)) for i in range(4)]
    cloud = hmlvs.measure(session.truth, pairs, poses)
    z = cloud.valid_points()[:, 2]  # the board plane z = 0
    assert cloud.num_valid > 1000 and np.sqrt(np.mean(z**2)) < 0.1
