"""Robot descriptions: --robot FILE, a manifest's robot mapping, built-in names."""

import json

import hmlvs
from hmlvs.cli import main as cli_main
from hmlvs.data.calibration_file import Calibration
from hmlvs.data.robot_file import load_robot, save_robot
from hmlvs.image.scan import stripes_from_images
from hmlvs.measurement.measure import measure, measure_images
import numpy as np
import pytest

JOINTS = [[0.1, -0.5, 0.9, 0.4, 0.2], [-0.2, -0.6, 1.0, 0.5, -0.1], [0.0, -0.4, 0.8, 0.3, 0.6]]


def _other_arm():
    """A 5-joint arm unlike the SCORBOT (longer links, a base offset, a tool)."""
    base = np.eye(4)
    base[:3, 3] = [10.0, -20.0, 50.0]
    tool = np.eye(4)
    tool[2, 3] = 35.0
    return hmlvs.Robot.from_dh([(80, -np.pi / 2, 420), (380, 0, 0), (400, 0, 0),
                                (0, -np.pi / 2, 0), (0, 0, 180)], base_from_link0=base,
                               flange_from_hand=tool, name="test arm")


def _manifest(tmp_path, robot):
    """Stripe-list entries with joint readings (no images needed), taken with ``robot``."""
    px = np.array([[300.0, 200.0], [320.0, 260.0], [340.0, 300.0]])
    np.savetxt(tmp_path / "s.csv", px, delimiter=",", header="u,v", comments="")
    doc = {"format": "hmlvs-images", "version": 1, "joint_unit": "rad",
           "poses": [{"id": f"p{i}", "stripe": "s.csv", "joints": j}
                     for i, j in enumerate(JOINTS)]}
    if robot is not None:
        doc["robot"] = robot
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    return tmp_path / "manifest.json", px


def test_manifest_robot_mapping_is_used(tmp_path):
    arm = _other_arm()
    path, _ = _manifest(tmp_path, arm.to_dict())
    _, _, poses, reports = stripes_from_images(path)
    assert all(r.ok for r in reports)
    np.testing.assert_allclose(poses, arm.poses(JOINTS), atol=1e-9)
    assert np.abs(poses - hmlvs.Robot.scorbot_er7().poses(JOINTS)).max() > 10.0
    # the built-in name still means the SCORBOT
    path, _ = _manifest(tmp_path, "SCORBOT ER-VII")
    np.testing.assert_allclose(stripes_from_images(path)[2],
                               hmlvs.Robot.scorbot_er7().poses(JOINTS), atol=1e-9)


def test_unknown_robot_name_needs_a_description(tmp_path):
    arm = _other_arm()
    path, _ = _manifest(tmp_path, "UR10e")
    with pytest.raises(ValueError, match=r"manifest.json: the robot 'UR10e' is not a built-in "
                       r"arm \(hmlvs knows 'SCORBOT ER-VII'\); give its DH description: "
                       "--robot FILE"):
        stripes_from_images(path)
    # given in code, it is used
    np.testing.assert_allclose(stripes_from_images(path, robot=arm)[2], arm.poses(JOINTS),
                               atol=1e-9)


def test_manifest_robot_beats_the_calibrations(tmp_path):
    """A calibration made with the SCORBOT measuring a scan taken with another arm: the
    manifest says which arm took the images."""
    arm = _other_arm()
    params = hmlvs.Parameters.nominal()
    cal = Calibration(params, robot=hmlvs.Robot.scorbot_er7())
    path, px = _manifest(tmp_path, arm.to_dict())
    got = measure_images(cal, path).cloud
    want = measure(params, [px] * 3, arm.poses(JOINTS))
    np.testing.assert_allclose(got.points, want.points, atol=1e-9)
    # without a robot in the manifest, the calibration's robot is the one
    path, px = _manifest(tmp_path, None)
    cal = Calibration(params, robot=arm)
    np.testing.assert_allclose(measure_images(cal, path).cloud.points, want.points, atol=1e-9)


def test_cli_measure_with_robot_file(tmp_path, capsys):
    arm = _other_arm()
    robot_file = save_robot(arm, tmp_path / "arm.yaml")
    np.testing.assert_allclose(load_robot(robot_file).poses(JOINTS), arm.poses(JOINTS))
    cal = Calibration(hmlvs.Parameters.nominal()).save(tmp_path / "cal.yaml")
    path, px = _manifest(tmp_path, "my arm")
    out = tmp_path / "cloud.csv"
    with pytest.raises(SystemExit) as e:
        cli_main(["measure", str(cal), str(path), "--robot", str(robot_file), "--out", str(out),
                  "--json"])
    assert e.value.code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["images"] == 3 and summary["used"] == 3 and summary["rejected"] == {}
    got = np.loadtxt(out, delimiter=",", skiprows=1)[:, :3]
    want = measure(hmlvs.Parameters.nominal(), [px] * 3, arm.poses(JOINTS)).valid_points()
    np.testing.assert_allclose(got, want, atol=1e-5)
    # without --robot the unknown name is a clear error
    with pytest.raises(SystemExit) as e:
        cli_main(["measure", str(cal), str(path), "--out", str(out)])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "the robot 'my arm' is not a built-in arm" in err and "--robot FILE" in err


@pytest.mark.parametrize(
    "text, match",
    [("name: x\n", r"arm.yaml: lacks links; it must be a robot description: a mapping with "
      r"'links', a list of DH rows \{a, alpha, d\[, offset, prismatic, theta\]\}"),
     ("links: [{a: 1, alpha: 0, dd: 3}]\n", r"arm.yaml: links\[0\]: lacks d \(it has the "
      r"unknown key\(s\) 'dd'\); it must be a DH row"),
     ("links: [{a: 1, alpha: 0, d: .nan}]\n", r"arm.yaml: links\[0\]\.d: must be a finite "
      "number, got nan"),
     ("[1, 2]\n", r"arm.yaml: must be a robot description: a mapping with 'links'"),
     ("links: [{a: 1, alpha: 0, d: 3}]\nconvention: craig\n", r"arm.yaml: convention: must be "
      "one of standard, modified, got 'craig'"),
     ("links: []\n", r"arm.yaml: links: must hold at least one DH row, got \[\]"),
     ("links: [{a: 1, alpha: 0, d: '3'}]\n", r"arm.yaml: links\[0\]\.d: must be a length in "
      "mm, got '3'"),
     ("links: [{a: 1, alpha: 0, d: 3, prismatic: 1}]\n", r"arm.yaml: links\[0\]\.prismatic: "
      "must be true or false, got 1"),
     ("links: [{a: 1, alpha: 0, d: 3}]\nconventoin: modified\n", r"arm.yaml: unknown key "
      "'conventoin'; the keys are name, convention, links"),
     ("links: [{a: 1, alpha: 0, d: 3}]\nflange_from_hand: [[1, 0], [0, 1]]\n",
      r"arm.yaml: flange_from_hand: must be a 4x4 transform of 4 items, got 2"),
     ("links: [{a: 1, alpha: 0, d: 3}]\njoint_limits: [[1, 0]]\n", r"arm.yaml: malformed "
      r"robot description \(joint_limits must be \(1, 2\) with lower <= upper\)")],
)
def test_bad_robot_files(tmp_path, text, match):
    (tmp_path / "arm.yaml").write_text(text)
    with pytest.raises(ValueError, match=match):
        load_robot(tmp_path / "arm.yaml")


def test_cli_calibrate_stores_the_robot_file(tmp_path, capsys):
    arm = _other_arm()
    robot_file = save_robot(arm, tmp_path / "arm.json")
    ds = hmlvs.simulate.session(num_poses=12, seed=4).dataset.save(tmp_path / "d.npz")
    out = tmp_path / "cal.yaml"
    with pytest.raises(SystemExit) as e:
        cli_main(["calibrate", str(ds), "--method", "lm", "--robot", str(robot_file),
                  "--out", str(out), "--json"])
    assert e.value.code == 0, capsys.readouterr().err
    back = Calibration.load(out).robot
    assert back.name == "test arm"
    np.testing.assert_allclose(back.poses(JOINTS), arm.poses(JOINTS), atol=1e-9)
    with pytest.raises(SystemExit) as e:
        cli_main(["calibrate", str(ds), "--robot", str(tmp_path / "none.yaml")])
    assert e.value.code == 2
    assert "none.yaml: no such robot description file" in capsys.readouterr().err


def test_the_general_models_views_take_the_manifests_robot_as_the_others_do(tmp_path):
    # views_from_images' arm is the manifest's as for the scans and the paper model's pass
    # (a DH mapping, a built-in name); an unknown name asks for its description
    from hmlvs.image.views import _session_robot

    arm = _other_arm()
    records = [{"id": "p0", "on": "a.png", "joints": JOINTS[0]}]
    got = _session_robot({"robot": arm.to_dict()}, records, None, "m.json")
    np.testing.assert_allclose(got.poses(JOINTS), arm.poses(JOINTS), atol=1e-9)
    assert _session_robot({}, records, None, "m.json").name == "SCORBOT ER-VII"
    assert _session_robot({"robot": arm.to_dict()}, records, arm, "m.json") is arm
    with pytest.raises(ValueError, match="the robot 'UR10e' is not a built-in arm"):
        _session_robot({"robot": "UR10e"}, records, None, "m.json")
    # entries that give their pose need no arm: the name is not read
    posed = [{"id": "p0", "on": "a.png", "pose": np.eye(4).tolist()}]
    assert _session_robot({"robot": "UR10e"}, posed, None, "m.json").name == "SCORBOT ER-VII"
