"""Faults the error policy must survive (issue 40), in the inputs: bad names, sizes and
schemas are refused with one sentence (exit 2), never a crash."""

from __future__ import annotations

import json
import os
from pathlib import Path
import subprocess
import sys

from conftest import run_cli as _run
from conftest import tree_digest as _tree
import hmlvs
from hmlvs import _io
import numpy as np
import pytest


@pytest.fixture(scope="module")
def files(cli_files):
    return cli_files


# -- 5. names and sizes ----------------------------------------------------------------------
def _copy_session(sess: Path, to: Path, change=None) -> Path:
    """A copy of the rendered session at ``to`` (a str or bytes path), its manifest changed by
    ``change(doc)``."""
    import shutil

    shutil.copytree(os.fsencode(sess), os.fsencode(to))
    to = Path(os.fsdecode(to))
    if change is not None:
        doc = json.loads((to / "manifest.json").read_text())
        change(doc)
        (to / "manifest.json").write_text(json.dumps(doc))
    return to


def _hmlvs(*argv: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    # in a process of its own: a crash (SIGSEGV) must show as such, not take the suite down
    return subprocess.run([sys.executable, "-m", "hmlvs", *argv], capture_output=True,
                          text=True, cwd=cwd, timeout=300, errors="surrogateescape")


def test_names_that_are_not_utf8_never_crash(files, tmp_path):
    # in a process of its own: cv2.imread on such a name was a SIGSEGV (exit -11). The
    # session's folder name is not UTF-8; v000's laser-on image has the byte 0xff in its
    # name (read by its bytes); v001's names an unpaired surrogate, which no file system
    # holds (its entry is rejected, naming the file)
    _, _, _, sess = files

    def rename(doc):
        doc["poses"][0]["on"] = "v000_on-\udcff.png"
        doc["poses"][1]["on"] = "v001_on-\ud800.png"

    weird = _copy_session(sess, os.fsencode(tmp_path) + b"/sess-\xff\xfe", rename)
    os.rename(weird / "v000_on.png", os.fsencode(weird) + b"/v000_on-\xff.png")
    r = _hmlvs("inspect", str(weird), "--out", str(tmp_path / "pics"))
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("v000: ") and lines[0].endswith("-> v000.png")
    assert lines[1].startswith("v001: rejected (the laser-on image file ")
    assert "v001_on-\\ud800.png': its name holds a character no file name can (an unpaired " \
           "surrogate); rename it)" in lines[1]
    assert lines[2].startswith("v002: ") and lines[2].endswith("-> v002.png")
    assert sorted(p.name for p in (tmp_path / "pics").iterdir()) == ["v000.png", "v002.png"]


def test_deep_nesting_is_a_sentence_not_a_recursion_error(files, tmp_path, capsys):
    _, _, cal, _ = files
    from hmlvs.data.manifest import read_manifest

    deep = tmp_path / "manifest.json"
    deep.write_text('{"format": "hmlvs-images", "version": 1, "poses": '
                    + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(ValueError, match=r"manifest.json: malformed manifest: its lists and "
                                         r"mappings nest more than 32 levels deep"):
        read_manifest(deep)
    deep_cal = tmp_path / "cal.yaml"
    deep_cal.write_text(cal.read_text() + "extra: " + "[" * 3000 + "]" * 3000 + "\n")
    code, _, err = _run(["export", str(deep_cal), "--format", "json"], capsys)
    assert code == 2
    assert err.strip() == (f"error: {deep_cal}: malformed calibration file: its lists and "
                           "mappings nest more than 32 levels deep")
    # a data set's .npz carries its header as JSON text: bounded the same way
    _, ds, _, _ = files
    with np.load(ds, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["header"] = np.array('{"meta": ' + "[" * 100_000 + "]" * 100_000 + "}")
    deep_ds = tmp_path / "deep.npz"
    np.savez(deep_ds, **arrays)
    code, _, err = _run(["calibrate", str(deep_ds), "--method", "lm", "--out",
                         str(tmp_path / "x.yaml")], capsys)
    assert code == 2
    assert "malformed data set header: its lists and mappings nest more than 32 levels" in err
    assert not (tmp_path / "x.yaml").exists()
    shallow = tmp_path / "shallow.json"  # 32 levels are fine for the reader
    shallow.write_text("[" * 32 + "]" * 32)
    assert _io.read_document(shallow, "x") == json.loads("[" * 32 + "]" * 32)


def test_a_huge_board_is_a_sentence_not_a_memory_error(files, tmp_path, capsys):
    _, _, _, sess = files
    copy = _copy_session(sess, tmp_path / "sess",
                         lambda doc: doc["board"].update(rows=1_000_000))
    before = _tree(copy)
    code, _, err = _run(["calibrate", str(copy), "--out", str(tmp_path / "c.yaml"), "-q"],
                        capsys)
    assert code == 2
    assert err.startswith(f"error: {copy}: board: ")
    assert "at most 1000 inner corners per side, got 1000000 x 9" in err
    assert _tree(copy) == before and not (tmp_path / "c.yaml").exists()
    from hmlvs.geometry.board import BoardSpec, Checkerboard

    for make in (lambda: Checkerboard(rows=6, cols=1001), lambda: BoardSpec(1001, 6, 20.0)):
        with pytest.raises(ValueError, match="at most 1000 inner corners per side"):
            make()
    Checkerboard(rows=1000, cols=1000)  # the bound itself is allowed


# -- 6. schemas ------------------------------------------------------------------------------
def _opencv_doc(**sensor_changes) -> dict:
    from hmlvs.data.calibration_file import Calibration
    from hmlvs.models.opencv import OpenCvSensor

    sensor = OpenCvSensor(camera_matrix=[[1000, 0, 320], [0, 1000, 240], [0, 0, 1]],
                          dist_coeffs=[0, 0, 0, 0, 0], image_size=(640, 480),
                          laser_plane=[0, 0.5, 0.866, -200], hand_from_camera=np.eye(4))
    doc = Calibration(sensor=sensor, model="opencv").to_dict()
    doc["sensor"].update(sensor_changes)
    return doc


@pytest.mark.parametrize("size", [[True, True], ["640", "480"], [640.9, 480.5], [640],
                                  [0, 480], [-640, 480], None])
def test_a_calibrations_image_size_is_two_positive_whole_numbers(size):
    from hmlvs.data.calibration_file import Calibration

    with pytest.raises(ValueError, match=r"^cal.yaml: sensor: image_size must be two positive "
                                         r"whole numbers of pixels \(width, height\), got "):
        Calibration.from_dict(_opencv_doc(image_size=size), source="cal.yaml")


def test_a_whole_float_image_size_is_still_fine():
    from hmlvs.data.calibration_file import Calibration

    cal = Calibration.from_dict(_opencv_doc(image_size=[640.0, 480]), source="cal.yaml")
    assert cal.sensor.image_size == (640, 480)
    assert all(type(v) is int for v in cal.sensor.image_size)


def test_a_laser_plane_through_the_camera_is_refused():
    from hmlvs.data.calibration_file import Calibration

    with pytest.raises(ValueError, match=r"^cal.yaml: sensor: laser_plane .* has d = 0"):
        Calibration.from_dict(_opencv_doc(laser_plane=[0, 0.5, 0.866, 0]), source="cal.yaml")
    with pytest.raises(ValueError, match="non-zero normal"):
        Calibration.from_dict(_opencv_doc(laser_plane=[0, 0, 0, -200]), source="cal.yaml")


@pytest.mark.parametrize("name", ["Su", "Sv", "f"])
def test_zero_intrinsics_are_refused_at_load(files, tmp_path, capsys, name):
    import yaml

    _, _, cal, _ = files
    doc = yaml.safe_load(cal.read_text())
    doc["parameters"][name] = 0
    bad = tmp_path / "zero.yaml"
    bad.write_text(yaml.safe_dump(doc))
    code, out, err = _run(["export", str(bad), "--format", "opencv"], capsys)
    assert code == 2 and out == ""
    assert err.strip() == (f"error: {bad}: parameters: {name} is 0; the focal length f and the "
                           "pixel pitches Su, Sv scale every pixel to mm and must not be 0")


@pytest.mark.parametrize("key", ["base_from_link0", "flange_from_hand"])
@pytest.mark.parametrize("matrix", [
    np.diag([1.01, 1.01, 1.01, 1.0]),                                    # a scale
    np.diag([1.0, 1.0, -1.0, 1.0]),                                      # a mirror
    np.array([[1, 0.1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]),  # a shear
    np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]),    # a last row
], ids=["scale", "mirror", "shear", "last-row"])
def test_a_robots_base_and_tool_transforms_must_be_rigid(key, matrix):
    from hmlvs.data.robot_file import robot_from_dict

    d = hmlvs.Robot.scorbot_er7().to_dict()
    d[key] = matrix.tolist()
    with pytest.raises(ValueError, match=rf"^arm.yaml: malformed robot description \({key} is "
                                         r"not a rigid transform .* to within 0\.001\)$"):
        robot_from_dict(d, "arm.yaml")
    # a rotation of 45 deg about z written by hand with four decimals: fine
    d[key] = [[0.7071, -0.7071, 0, 10], [0.7071, 0.7071, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    robot_from_dict(d, "arm.yaml")


def test_manifest_poses_in_metres_are_refused_like_a_pose_files(files, tmp_path):
    from hmlvs.data.manifest import read_manifest

    _, _, _, sess = files

    def metres(doc):
        for e in doc["poses"]:
            pose = np.array(e["pose"])
            pose[:3, 3] *= 1e-3
            e["pose"] = pose.tolist()

    copy = _copy_session(sess, tmp_path / "sess", metres)
    with pytest.raises(ValueError, match=r"manifest.json: the hand positions are 0\.\d+ mm from "
                                         r"the robot base \(median\): they look like metres; "
                                         r"name it as the manifest's pose_format: \{unit: m\}$"):
        read_manifest(copy)
    doc = json.loads((copy / "manifest.json").read_text())
    doc["pose_format"] = {"unit": "m"}
    (copy / "manifest.json").write_text(json.dumps(doc))
    entries, _, _ = read_manifest(copy)
    assert np.linalg.norm(entries[0]["pose"][:3, 3]) > 100  # read as metres, given in mm


def test_a_stripe_list_of_one_column_is_refused(tmp_path):
    from hmlvs.data.manifest import read_stripe_list

    one = tmp_path / "s.csv"
    one.write_text("320\n300\n")
    with pytest.raises(ValueError, match=r"s.csv must hold rows of u, v\[, intensity\]; its "
                                         r"rows have 1 column$"):
        read_stripe_list(one)
    one.write_text("320,300\n")  # one pixel is still one pixel
    assert read_stripe_list(one)[0].tolist() == [[320.0, 300.0]]


def test_images_of_another_size_than_the_calibrations_are_refused(files, tmp_path, capsys):
    from hmlvs.data.calibration_file import Calibration

    _, _, _, sess = files
    cal = tmp_path / "cal640.yaml"
    Calibration.from_dict(_opencv_doc(), source="x").save(cal)
    code, _, err = _run(["measure", str(cal), str(sess), "--out", str(tmp_path / "c.ply")],
                        capsys)
    assert code == 2 and not (tmp_path / "c.ply").exists()
    assert err.strip() == (f"error: {sess}: the manifest's image_size is 1024 x 768 pixels but "
                           f"the calibration {cal} is for 640 x 480 pixel images: measure with "
                           "a calibration of this camera at this resolution")
    copy = _copy_session(sess, tmp_path / "sess", lambda doc: doc.pop("image_size"))
    code, _, err = _run(["measure", str(cal), str(copy), "--out", str(tmp_path / "c.ply")],
                        capsys)
    assert code == 2 and not (tmp_path / "c.ply").exists()
    assert err.strip() == (f"error: {copy}: entry v000: the images v000_on.png and "
                           f"v000_off.png are 1024 x 768 pixels but the calibration {cal} is "
                           "for 640 x 480 pixel images: measure with a calibration of this "
                           "camera at this resolution")


def test_the_manifests_image_size_holds_on_the_opencv_path(files, tmp_path, capsys):
    _, _, _, sess = files
    copy = _copy_session(sess, tmp_path / "sess", lambda doc: doc.update(image_size=[640, 480]))
    code, _, err = _run(["calibrate", str(copy), "--model", "opencv", "--out",
                         str(tmp_path / "c.yaml"), "-q"], capsys)
    assert code == 2 and not (tmp_path / "c.yaml").exists()
    assert err.strip() == f"error: {copy}: no image pair could be read: " + "; ".join(
        f"v00{i}: the images are 1024 x 768 pixels but the session's are 640 x 480"
        for i in range(3))


# -- 7. messages -----------------------------------------------------------------------------
def test_a_pose_file_with_a_byte_order_mark_and_named_columns(tmp_path):
    from hmlvs.data.poses import read_poses

    rows = [("v000", 0.1, -0.2, 0.3, 500.0, 20.0, 300.0),
            ("v001", 0.0, 0.1, -0.1, 480.0, -10.0, 320.0)]
    plain = tmp_path / "plain.csv"
    plain.write_text("id,x,y,z,rx,ry,rz\n" + "".join(
        f"{i},{x},{y},{z},{a},{b},{c}\n" for i, a, b, c, x, y, z in rows))
    named = tmp_path / "named.csv"  # the same poses, rotation first, with Excel's BOM
    named.write_bytes(("id,rx,ry,rz,x,y,z\n" + "".join(
        f"{i},{a},{b},{c},{x},{y},{z}\n" for i, a, b, c, x, y, z in rows)).encode("utf-8-sig"))
    ids, want = read_poses(plain, unit="mm")
    ids2, got = read_poses(named, unit="mm")
    assert ids == ids2 == ["v000", "v001"]
    np.testing.assert_allclose(got, want, atol=1e-12)
    assert np.allclose(got[0][:3, 3], [500.0, 20.0, 300.0])


def test_read_poses_of_none_is_a_value_error():
    from hmlvs.data.poses import read_poses

    with pytest.raises(ValueError, match=r"^no pose file given: expected a file name, got "
                                         r"None$"):
        read_poses(None, unit="mm")


def test_an_empty_poses_list_is_one_sentence(files, tmp_path, capsys):
    _, _, _, sess = files
    copy = _copy_session(sess, tmp_path / "sess", lambda doc: doc.update(poses=[]))
    code, _, err = _run(["calibrate", str(copy), "--out", str(tmp_path / "c.yaml")], capsys)
    assert code == 2
    assert err.strip() == (f"error: {copy}: the session lists no image pairs (its poses list "
                           "is empty)")
    assert not err.strip().endswith(":")


def test_an_uppercase_yaml_manifest_is_read_as_yaml(files, tmp_path):
    from hmlvs.data.manifest import read_manifest
    import yaml

    _, _, _, sess = files
    copy = _copy_session(sess, tmp_path / "sess")
    doc = json.loads((copy / "manifest.json").read_text())
    (copy / "manifest.json").unlink()
    (copy / "MANIFEST.YAML").write_text(yaml.safe_dump(doc))
    entries, _, _ = read_manifest(copy / "MANIFEST.YAML")
    assert [e["id"] for e in entries] == ["v000", "v001", "v002"]


# -- 8. inspect: one picture per view ----------------------------------------------------------
def test_ids_that_make_one_file_name_get_one_picture_each(files, tmp_path, capsys):
    _, _, _, sess = files

    def ids(doc):
        for e, pid in zip(doc["poses"], ["a/b", "a_b", "A_B"]):
            e["id"] = pid

    copy = _copy_session(sess, tmp_path / "sess", ids)
    code, out, err = _run(["inspect", str(copy), "--out", str(tmp_path / "pics"), "--json"],
                          capsys)
    assert code in (0, None), err
    images = [Path(v["image"]).name for v in json.loads(out)]
    assert images == ["a_b.png", "a_b-2.png", "A_B-3.png"]
    assert sorted(p.name for p in (tmp_path / "pics").iterdir()) == sorted(images)


def test_export_says_its_warning_without_a_source_line(files, tmp_path):
    _, _, cal, _ = files
    bent = tmp_path / "k.yaml"
    bent.write_text(cal.read_text().replace(" k: 0.0,", " k: 0.05,"))
    assert bent.read_text() != cal.read_text()
    r = _hmlvs("export", str(bent), "--format", "opencv", "--out", str(tmp_path / "o.yaml"))
    assert r.returncode == 0, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning UserWarning: the division model")
    assert ".py:" not in r.stderr and "warnings.warn" not in r.stderr


def test_a_paper_calibration_from_images_holds_measuring_to_its_image_size(tmp_path, capsys):
    """A paper-model calibration from images stores the images' size; measuring images of
    another size with it is refused like with an opencv calibration (before, only opencv
    calibrations carried a size, so the check was skipped for the paper model)."""
    from hmlvs.data.calibration_file import Calibration
    from hmlvs.models.params import Parameters
    from hmlvs.sim.general import general_session, render_general_session

    cal = Calibration(params=Parameters.nominal(), image_size=(800, 600))
    path = tmp_path / "paper.yaml"
    cal.save(path)
    assert Calibration.load(path).image_size == (800, 600)
    sess = tmp_path / "sess"
    render_general_session(general_session(views=1, seed=2), sess)  # 1024 x 768 images
    code, _, err = _run(["measure", str(path), str(sess), "--out", str(tmp_path / "c.ply")],
                        capsys)
    assert code == 2
    assert "1024 x 768" in err and "800 x 600" in err
    assert not (tmp_path / "c.ply").exists()
    bad = tmp_path / "bad.yaml"
    bad.write_text(path.read_text().replace("image_size: [800, 600]", "image_size: [800.5, 600]"))
    with pytest.raises(ValueError, match="image_size must be .width, height. in pixels"):
        Calibration.load(bad)
