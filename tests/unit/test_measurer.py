"""Live measurement (hmlvs.Measurer): a frame and its robot pose -> the stripe's points in
the base and the camera, per scan line with a status; the same from several threads."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import hmlvs
from hmlvs.sim.general import example_sensor, general_session, render_general_session
import numpy as np
import pytest

pytestmark = pytest.mark.scene  # rendered images

SIZE = (640, 480)


@pytest.fixture(scope="module")
def rendered():
    s = general_session(example_sensor(SIZE), hmlvs.Checkerboard(rows=5, cols=7, square=15.0),
                        views=4, seed=5, distance=(330.0, 480.0))
    return s, render_general_session(s)


def _board_distance(s, pts: np.ndarray) -> np.ndarray:
    bfb = s.sensor.base_from_board
    return (pts - bfb[:3, 3]) @ bfb[:3, 2]


def test_frames_are_measured_on_the_board_plane(rendered):
    s, r = rendered
    m = hmlvs.Measurer(s.sensor)
    for i in range(len(s)):
        for off in (r.off[i], None):  # a laser on/off pair, and the laser-on frame alone
            prof = m.points(r.on[i], s.base_from_hand[i], off)
            assert len(prof) == SIZE[0]
            ok = prof.measured
            # the stripe crosses most of the image (the board and the table around it)
            assert ok.sum() > 0.5 * np.isfinite(s.stripe_v[i]).sum(), (i, ok.sum())
            # every measured point lies on the board's plane up to the stripe centres' error
            # (against the true line 0.04-0.06 px RMS with a laser-off frame, 0.04-0.23 px
            # without; at 330-520 mm the triangulation turns it into 0.06-0.12 mm and
            # 0.06-0.32 mm RMS: measured), and where its camera point maps to
            d = _board_distance(s, prof.points[ok])
            limit = 0.2 if off is not None else 0.5
            assert np.sqrt(np.mean(d**2)) < limit, (i, off is None)
            cam_h = np.c_[prof.camera_points[ok], np.ones(ok.sum())]
            base = (s.base_from_hand[i] @ s.sensor.hand_from_camera @ cam_h.T).T[:, :3]
            np.testing.assert_allclose(base, prof.points[ok], atol=1e-9)
            # the rest carry no point, and say why
            assert np.isnan(prof.points[~ok]).all()
            status = hmlvs.measurement.measurer.PointStatus
            assert set(np.unique(prof.status[~ok])) <= {status.NO_STRIPE, status.NO_POINT}


def test_a_blank_frame_has_no_stripe(rendered):
    s, _ = rendered
    prof = hmlvs.Measurer(s.sensor).points(np.full(SIZE[::-1], 40, np.uint8),
                                            s.base_from_hand[0])
    assert (prof.status == hmlvs.measurement.measurer.PointStatus.NO_STRIPE).all()
    assert np.isnan(prof.points).all()


def test_several_threads_give_the_same_profiles(rendered):
    s, r = rendered
    m = hmlvs.Measurer(s.sensor)
    jobs = [(r.on[i], s.base_from_hand[i]) for i in range(len(s))] * 3
    serial = [m.points(f, p) for f, p in jobs]
    with ThreadPoolExecutor(max_workers=3) as pool:
        threaded = list(pool.map(lambda j: m.points(*j), jobs))
    for a, b in zip(serial, threaded):
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.status, b.status)


def test_bad_frames_and_calibrations_are_refused(rendered, tmp_path):
    s, r = rendered
    m = hmlvs.Measurer(s.sensor)
    with pytest.raises(ValueError, match="the frame is 320 x 240 pixels but the calibration's "
                       "images are 640 x 480"):
        m.points(np.zeros((240, 320), np.uint8), s.base_from_hand[0])
    with pytest.raises(ValueError, match="base_from_hand row 0 is not finite"):
        m.points(r.on[0], np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="the frame must be an image"):
        m.points("frame.png", s.base_from_hand[0])
    with pytest.raises(ValueError, match="bogus"):
        hmlvs.Measurer(s.sensor, bogus=1)
    # a channel is checked against each frame (grey frames have none)
    with pytest.raises(ValueError, match="channel=2 was given but the laser-on image is "
                       "grayscale"):
        hmlvs.Measurer(s.sensor, channel=2).points(r.on[0], s.base_from_hand[0])

    class Other:  # a SensorModel neither of the two models
        model = "other"
        points_in_camera = points_in_base = s.sensor.points_in_camera
        hand_from_camera_matrix = s.sensor.hand_from_camera_matrix

    with pytest.raises(ValueError, match="with the paper or the opencv model, not a Other"):
        hmlvs.Measurer(Other())


def test_measure_streams_a_scan_into_the_cloud_file(rendered, tmp_path):
    """`hmlvs measure` writes the cloud frame by frame (measure_images_to): the same points,
    in the same file format, as measuring the whole scan in memory; a failed run writes
    nothing."""
    from hmlvs.cli import main
    from hmlvs.measurement.measure import measure_images, measure_images_to, read_ply
    from hmlvs.sim.general import render_general_session

    s, _ = rendered
    folder = tmp_path / "scan"
    render_general_session(s, folder)
    cal_path = tmp_path / "true.yaml"
    hmlvs.Calibration(sensor=s.sensor, model="opencv", method="truth").save(cal_path)
    whole = measure_images(cal_path, folder)
    done = []
    streamed = measure_images_to(cal_path, folder, tmp_path / "a.ply",
                                 progress=lambda k, n: done.append((k, n)))
    assert done == [(k + 1, len(s)) for k in range(len(s))]
    assert streamed.points == whole.cloud.num_valid and streamed.ids == whole.ids
    got = read_ply(tmp_path / "a.ply")
    np.testing.assert_array_equal(np.c_[got["x"], got["y"], got["z"]],
                                  whole.cloud.valid_points())
    np.testing.assert_array_equal(got["pose_index"], whole.cloud.pose_index[whole.cloud.valid])
    whole.cloud.save(tmp_path / "whole.csv")
    with pytest.raises(SystemExit) as e:
        main(["measure", str(cal_path), str(folder), "--out", str(tmp_path / "b.csv")])
    assert e.value.code == 0
    assert (tmp_path / "b.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    # a scan of frames none of which has a stripe: refused, and no file written
    dark = tmp_path / "dark"
    render_general_session(s, dark)
    for png in dark.glob("*_on.png"):
        png.write_bytes((dark / png.name.replace("_on", "_off")).read_bytes())
    with pytest.raises(SystemExit) as e:
        main(["measure", str(cal_path), str(dark), "--out", str(tmp_path / "c.ply")])
    assert e.value.code == 2
    assert not (tmp_path / "c.ply").exists()
