"""The verdict on a calibration (issue 38): a correct rendered session is trustworthy and
exits 0; each usual mistake (wrong square, inverted poses, the other quaternion order,
metres read as millimetres, a moved board, images that do not belong to their poses) ends
in exit 3 / an untrustworthy verdict with the cause named; ``hmlvs measure`` refuses an
untrustworthy calibration; the predicted 3D uncertainty matches the measured error."""

from __future__ import annotations

import dataclasses
import json
import math

from hmlvs.calibration.joint import calibrate_joint
from hmlvs.cli import main
from hmlvs.data.calibration_file import Calibration
from hmlvs.data.poses import rotation_to_quaternion
from hmlvs.data.views import ViewData
from hmlvs.diagnostics.map_sigma import map_sigma_mm
from hmlvs.diagnostics.verdict import Verdict, judge_joint, reorder_quaternions, require_check
from hmlvs.geometry.transforms import invert_transform
from hmlvs.image.views import views_from_images
from hmlvs.sim.general import general_session, render_general_session
import numpy as np
import pytest

pytestmark = pytest.mark.slow  # the module's shared sessions take long to make

# Only the tests whose figures are fine numerical agreements run again in the Prescott pass
# (marker scene); the mistakes are tens to hundreds of pixels off, whatever the BLAS kernels.


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("verdict")
    session = general_session(views=10, seed=1)
    render_general_session(session, out)
    views, board, size, _, _ = views_from_images(out)
    return session, out, views, board, size


def _run(args, capsys):
    with pytest.raises(SystemExit) as e:
        main(args)
    return e.value.code, capsys.readouterr()


def _manifest(folder, name, edit):
    doc = json.loads((folder / "manifest.json").read_text())
    edit(doc)
    path = folder / name
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.scene
def test_correct_render_is_trustworthy_exit_0_verdict_in_file_json_and_report(
        rendered, tmp_path, capsys):
    _, folder, *_ = rendered
    out, rep = tmp_path / "cal.yaml", tmp_path / "r.html"
    code, io = _run(["calibrate", str(folder), "--out", str(out), "--report", str(rep),
                     "--json", "--require", "1.0"], capsys)
    assert code == 0
    v = json.loads(io.out)["verdict"]
    assert v["trustworthy"] is True and v["reasons"] == []
    names = {c["name"]: c for c in v["checks"]}
    for n in ("corner_rms", "chain_vs_free_corner_rms", "laser_rms", "board_spread_mm",
              "board_spread_deg", "views_rejected", "corner_coverage", "stripe_coverage",
              "pose_variety", "unknowns_determined", "cross_validation", "map_sigma_p95",
              "cross_validation_p95"):
        assert names[n]["ok"] is True and set(names[n]) >= {"name", "value", "limit", "ok"}, n
    # measured on this session: 0.015 px through the chain, board spread 0.006 mm
    assert names["corner_rms"]["value"] < 0.1 and names["board_spread_mm"]["value"] < 0.1
    assert 0 < v["map_sigma_mm"]["rms"] <= v["map_sigma_mm"]["p95"] < 1.0
    assert names["cross_validation"]["ok"] and names["cross_validation_p95"]["ok"]
    assert 0 < v["cross_validation_mm"]["rms"] <= v["cross_validation_mm"]["p95"] < 1.0
    cal = Calibration.load(out)
    assert cal.trustworthy is True
    html = rep.read_text()
    assert html.index("Verdict: this calibration can be trusted") < html.index(
        "Predicted 3D uncertainty over the image") < html.index("Camera (OpenCV")


def test_wrong_square_exits_3_names_the_square_and_measure_refuses(rendered, tmp_path,
                                                                   capsys):
    _, folder, *_ = rendered
    def edit(doc):  # 8 views are enough, and faster
        doc["board"]["square"] = 15.0
        doc["poses"] = doc["poses"][:8]

    m = _manifest(folder, "square15.json", edit)
    out = tmp_path / "cal.yaml"
    code, io = _run(["calibrate", str(m), "--out", str(out), "--quiet"], capsys)
    assert code == 3
    # the verdict comes first, in words
    assert io.out.startswith("VERDICT: this calibration is NOT to be trusted:\n  - likely "
                             "mistake: the robot motion implies squares of 20.0 mm, not 15: "
                             "check `board.square`")
    assert "(marked not trustworthy)" in io.out
    cal = Calibration.load(out)  # still written, marked
    assert cal.trustworthy is False and "squares of 20.0 mm" in cal.verdict["reasons"][0]
    one = _manifest(folder, "one.json", lambda d: d.update(poses=d["poses"][:1]))
    code, io = _run(["measure", str(out), str(one), "--out", str(tmp_path / "c.ply")], capsys)
    assert code == 2 and "is marked not trustworthy" in io.err and "--accept-untrusted" in io.err
    assert not (tmp_path / "c.ply").exists()
    code, _ = _run(["measure", str(out), str(one), "--out", str(tmp_path / "c.ply"),
                    "--accept-untrusted", "--json"], capsys)
    assert code == 0 and (tmp_path / "c.ply").exists()


def test_quaternion_order_declared_wrong_exits_3_with_the_order_named(rendered, tmp_path,
                                                                      capsys):
    _, folder, *_ = rendered

    def edit(doc):
        doc["pose_format"] = {"quaternion_order": "wxyz"}  # but written x y z w
        doc["poses"] = doc["poses"][:8]
        for p in doc["poses"]:
            m = np.asarray(p["pose"], float)
            p["pose"] = {"position": m[:3, 3].tolist(),
                         "quaternion": rotation_to_quaternion(m[:3, :3], "xyzw").tolist()}

    m = _manifest(folder, "quat.json", edit)
    code, io = _run(["calibrate", str(m), "--out", str(tmp_path / "cal.yaml"), "--json"],
                    capsys)
    assert code == 3
    v = json.loads(io.out)["verdict"]
    assert "quaternions are written xyzw, not wxyz" in v["reasons"][0]


def _with_poses(views, f):
    return [dataclasses.replace(v, base_from_hand=f(i, np.asarray(v.base_from_hand, float)))
            for i, v in enumerate(views)]


def _moved(i, m):
    c, s = math.cos(math.radians(5)), math.sin(math.radians(5))
    t = np.eye(4)
    t[:2, :2] = [[c, -s], [s, c]]
    t[:3, 3] = [30.0, -20.0, 0.0]
    return t @ m if i in (1, 5, 8) else m


_SWAP = {2: 7, 7: 2, 4: 9, 9: 4}

MISTAKES = {
    # name: (board square, pose edit, phrase of the first reason)
    "square 25": (25.0, None, "the robot motion implies squares of 20.0 mm, not 25"),
    "inverted": (None, lambda i, m: invert_transform(m),
                 "they are hand_from_base, not base_from_hand"),
    "quaternion": (None, lambda i, m: reorder_quaternions(m, (1, 2, 3, 0)),
                   "quaternions are written xyzw, not wxyz"),
    "metres": (None, lambda i, m: np.vstack([np.c_[m[:3, :3], m[:3, 3] / 1000], [0, 0, 0, 1]]),
               "the robot positions are metres read as millimetres: set the poses' unit to m"),
    "board moved": (None, _moved, "view(s) v001, v005, v008 put the board elsewhere"),
    "images of other poses": (None, lambda i, m: m, "view(s) v002, v004, v007, v009 put the "
                              "board elsewhere"),
}


@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_each_usual_mistake_is_untrustworthy_with_its_cause_named(rendered, mistake):
    _, _, views, board, size = rendered
    square, edit, phrase = MISTAKES[mistake]
    if mistake == "images of other poses":
        poses = [v.base_from_hand for v in views]
        edit = lambda i, m: poses[_SWAP.get(i, i)]  # noqa: E731
    vs = views if edit is None else _with_poses(views, edit)
    b = board if square is None else dataclasses.replace(board, square=square)
    v = judge_joint(calibrate_joint(vs, b, size), vs, b, map_sigma=False, cross_validate=False)
    assert not v.trustworthy
    assert phrase in v.reasons[0], v.reasons
    assert v.likely_mistake == v.reasons[0]


def test_a_held_camera_s_mistakes_are_looked_for_with_its_lens(rendered):
    """A robot session calibrated with the camera and plane of an earlier calibration held (as
    from a bench session): the search for the usual mistakes uses the held camera's lens (the
    five terms), not a pinhole, and still names the moved views."""
    _, _, views, board, size = rendered
    held = calibrate_joint(views, board, size).sensor
    vs = _with_poses(views, _moved)
    v = judge_joint(calibrate_joint(vs, board, size, camera=held), vs, board, map_sigma=False,
                    cross_validate=False)
    assert not v.trustworthy
    assert "view(s) v001, v005, v008 put the board elsewhere" in v.reasons[0], v.reasons


def test_the_verdict_round_trips_and_old_files_load_without_one(rendered, tmp_path):
    _, _, views, board, size = rendered
    r = calibrate_joint(views, board, size)
    v = require_check(judge_joint(r, views, board), 0.01)  # a demand it cannot meet
    failed = [c for c in v.checks if not c.ok]
    assert not v.trustworthy and v.reasons == [c.problem for c in failed]
    # measured here: p95 0.24 mm predicted, the halves' maps 0.075 mm apart (p95)
    assert {c.name for c in failed} == {"map_sigma_p95", "cross_validation_p95"}
    cal = Calibration.from_joint(r)
    assert cal.trustworthy is None  # an old file: no verdict
    old = Calibration.load(cal.save(tmp_path / "old.yaml"))
    assert old.verdict is None and old.trustworthy is None
    cal.verdict = v.to_dict()
    back = Calibration.load(cal.save(tmp_path / "new.json"))
    assert back.trustworthy is False and back.verdict["reasons"] == v.reasons
    again = Verdict.from_dict(back.verdict)
    assert [(c.name, c.ok, c.kind) for c in again.checks] == [
        (c.name, c.ok, c.kind) for c in v.checks]
    assert again.text().splitlines()[:3] == v.text().splitlines()[:3]


def _noisy_views(session, seed, corner_px=0.05, stripe_px=0.1):
    """Views with the session's true corners and stripe pixels plus Gaussian noise."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(len(session)):
        c = session.corners[i] + rng.normal(0, corner_px, session.corners[i].shape)
        s = session.stripe_pixels(i)
        s[:, 1] += rng.normal(0, stripe_px, len(s))
        out.append(ViewData(f"v{i:03d}", c, np.arange(len(c)), s, session.base_from_hand[i]))
    return out


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_predicted_map_uncertainty_within_3x_of_the_held_out_error(seed):
    """Predicted from the calibration alone (covariance + the stripe noise it measures);
    measured on held-out views against the truth: the noisy stripe pixel mapped with the
    calibration against the true stripe pixel mapped with the true sensor. Both checked
    independently; measured here (seeds 3, 4, 5): predicted 0.253, 0.256, 0.257 mm RMS,
    held-out 0.255, 0.276, 0.239 mm."""
    s = general_session(views=14, seed=seed)
    views = _noisy_views(s, seed)
    r = calibrate_joint(views[:10], s.board, s.sensor.image_size)
    pred = map_sigma_mm(r)
    rng = np.random.default_rng(100 + seed)
    errs = []
    for i in range(10, len(s)):
        true_px = s.stripe_pixels(i)
        px = true_px + np.c_[np.zeros(len(true_px)), rng.normal(0, 0.1, len(true_px))]
        pose = np.repeat(s.base_from_hand[i][None], len(px), axis=0)
        got, ok1 = r.sensor.points_in_base(px, pose, on_invalid="mask")
        true, ok2 = s.sensor.points_in_base(true_px, pose, on_invalid="mask")
        errs.append(np.linalg.norm(got - true, axis=1)[ok1 & ok2])
    e = np.concatenate(errs)
    measured = float(np.sqrt(np.mean(e**2)))
    assert pred is not None
    assert 1 / 3 < pred["rms"] / measured < 3, (pred, measured)


def test_paper_model_gets_a_verdict_too(tmp_path, capsys):
    """The paper model: fewer checks (the solve's end, the fit against the sensor class's
    accuracy, held-out against fit); a correct simulated session is trustworthy, reference
    points 1.33 times too far from the base (a wrong board square) are not."""
    import hmlvs

    ds = hmlvs.simulate.session(num_poses=12, seed=4).dataset
    good = ds.save(tmp_path / "good.npz")
    bad = dataclasses.replace(ds, points=ds.points * 1.33).save(tmp_path / "bad.npz")
    code, io = _run(["calibrate", str(good), "--method", "lm", "--out",
                     str(tmp_path / "g.yaml"), "--report", str(tmp_path / "g.html"), "--json"],
                    capsys)
    assert code == 0 and json.loads(io.out)["verdict"]["trustworthy"] is True
    html = (tmp_path / "g.html").read_text()
    assert html.index("Verdict: this calibration can be trusted") < html.index("Parameters")
    assert Calibration.load(tmp_path / "g.yaml").trustworthy is True
    code, io = _run(["calibrate", str(bad), "--method", "lm", "--out",
                     str(tmp_path / "b.yaml"), "--json"], capsys)
    assert code == 3
    v = json.loads(io.out)["verdict"]
    assert not v["trustworthy"] and "from their reference positions" in v["reasons"][0]
    assert Calibration.load(tmp_path / "b.yaml").trustworthy is False


def test_another_sessions_images_with_these_poses_are_refused_as_disagreeing(rendered):
    """Every image from another session: no view's numbering fits its pose, so the input
    is refused (exit 2 on the command line) with the disagreement named."""
    _, _, views, board, size = rendered
    other = general_session(views=len(views), seed=2).base_from_hand
    vs = [dataclasses.replace(v, base_from_hand=other[i]) for i, v in enumerate(views)]
    with pytest.raises(ValueError, match="the images disagree with their robot poses"):
        calibrate_joint(vs, board, size)


@pytest.mark.scene
def test_predicted_map_uncertainty_on_the_render_within_3x_of_held_out_error(rendered):
    """As above, on the rendered images: calibrated on 7 views, measured on the 3 others'
    detected stripe pixels against the true stripe point of the same column (measured
    here: predicted 0.151 mm RMS, held-out 0.123 mm; 12-view renders of seeds 1 and 2:
    0.144 / 0.130 against 0.131 / 0.118 mm)."""
    session, _, views, board, size = rendered
    r = calibrate_joint(views[:7], board, size)
    pred = map_sigma_mm(r)
    errs = []
    for v in views[7:]:
        i = int(v.id[1:])
        px = np.asarray(v.laser_pixels, float)
        u = px[:, 0].astype(int)
        vt = session.stripe_v[i][u]
        ok = np.isfinite(vt) & session.stripe_on_board[i][u]
        pose = np.repeat(session.base_from_hand[i][None], ok.sum(), axis=0)
        got, ok1 = r.sensor.points_in_base(px[ok], pose, on_invalid="mask")
        true, ok2 = session.sensor.points_in_base(np.c_[u[ok], vt[ok]].astype(float), pose,
                                                  on_invalid="mask")
        errs.append(np.linalg.norm(got - true, axis=1)[ok1 & ok2])
    measured = float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))
    assert pred is not None
    assert 1 / 3 < pred["rms"] / measured < 3, (pred, measured)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stripe_noise_is_measured_from_the_stripes_themselves(seed):
    """A smooth distorted line plus 0.1 px noise over 3 views: the estimate within 10 %
    (the map uncertainty and the laser check rest on it)."""
    from hmlvs.diagnostics.verdict import stripe_noise_px

    rng = np.random.default_rng(seed)
    sets = []
    for _ in range(3):
        u = np.arange(100.0, 900.0)
        x = (u - 500) / 400
        v = 300 + rng.uniform(-80, 80) * x + rng.uniform(-30, 30) * x**2 + 8 * x**3
        sets.append(np.c_[u, v + rng.normal(0, 0.1, len(u))])
    assert stripe_noise_px(sets) == pytest.approx(0.1, rel=0.1)
