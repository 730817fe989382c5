"""Export to OpenCV, ROS camera_info and JSON; the calibration file's model/sensor keys."""

import json
import math

import cv2
import hmlvs
from hmlvs.cli import main as cli_main
from hmlvs.data.calibration_file import Calibration
from hmlvs.data.export import division_to_brown, export, export_text, sensor_of
from hmlvs.data.poses import rotation_from_quaternion
from hmlvs.models.opencv import OpenCvSensor
from hmlvs.models.paper import hand_from_camera, points_in_camera, rays_in_camera
from hmlvs.models.params import TABLE2_LOWER, TABLE2_UPPER
import numpy as np
import pytest
import yaml

K_PAPER = 0.005  # 1/mm^2: ~4 % (about 13 px) at the image corners of the nominal sensor


def _paper():
    return hmlvs.Parameters.nominal().replace(k=K_PAPER, omega=0.02, phi=0.03, varphi=-0.01)


def _opencv_sensor():
    bfb = np.eye(4)
    bfb[:3, 3] = [700.0, 90.0, 0.0]
    hfc = np.eye(4)
    hfc[:3, :3] = rotation_from_quaternion([0.1, -0.2, 0.05, 0.97], "xyzw")
    hfc[:3, 3] = [55.0, -3.0, -40.0]
    return OpenCvSensor(camera_matrix=[[1100.0, 0, 330.5], [0, 1095.0, 238.25], [0, 0, 1]],
                        dist_coeffs=[-0.21, 0.12, 0.001, -0.0005, -0.03], image_size=(640, 480),
                        laser_plane=[0.0, 0.9, 0.43, -125.0], hand_from_camera=hfc,
                        base_from_board=bfb)


def _grid(w=640, h=480, n=33):
    uu, vv = np.meshgrid(np.linspace(0, w - 1, n), np.linspace(0, h - 1, n))
    return np.column_stack([uu.ravel(), vv.ravel()])


@pytest.fixture
def cal_files(tmp_path):
    paper = Calibration(_paper(), method="pso+lm").save(tmp_path / "paper.yaml")
    cv = Calibration(sensor=_opencv_sensor(), model="opencv").save(tmp_path / "opencv.json")
    return {"paper": paper, "opencv": cv}


def test_k_is_a_reasonable_distortion():
    p = _paper()
    assert TABLE2_LOWER[5] <= p.k <= TABLE2_UPPER[5]
    corner = np.array([[0.0, 0.0]])
    shift = np.linalg.norm(rays_in_camera(p, corner)[0, :2] / p.Su - (corner[0] - [p.Cu, p.Cv]))
    assert 5.0 < shift < 30.0  # visible, as a real lens's, not extreme


def test_opencv_undistortion_matches_the_division_model():
    p = _paper()
    s = sensor_of(p)
    assert s.image_size == (640, 480)
    np.testing.assert_allclose(s.camera_matrix, [[p.f / p.Su, 0, p.Cu], [0, p.f / p.Sv, p.Cv],
                                                 [0, 0, 1]])
    assert s.dist_coeffs[2] == s.dist_coeffs[3] == 0.0
    px = _grid()
    rays = rays_in_camera(p, px)  # the C++ model's undistortion: (Xu, Yu, f)
    ideal = np.column_stack([s.fx * rays[:, 0] / rays[:, 2] + s.cx,
                             s.fy * rays[:, 1] / rays[:, 2] + s.cy])
    und = cv2.undistortPoints(px.reshape(-1, 1, 2), s.camera_matrix, s.dist_coeffs,
                              P=s.camera_matrix).reshape(-1, 2)
    assert np.abs(px - ideal).max() > 10.0  # the distortion is there to be modelled
    assert np.abs(und - ideal).max() < 0.05
    # and the other way: a laser point of the paper model projects to its pixel in OpenCV
    pts, valid = points_in_camera(p, px[px[:, 1] > 60], on_invalid="mask")
    proj, _ = cv2.projectPoints(pts[valid], np.zeros(3), np.zeros(3), s.camera_matrix,
                                s.dist_coeffs)
    assert np.abs(proj.reshape(-1, 2) - px[px[:, 1] > 60][valid]).max() < 0.05
    assert division_to_brown(p, (640, 480))[1] < 0.05


def test_laser_plane_and_hand_eye_of_a_paper_calibration():
    p = _paper()
    s = sensor_of(p, image_size=(800, 600))
    assert s.image_size == (800, 600)
    pts, valid = points_in_camera(p, _grid(), on_invalid="mask")
    dist = pts[valid] @ s.laser_plane[:3] + s.laser_plane[3]
    assert np.abs(dist).max() < 1e-9 and valid.sum() > 500
    n = math.hypot(1.0, math.tan(p.theta))
    np.testing.assert_allclose(s.laser_plane, [0, 1 / n, math.tan(p.theta) / n, -p.H / n])
    np.testing.assert_allclose(s.hand_from_camera, hand_from_camera(p))


def test_a_large_k_warns_that_the_fit_is_poor():
    with pytest.warns(UserWarning, match=r"matched by OpenCV's k1, k2, k3 only within"):
        sensor_of(hmlvs.Parameters.nominal().replace(k=0.1))


@pytest.mark.parametrize("which", ["paper", "opencv"])
def test_opencv_format_reads_back_with_filestorage(tmp_path, cal_files, which):
    s = sensor_of(Calibration.load(cal_files[which]))
    path = export(cal_files[which], "opencv", tmp_path / "cam.yaml")
    assert path.read_text().startswith("%YAML:1.0\n")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.isOpened()
    assert int(fs.getNode("image_width").real()) == 640
    assert int(fs.getNode("image_height").real()) == 480
    np.testing.assert_array_equal(fs.getNode("camera_matrix").mat(), s.camera_matrix)
    np.testing.assert_array_equal(fs.getNode("distortion_coefficients").mat(),
                                  s.dist_coeffs.reshape(1, 5))
    np.testing.assert_array_equal(fs.getNode("laser_plane").mat(), s.laser_plane.reshape(1, 4))
    np.testing.assert_array_equal(fs.getNode("hand_from_camera").mat(), s.hand_from_camera)
    board = fs.getNode("base_from_board")
    if which == "opencv":
        np.testing.assert_array_equal(board.mat(), s.base_from_board)
    else:
        assert board.empty()
    fs.release()


@pytest.mark.parametrize("which", ["paper", "opencv"])
def test_ros_camera_info(tmp_path, cal_files, which):
    s = sensor_of(Calibration.load(cal_files[which]))
    d = yaml.safe_load(export_text(cal_files[which], "ros", camera_name="laser_cam"))
    assert d["image_width"] == 640 and d["image_height"] == 480
    assert d["camera_name"] == "laser_cam" and d["distortion_model"] == "plumb_bob"
    assert (d["camera_matrix"]["rows"], d["camera_matrix"]["cols"]) == (3, 3)
    np.testing.assert_array_equal(np.reshape(d["camera_matrix"]["data"], (3, 3)),
                                  s.camera_matrix)
    assert (d["distortion_coefficients"]["rows"], d["distortion_coefficients"]["cols"]) == (1, 5)
    np.testing.assert_array_equal(d["distortion_coefficients"]["data"], s.dist_coeffs)
    np.testing.assert_array_equal(np.reshape(d["rectification_matrix"]["data"], (3, 3)),
                                  np.eye(3))
    assert (d["projection_matrix"]["rows"], d["projection_matrix"]["cols"]) == (3, 4)
    proj = np.reshape(d["projection_matrix"]["data"], (3, 4))
    np.testing.assert_array_equal(proj[:, :3], s.camera_matrix)
    np.testing.assert_array_equal(proj[:, 3], 0.0)


@pytest.mark.parametrize("which", ["paper", "opencv"])
def test_json_export(tmp_path, cal_files, which):
    s = sensor_of(Calibration.load(cal_files[which]))
    d = json.loads(export_text(cal_files[which], "json"))
    np.testing.assert_array_equal(d["camera_matrix"], s.camera_matrix)
    np.testing.assert_array_equal(d["dist_coeffs"], s.dist_coeffs)
    assert d["image_size"] == [640, 480]
    np.testing.assert_array_equal(d["laser_plane"], s.laser_plane)
    np.testing.assert_array_equal(d["hand_from_camera"], s.hand_from_camera)
    pose = d["hand_from_camera_pose"]
    np.testing.assert_allclose(pose["xyz_mm"], s.hand_from_camera[:3, 3])
    np.testing.assert_allclose(rotation_from_quaternion(pose["quaternion_xyzw"], "xyzw"),
                               s.hand_from_camera[:3, :3], atol=1e-12)
    if which == "opencv":
        np.testing.assert_array_equal(d["base_from_board"], s.base_from_board)
        assert not np.allclose(s.hand_from_camera[:3, :3], np.eye(3), atol=0.1)
    else:
        assert d["base_from_board"] is None


def test_cli_export_stdout_file_and_errors(tmp_path, cal_files, capsys):
    with pytest.raises(SystemExit) as e:
        cli_main(["export", str(cal_files["paper"]), "--format", "json"])
    assert e.value.code == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads(export_text(cal_files["paper"], "json"))
    out = tmp_path / "ci.yaml"
    with pytest.raises(SystemExit) as e:
        cli_main(["export", str(cal_files["opencv"]), "--format", "ros", "--out", str(out)])
    assert e.value.code == 0 and str(out) in capsys.readouterr().out
    assert yaml.safe_load(out.read_text())["camera_matrix"]["data"][0] == 1100.0
    with pytest.raises(SystemExit) as e:
        cli_main(["export", str(cal_files["paper"]), "--format", "matlab"])
    assert e.value.code == 2
    assert "unknown export format 'matlab'; choose opencv, ros, json" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        cli_main(["export", str(tmp_path / "nope.yaml"), "--format", "ros"])
    assert e.value.code == 2 and "nope.yaml: no such calibration file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        cli_main(["export", str(cal_files["paper"]), "--format", "opencv", "--image-size",
                  "660", "500", "--out", str(out)])
    assert e.value.code == 0
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    assert fs.getNode("image_width").real() == 660.0


# ------------------------------------------------------------------------------------------
# the calibration file's model and sensor keys


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_opencv_calibration_file_round_trip(tmp_path, suffix):
    s = _opencv_sensor()
    path = Calibration(sensor=s, model="opencv", fit_rms=0.08,
                       robot=hmlvs.Robot.scorbot_er7()).save(tmp_path / f"c{suffix}")
    text = path.read_text()
    d = json.loads(text) if suffix == ".json" else yaml.safe_load(text)
    assert d["model"] == "opencv" and "parameters" not in d
    np.testing.assert_array_equal(d["hand_from_camera"], s.hand_from_camera)
    back = Calibration.load(path)
    assert back.model == "opencv" and back.params is None and back.fit_rms == 0.08
    for name in ("camera_matrix", "dist_coeffs", "laser_plane", "hand_from_camera",
                 "base_from_board"):
        np.testing.assert_array_equal(getattr(back.sensor, name), getattr(s, name))
    assert back.sensor.image_size == (640, 480) and back.robot.name == "SCORBOT ER-VII"
    assert "fx" in back.table()


def test_paper_files_without_model_still_read(tmp_path):
    p = _paper()
    d = Calibration(p).to_dict()
    assert d["model"] == "paper"
    del d["model"]  # files written before the key existed
    (tmp_path / "old.json").write_text(json.dumps(d))
    back = Calibration.load(tmp_path / "old.json")
    assert back.model == "paper" and back.sensor is None
    np.testing.assert_array_equal(back.params.to_array(), p.to_array())


@pytest.mark.parametrize(
    "change, match",
    [(lambda d: d.update(model="fisheye"),
      "model: must be one of paper, opencv, got 'fisheye'"),
     (lambda d: d.pop("sensor"), "a calibration of model opencv needs a 'sensor' block"),
     (lambda d: d["sensor"].pop("laser_plane"), r"c.json: sensor: the opencv sensor lacks "
      "laser_plane"),
     (lambda d: d["sensor"].update(image_size=[640]), r"c.json: sensor: image_size must be"),
     (lambda d: d.update(model="paper"), "'parameters' must map the 14 parameter names")],
)
def test_bad_model_blocks(tmp_path, change, match):
    d = Calibration(sensor=_opencv_sensor(), model="opencv").to_dict()
    change(d)
    (tmp_path / "c.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match=match):
        Calibration.load(tmp_path / "c.json")


def test_measuring_with_an_opencv_calibration_file_uses_its_sensor(tmp_path):
    cal = Calibration(sensor=_opencv_sensor(), model="opencv")
    path = cal.save(tmp_path / "cal.yaml")
    px = np.array([[300.0, 400.0], [320.0, 420.0]])
    cloud = hmlvs.measure(path, [px], np.eye(4))
    expected, ok = cal.sensor.points_in_base(px, np.stack([np.eye(4)] * 2), on_invalid="mask")
    assert ok.all() and np.array_equal(cloud.valid, ok)
    assert np.allclose(cloud.points[ok], expected[ok])
