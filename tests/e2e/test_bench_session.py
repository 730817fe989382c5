"""Bench sessions: the sensor on a bench, the board held in front of it in several poses and no
robot poses, calibrate the camera and the laser plane (camera mode); a robot session then
holds them (`--initial`) and calibrates the hand-eye transform and the board's pose."""

from __future__ import annotations

import json

from conftest import run_cli
from hmlvs.data.calibration_file import load_calibration
from hmlvs.image.scan import stripes_from_images
from hmlvs.measurement.measure import measure, measure_images, read_ply
from hmlvs.measurement.measurer import Measurer
from hmlvs.sim.general import general_session, render_general_session, render_general_view
import numpy as np
import pytest

# rendered images; on one BLAS kernel: the bench workflow's checks are which views and
# parameters are held or found, at tolerances far above the kernels' last bits (suite time)
pytestmark = [pytest.mark.scene, pytest.mark.one_kernel]


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """A rendered session of the general sensor twice: with its robot poses, and as a bench
    session (the same images, the manifest without poses)."""
    robot = tmp_path_factory.mktemp("robot")
    s = general_session(views=10, seed=5)
    render_general_session(s, robot)
    bench = tmp_path_factory.mktemp("bench")
    doc = json.loads((robot / "manifest.json").read_text())
    for e in doc["poses"]:
        del e["pose"]
        e["on"], e["off"] = (str(robot / e[k]) for k in ("on", "off"))
    (bench / "manifest.json").write_text(json.dumps(doc))
    return s, robot, bench


@pytest.fixture(scope="module")
def bench_calibration(sessions, tmp_path_factory):
    """`hmlvs calibrate BENCH --out b.yaml`, once for the module: (its file, exit code,
    stdout, stderr)."""
    import contextlib
    import io

    from hmlvs.cli import main

    out = tmp_path_factory.mktemp("bench_cal") / "b.yaml"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr), \
            pytest.raises(SystemExit) as e:
        main(["calibrate", str(sessions[2]), "--out", str(out)])
    return out, e.value.code, stdout.getvalue(), stderr.getvalue()


def test_a_bench_session_calibrates_camera_and_laser_plane(sessions, bench_calibration):
    s = sessions[0]
    path, code, out, err = bench_calibration
    assert code in (0, None), err
    assert "camera mode" in out
    cal = load_calibration(path)
    t = s.sensor
    assert abs(cal.sensor.fx / t.camera_matrix[0, 0] - 1) < 2e-3
    normal = cal.sensor.laser_plane[:3]
    assert abs(normal @ t.laser_plane[:3]) > np.cos(np.radians(0.1))
    assert abs(cal.sensor.laser_plane[3] - t.laser_plane[3]) < 0.2


def test_a_robot_session_holds_the_bench_camera_and_finds_the_hand_eye(
        sessions, bench_calibration, tmp_path, capsys):
    s, robot, _ = sessions
    code, out, err = run_cli(["calibrate", str(robot), "--initial", str(bench_calibration[0]),
                           "--out", str(tmp_path / "r.yaml")], capsys)
    assert code in (0, None), err
    b, r = (load_calibration(p).sensor for p in (bench_calibration[0], tmp_path / "r.yaml"))
    # held: the bench calibration's camera and plane, unchanged
    np.testing.assert_array_equal(r.intrinsics_vector(), b.intrinsics_vector())
    np.testing.assert_allclose(r.laser_plane, b.laser_plane, rtol=0, atol=1e-12)
    # calibrated: the hand-eye transform
    d = np.linalg.inv(s.sensor.hand_from_camera) @ r.hand_from_camera
    assert np.linalg.norm(d[:3, 3]) < 0.5
    assert np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1))) < 0.1


def test_bench_and_robot_poses_cannot_be_mixed(sessions, tmp_path, capsys):
    _, robot, _ = sessions
    doc = json.loads((robot / "manifest.json").read_text())
    del doc["poses"][3]["pose"]
    for e in doc["poses"]:
        e["on"], e["off"] = (str(robot / e[k]) for k in ("on", "off"))
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    code, _, err = run_cli(["calibrate", str(tmp_path), "--out", str(tmp_path / "x.yaml")],
                        capsys)
    assert code == 2 and "entry 3 (id v003) has neither 'joints' nor 'pose'" in err
    assert not (tmp_path / "x.yaml").exists()


def test_a_bench_session_is_refused_where_poses_are_needed(sessions, tmp_path, capsys):
    _, _, bench = sessions
    with pytest.raises(ValueError, match="no robot poses .* measuring in the robot's base"):
        stripes_from_images(bench)
    code, _, err = run_cli(["calibrate", str(bench), "--model", "paper", "--out",
                         str(tmp_path / "p.yaml")], capsys)
    assert code == 2 and "bench session" in err and "--model opencv" in err


def test_opencv_options_that_do_nothing_are_refused(sessions, tmp_path, capsys):
    _, robot, _ = sessions
    code, _, err = run_cli(["calibrate", str(robot), "--method", "lm", "--fixed", "f", "--out",
                         str(tmp_path / "x.yaml")], capsys)
    assert code == 2 and "--method, --fixed apply to the paper model only" in err
    assert not (tmp_path / "x.yaml").exists()


def test_a_bench_calibration_does_not_measure_in_the_base_frame(sessions, bench_calibration,
                                                                tmp_path, capsys):
    _, robot, _ = sessions
    code, _, err = run_cli(["measure", str(bench_calibration[0]), str(robot), "--out",
                         str(tmp_path / "c.ply")], capsys)
    assert code == 2 and "bench session's (camera mode)" in err and "--frame camera" in err
    assert not (tmp_path / "c.ply").exists()
    with pytest.raises(ValueError, match="bench session's .* without a pose measures in the "
                       "camera frame"):
        Measurer(bench_calibration[0]).points(render_general_view(sessions[0], 0)[0],
                                              sessions[0].base_from_hand[0])


def _board_in_camera(s, i):
    """The render's true board plane of view i in the camera frame: (normal, offset)."""
    camera_from_board = np.linalg.inv(s.base_from_hand[i] @ s.sensor.hand_from_camera) \
        @ s.sensor.base_from_board
    n = camera_from_board[:3, 2]
    return n, float(n @ camera_from_board[:3, 3])


def test_a_bench_calibration_measures_in_the_camera_frame(sessions, bench_calibration, tmp_path,
                                                          capsys):
    """hmlvs measure --frame camera of the bench session itself (no poses): each view's profile
    where the camera saw it, on the render's true board plane of that view; the same from
    the library (measure_images, Measurer without a pose)."""
    s, _, bench = sessions
    cloud = tmp_path / "c.ply"
    code, out, err = run_cli(["measure", str(bench_calibration[0]), str(bench), "--frame",
                              "camera", "--out", str(cloud)], capsys)
    assert code in (0, None), err
    assert "measured in the camera frame" in out
    assert b"comment hmlvs point cloud, camera frame, units mm" in cloud.read_bytes()[:200]
    ply = read_ply(cloud)
    xyz = np.column_stack([ply["x"], ply["y"], ply["z"]])
    assert len(xyz) > 300 * len(s)
    for i in range(len(s)):
        n, d = _board_in_camera(s, i)
        off = xyz[ply["pose_index"] == i] @ n - d
        # the stripe's noise and the bench calibration's error, about 0.1 mm at 300 mm; a
        # point mapped through any robot pose would lie metres away
        assert np.sqrt(np.mean(off**2)) < 0.3, i
    lib = measure_images(bench_calibration[0], bench, frame="camera")
    assert lib.cloud.frame == "camera"
    np.testing.assert_allclose(lib.cloud.valid_points(), xyz, rtol=0, atol=1e-9)
    on, off = render_general_view(s, 2)
    profile = Measurer(bench_calibration[0]).points(on, off=off)  # as the session was read
    assert np.isnan(profile.points).all() and profile.measured.sum() > 300
    n, d = _board_in_camera(s, 2)
    assert np.sqrt(np.mean((profile.camera_points[profile.measured] @ n - d) ** 2)) < 0.3


def test_frame_is_checked_before_anything_is_written(sessions, bench_calibration, tmp_path,
                                                     capsys):
    _, robot, bench = sessions
    code, _, err = run_cli(["measure", str(bench_calibration[0]), str(bench), "--frame",
                            "world", "--out", str(tmp_path / "c.ply")], capsys)
    assert code == 2 and "--frame must be base or camera, got 'world'" in err
    assert not (tmp_path / "c.ply").exists()
    with pytest.raises(ValueError, match="frame='camera' measures without robot poses"):
        measure(bench_calibration[0], [np.array([[320.0, 240.0]])], np.eye(4)[None],
                frame="camera")


def test_robot_poses_uncertain_from_the_command_line(sessions, tmp_path, capsys):
    """--robot-poses uncertain reaches the joint solve: each view keeps its own board pose and
    the poses' spread is estimated (near zero on a render with exact poses) and printed."""
    s, robot, _ = sessions
    code, out, err = run_cli(["calibrate", str(robot), "--robot-poses", "uncertain", "--out",
                           str(tmp_path / "u.yaml")], capsys)
    assert code in (0, None), err
    line = next(ln for ln in out.splitlines() if ln.startswith("robot poses: uncertain"))
    spread_mm = float(line.split("estimated at ")[1].split(" mm")[0])
    assert spread_mm < 0.1  # the render's poses are exact
    cal = load_calibration(tmp_path / "u.yaml")
    assert abs(cal.sensor.fx / s.sensor.camera_matrix[0, 0] - 1) < 2e-3


@pytest.mark.parametrize("args, message", [
    (["--robot-poses", "sometimes"], "--robot-poses must be exact or uncertain"),
    (["--robot-poses", "uncertain", "--model", "paper"], "--robot-poses applies to the opencv"),
])
def test_robot_poses_option_is_checked_before_anything_is_read(sessions, tmp_path, capsys,
                                                                args, message):
    _, robot, _ = sessions
    code, _, err = run_cli(["calibrate", str(robot), *args, "--out", str(tmp_path / "x.yaml")],
                           capsys)
    assert code == 2 and message in err
    assert not (tmp_path / "x.yaml").exists()


def test_a_bench_session_has_no_robot_poses_to_doubt(sessions, tmp_path, capsys):
    _, _, bench = sessions
    code, _, err = run_cli(["calibrate", str(bench), "--robot-poses", "uncertain", "--out",
                         str(tmp_path / "x.yaml")], capsys)
    assert code == 2 and "views without a robot pose" in err
    assert not (tmp_path / "x.yaml").exists()


@pytest.mark.parametrize("terms, message", [
    ("k1,k9", "unknown distortion term 'k9'"),
    ("k1,k2,s1", "s1, s2, s3 and s4 go together"),
])
def test_distortion_terms_are_checked_before_the_images_are_read(sessions, tmp_path, capsys,
                                                                 terms, message):
    _, robot, _ = sessions
    code, out, err = run_cli(["calibrate", str(robot), "--distortion", terms, "--out",
                              str(tmp_path / "x.yaml")], capsys)
    assert code not in (0, None) and message in err
    assert "corners" not in out  # no view's line: refused before any image was read
    assert not (tmp_path / "x.yaml").exists()
