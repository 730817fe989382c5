"""Image sessions given in every form the CLI documents, and one bad pair that must not stop a
session (issue: hardening against bad input and faults)."""

from __future__ import annotations

import json
import shutil

from conftest import run_cli
import hmlvs
import numpy as np
import pytest
import yaml

#: a board origin 17 mm off the true one (700, 90, 0) in y and 88 mm in z: the corners
#: predicted for pair p003 make OpenCV's perspectiveTransform assert inside find_corners
WRONG_ORIGIN = [700.0353292197043, 73.21365954759082, 87.62796006479756]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """4 pairs (seed 0) with the board's measured pose: 9 calibration points. p001 shows
    only the board's corner (5 inner corners, no 3 x 3 grid for ``findChessboardCornersSB``):
    its corners are found as X-junctions where the robot pose predicts them."""
    out = tmp_path_factory.mktemp("session") / "s"
    hmlvs.simulate.render_session(num_poses=4, seed=0, out_dir=out)
    return out


def _copy(rendered, tmp_path, change=None):
    folder = tmp_path / "s"
    shutil.copytree(rendered, folder)
    doc = json.loads((folder / "manifest.json").read_text())
    if change is not None:
        change(doc)
        (folder / "manifest.json").write_text(json.dumps(doc))
    return folder, doc


def test_a_wrong_board_origin_rejects_the_pair_not_the_session(rendered, tmp_path):
    def wrong_origin(doc):
        doc["board"]["origin"] = WRONG_ORIGIN
        doc["poses"].insert(0, doc["poses"].pop(3))  # the failing pair first

    folder, _ = _copy(rendered, tmp_path, wrong_origin)
    # no pair gives a point with this origin; every pair after the failing one is still tried
    with pytest.raises(ValueError, match="no image pair gave a calibration point") as e:
        hmlvs.image.paper_session.dataset_from_images(folder)
    lines = str(e.value).splitlines()[1:]
    assert [x.split(":")[0] for x in lines] == ["p003", "p000", "p001", "p002"]
    # (before, OpenCV's perspectiveTransform failed on the degenerate homography here)
    assert lines[0].startswith(
        "p003: rejected: checkerboard: the matched corners fit no homography (they lie on a "
        "line or repeat): the expected pixels are far off; check the board's geometry and the "
        "pose they were predicted from; ")
    # numbered again with the hand-eye the views agree on: with this origin they agree on none
    assert "the views do not agree on one numbering" in lines[0]
    assert all("homography" not in x for x in lines[1:])


def test_an_opencv_error_in_one_pair_leaves_the_others_used(rendered, tmp_path, monkeypatch):
    import cv2
    from hmlvs.image import paper_session as session

    folder, _ = _copy(rendered, tmp_path)
    ds, reports = hmlvs.image.paper_session.dataset_from_images(folder)
    used = {r.id: r.points for r in reports if r.ok}
    assert used == {"p000": 1, "p001": 1, "p002": 1, "p003": 6}
    real = session.find_corners
    calls = []

    def failing_once(image, board, expected=None, **kw):
        calls.append(1)
        if len(calls) == 1:  # the first pair, p000
            raise cv2.error("OpenCV(5.0.0) fundam.cpp:326: error: (-2:Unspecified error)")
        return real(image, board, expected=expected, **kw)

    monkeypatch.setattr(session, "find_corners", failing_once)
    # one thread: the first call is p000's (on two, p001's thread may call first)
    ds2, reports2 = hmlvs.image.paper_session.dataset_from_images(folder, threads=1)
    assert not reports2[0].ok and reports2[0].reason.startswith("checkerboard: OpenCV failed")
    assert "board's origin" in reports2[0].reason
    assert {r.id: r.points for r in reports2 if r.ok} == {"p001": 1, "p002": 1, "p003": 6}
    assert len(ds2) == len(ds) - 1
    np.testing.assert_array_equal(ds2.points, ds.points[ds.pose_index != 0])


def test_an_opencv_error_in_one_view_rejects_that_view(rendered, tmp_path, monkeypatch):
    """The same per-pair rule in the general model's views (hmlvs.image.views)."""
    import cv2
    from hmlvs.image import views

    folder, _ = _copy(rendered, tmp_path, lambda doc: doc["board"].pop("origin"))
    real = views.detect_corners

    def failing_for_p000(image, board):
        if failing_for_p000.first:
            failing_for_p000.first = False
            raise cv2.error("OpenCV(5.0.0) fundam.cpp:326: error: (-2:Unspecified error)")
        return real(image, board)

    failing_for_p000.first = True
    monkeypatch.setattr(views, "detect_corners", failing_for_p000)
    # one thread: the first call is p000's (on two, p001's thread may call first)
    found, _, size, _, reports = views.views_from_images(folder, threads=1)
    assert [r.id for r in reports] == ["p000", "p001", "p002", "p003"]
    assert not reports[0].ok and reports[0].reason.startswith("board: OpenCV failed (")
    assert size == (640, 480) and [v.id for v in found] == [r.id for r in reports if r.ok]


def _manifest_forms(rendered, tmp_path):
    """The same session as a folder, its manifest.yaml, and a JSON manifest with another
    name whose format key comes after 4 kB of entries."""
    folder, doc = _copy(rendered, tmp_path)
    (folder / "manifest.json").rename(folder / "manifest.yaml")
    (folder / "manifest.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    late = {"poses": [dict(p, note="x" * 1500) for p in doc["poses"]],
            **{k: v for k, v in doc.items() if k not in ("poses", "format", "version")},
            "format": doc["format"], "version": doc["version"]}
    (folder / "session.json").write_text(json.dumps(late, indent=1))
    assert (folder / "session.json").read_text().index('"format"') > 4096
    return [folder, folder / "manifest.yaml", folder / "session.json"]


def test_calibrate_and_measure_take_a_manifest_file_of_any_name(rendered, tmp_path, capsys):
    forms = _manifest_forms(rendered, tmp_path)
    calibrate = [run_cli(["calibrate", str(f), "--method", "lm", "--out",
                       str(tmp_path / "c.yaml")], capsys) for f in forms]
    # 9 points from 4 pairs, too few for 10 free parameters: the same refusal from the
    # calibration stage for every form, after the same per-pair lines
    for code, out, err in calibrate:
        assert code == 2
        assert err.startswith("error: too few points: 9 calibration points"), err
        assert out.splitlines()[0].startswith("p000: 1 points"), out
    assert calibrate[1:] == [calibrate[0]] * 2
    assert not (tmp_path / "c.yaml").exists()

    cal = hmlvs.Calibration(params=hmlvs.Parameters.nominal()).save(tmp_path / "cal.yaml")
    measured = []
    for f in forms:
        code, out, err = run_cli(["measure", str(cal), str(f), "--out", str(tmp_path / "m.csv"),
                               "--json"], capsys)
        assert code == 0, err
        measured.append((json.loads(out)["points"], (tmp_path / "m.csv").read_text()))
    assert measured[0][0] > 1000
    assert measured[1:] == [measured[0]] * 2
