"""One calibration type for both sensor models (issue 37): ``hmlvs.calibrate`` returns a
``hmlvs.Calibration`` for either, with the solver's outcome as ``solve``, one ``to_dict()``
(the file's), one form of the solve's figures, one measurement path and one report; the
command line's ``--json`` is built from the same ``to_dict()``."""

from __future__ import annotations

import json
import math

from conftest import run_cli
import hmlvs
from hmlvs.calibration.joint_result import JointCalibration
from hmlvs.calibration.result import CalibrationResult, Termination
from hmlvs.geometry.transforms import rotation_to_vector
from hmlvs.report.calibration import write_calibration_report
import numpy as np
import pytest

#: the solve's figures both models give (docs/file-formats.md, ``solve``)
COMMON_FIGURES = {"termination", "iterations", "seconds", "unknowns", "rank", "determined",
                  "not_determined", "rotation_vector_rad"}


@pytest.fixture(scope="module")
def both(cli_files):
    """The paper model on the 8-pose data set, the opencv model on the 3-view session."""
    import warnings

    _, ds, _, session = cli_files
    paper = hmlvs.calibrate(hmlvs.Dataset.load(ds), method="lm")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 3 views: the solve warns about what they determine
        opencv = hmlvs.calibrate(session, model="opencv")
    return paper, opencv


def _plain(d: dict) -> dict:
    """As the command line's JSON has it: tuples as lists, a figure that is not a number
    (NaN, inf) as null."""
    def finite(x):
        if isinstance(x, dict):
            return {k: finite(v) for k, v in x.items()}
        if isinstance(x, list):
            return [finite(v) for v in x]
        return None if isinstance(x, float) and not math.isfinite(x) else x

    return finite(json.loads(json.dumps(d)))


def test_both_models_return_a_calibration_holding_their_solve(both):
    paper, opencv = both
    assert type(paper) is type(opencv) is hmlvs.Calibration
    assert (paper.model, opencv.model) == ("paper", "opencv")
    assert isinstance(paper.solve, CalibrationResult)
    assert isinstance(opencv.solve, JointCalibration)
    assert paper.params is paper.solve.params and opencv.sensor is opencv.solve.sensor
    assert paper.fit_rms == paper.solve.fit_rms
    assert opencv.fit_rms == opencv.solve.laser_rms_mm
    for cal in both:
        # judged as the command line judges: the verdict in the file, its details beside it
        assert cal.verdict == cal.judged.to_dict() and cal.trustworthy == cal.judged.trustworthy
        assert cal.warnings == cal.solve.warnings
        assert cal.solve.summary() in cal.summary()


def test_one_to_dict_for_both_models(both, tmp_path):
    paper, opencv = (cal.to_dict() for cal in both)
    # the same keys but the paper model's parameters (an opencv file leaves them out)
    assert set(paper) - set(opencv) == {"parameters"} and set(opencv) <= set(paper)
    assert paper["sensor"] is None and opencv["sensor"]["camera_matrix"]
    # what is saved reads back to the same content; the solve is not saved
    for cal, d in zip(both, (paper, opencv)):
        back = hmlvs.Calibration.load(cal.save(tmp_path / f"{cal.model}.yaml"))
        assert back.solve is None and back.solve_figures() is None
        assert _plain(back.to_dict()) == _plain(d)


def test_the_solve_figures_have_one_form(both):
    for cal in both:
        fig = cal.solve_figures()
        assert COMMON_FIGURES <= set(fig), cal.model
        assert fig["termination"] in {t.value for t in Termination}
        assert 0 <= fig["rank"] <= fig["unknowns"] and fig["iterations"] >= 0
        np.testing.assert_allclose(fig["rotation_vector_rad"], rotation_to_vector(
            np.asarray(cal.to_dict()["hand_from_camera"])[:3, :3]), atol=1e-12)
    paper, opencv = (cal.solve_figures() for cal in both)
    det, undet = both[0].solve.determined_split()
    assert (paper["determined"], paper["not_determined"]) == (det, undet)
    assert paper["unknowns"] == 14 - len(both[0].fixed)
    assert opencv["rank"] == both[1].solve.rank and opencv["views"] == 3


def test_the_measurer_and_measure_take_either_calibration(both, cli_files):
    from hmlvs.sim.general import general_session, render_general_view

    paper, opencv = both
    ds = hmlvs.Dataset.load(cli_files[1])
    stripes = [ds.pixels[i:i + 1] for i in range(len(ds))]
    cloud = hmlvs.measure(paper, stripes, ds.poses)
    expected, _ = hmlvs.models.paper.points_in_base(paper.params, ds.pixels, ds.poses)
    np.testing.assert_array_equal(cloud.points, expected)
    np.testing.assert_array_equal(hmlvs.measure(paper.solve, stripes, ds.poses).points,
                                  cloud.points)
    # the opencv session's first view (cli_files renders general_session(views=3, seed=2))
    session = general_session(views=3, seed=2)
    frame, _ = render_general_view(session, 0)
    pose = session.base_from_hand[0]
    assert opencv.blur_var is not None and paper.blur_var is None  # the session's blur
    for cal, model in ((opencv, opencv.sensor), (paper, paper.params)):
        # the calibration measures as its sensor does with the camera blur it carries
        got = hmlvs.Measurer(cal).points(frame, pose)
        want = hmlvs.Measurer(model, blur_var=cal.blur_var).points(frame, pose)
        np.testing.assert_array_equal(got.points, want.points)
    assert hmlvs.Measurer(opencv).points(frame, pose).measured.sum() > 100


def test_one_report_for_either_calibration(both, cli_files, tmp_path):
    paper, opencv = both
    _, ds, _, session = cli_files
    # a calibration just computed: its own solve, its verdict first
    w = write_calibration_report(paper, tmp_path / "p.html", ds)
    assert w.result is paper.solve and len(w.dataset) == paper.num_points
    page = w.path.read_text()
    assert page.index("Verdict: this calibration") < page.index("Parameters (layout")
    w = write_calibration_report(opencv, tmp_path / "o.html")
    assert w.result is opencv.solve
    page = w.path.read_text()
    assert page.index("Verdict: this calibration") < page.index("Camera (OpenCV conventions)")
    assert hmlvs.report.write_calibration_report is write_calibration_report
    # read back from files: evaluated on the data given
    for cal in both:
        cal.save(tmp_path / f"{cal.model}.yaml")
    w = write_calibration_report(tmp_path / "paper.yaml", tmp_path / "p2.html", ds)
    # the same parameters on the same points: the same residuals; the file's verdict first
    assert w.result is not paper.solve and w.result.fit_rms == paper.fit_rms
    page = w.path.read_text()
    assert page.index("Verdict: this calibration") < page.index("Parameters (layout")
    with pytest.raises(ValueError, match="give data="):
        write_calibration_report(tmp_path / "opencv.yaml", tmp_path / "o2.html")
    with pytest.raises(ValueError, match="give data="):
        write_calibration_report(paper, tmp_path / "p3.html")
    with pytest.raises(ValueError, match="an .html file"):
        write_calibration_report(opencv, tmp_path / "o.txt")
    with pytest.raises(ValueError, match="hmlvs.Calibration"):
        write_calibration_report(paper.solve, tmp_path / "p4.html", ds)
    refused = ("o2.html", "p3.html", "p4.html", "o.txt")
    assert not [n for n in refused if (tmp_path / n).exists()]


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("model", ["paper", "opencv"])
def test_the_command_lines_json_is_the_librarys_to_dict(both, cli_files, tmp_path, capsys,
                                                         model):
    _, ds, _, session = cli_files
    cal = both[0] if model == "paper" else both[1]
    args = [str(ds), "--method", "lm"] if model == "paper" else [str(session)]
    code, out, err = run_cli(["calibrate", *args, "--out", str(tmp_path / "c.yaml"),
                              "--json"], capsys)
    assert code in (0, 3), err  # 3: a small session the verdict may not trust
    summary = json.loads(out)
    lib = _plain(cal.to_dict())
    for key in set(lib) - {"created"}:  # the time it was written
        assert summary[key] == lib[key], key
    figures = _plain(cal.solve_figures())
    assert set(summary["solve"]) == set(figures)
    for key in set(figures) - {"seconds"}:  # the run time
        assert summary["solve"][key] == figures[key], key
    assert summary["calibration"] == str(tmp_path / "c.yaml")
