"""The library and the command line share their defaults: the same data calibrated by
`hmlvs calibrate DATA` and by `hmlvs.calibrate(DATA)`, each with its defaults, gives the same
parameters, for both sensor models."""

from __future__ import annotations

import html
import json

from conftest import run_cli
import hmlvs
from hmlvs.calibration.options import LmOptions, PsoOptions
from hmlvs.cli import app
from hmlvs.models.opencv import CLASSIC_DISTORTION
from hmlvs.models.params import DEFAULT_FIXED
import numpy as np
import pytest


def _option_default(command: str, name: str):
    """The default typer shows for a command's option."""
    import typer.main

    cmd = typer.main.get_command(app).commands[command]
    return next(p.default for p in cmd.params if p.name == name)


def test_the_command_line_defaults_are_the_librarys():
    assert _option_default("calibrate", "iterations") == PsoOptions().iterations
    assert _option_default("calibrate", "loss_scale") == LmOptions().loss_scale
    assert _option_default("calibrate", "distortion") == ",".join(CLASSIC_DISTORTION)
    import inspect

    from hmlvs.calibration.solvers import calibrate as calibrate_paper

    # hmlvs.calibrate(model="paper") passes its options on to it
    assert inspect.signature(calibrate_paper).parameters["fixed"].default == DEFAULT_FIXED


@pytest.mark.slow
def test_paper_model_same_parameters_from_the_cli_and_the_library(cli_files, tmp_path, capsys):
    _, ds, _, _ = cli_files
    code, _, err = run_cli(["calibrate", str(ds), "--out", str(tmp_path / "cal.yaml"), "-q"],
                           capsys)
    assert code == 0, err
    from_cli = hmlvs.Calibration.load(tmp_path / "cal.yaml")
    from_lib = hmlvs.calibrate(hmlvs.Dataset.load(ds))
    assert sorted(from_cli.fixed) == sorted(DEFAULT_FIXED) == sorted(from_lib.fixed)
    # the file keeps every float exactly (repr), so the two agree to the last bit
    np.testing.assert_array_equal(from_cli.params.to_array(), from_lib.params.to_array())
    # the library's calibration is the file's content: the same parameters, the same verdict
    assert isinstance(from_lib, hmlvs.Calibration)
    _same_file_content(from_cli, from_lib)


@pytest.mark.slow
def test_the_paper_commands_library_call_gives_its_file(cli_files, tmp_path, capsys):
    # hmlvs calibrate --model paper is hmlvs.pipeline.calibrate_paper_data: the same options
    # (a hold-out drawn with a seed, LM) give the same file content, to the last bit
    _, ds, _, _ = cli_files
    out = tmp_path / "cal.yaml"
    code, _, err = run_cli(["calibrate", str(ds), "--holdout", "0.25", "--seed", "3",
                            "--method", "lm", "--out", str(out), "-q"], capsys)
    assert code in (0, 3), err
    run = hmlvs.pipeline.calibrate_paper_data(ds, holdout=0.25, seed=3, method="lm")
    assert run.test is not None and len(run.test) + len(run.dataset) == len(
        hmlvs.Dataset.load(ds)) and run.extracted is None and run.reports == []
    _same_file_content(hmlvs.Calibration.load(out), run.calibration)
    assert hmlvs.pipeline.session_model(ds) == "paper"
    with pytest.raises(ValueError, match="the opencv model is calibrated from images"):
        hmlvs.pipeline.session_model(ds, "opencv")


@pytest.mark.filterwarnings("ignore")
def test_opencv_model_same_parameters_from_the_cli_and_the_library(cli_files, tmp_path, capsys):
    _, _, _, session = cli_files
    code, _, err = run_cli(["calibrate", str(session), "--out", str(tmp_path / "cal.yaml"),
                            "-q"], capsys)
    assert code in (0, 3), err  # 3 views: the verdict may call it untrustworthy
    from_cli = hmlvs.Calibration.load(tmp_path / "cal.yaml").sensor
    lib = hmlvs.calibrate(session, model="opencv")
    from_lib = lib.sensor
    assert isinstance(lib, hmlvs.Calibration)
    _same_file_content(hmlvs.Calibration.load(tmp_path / "cal.yaml"), lib)
    # the command's library call: the same calibration, judged as the file says
    run = hmlvs.pipeline.calibrate_session(session)
    assert run.verdict.to_dict() == hmlvs.Calibration.load(tmp_path / "cal.yaml").verdict
    for name in ("camera_matrix", "dist_coeffs", "laser_plane", "hand_from_camera",
                 "base_from_board"):
        np.testing.assert_array_equal(getattr(from_cli, name), getattr(from_lib, name),
                                      err_msg=name)
        np.testing.assert_array_equal(getattr(from_cli, name),
                                      getattr(run.calibration.sensor, name), err_msg=name)


def _same_file_content(from_cli: hmlvs.Calibration, from_lib: hmlvs.Calibration) -> None:
    """The file the command line wrote and the library's calibration hold the same content
    (parameters or sensor, standard deviations, verdict, ...), but the time each was made."""
    cli, lib = from_cli.to_dict(), from_lib.to_dict()
    assert cli.keys() == lib.keys()
    for key in cli.keys() - {"created"}:
        assert cli[key] == lib[key], key
    assert from_lib.solve is not None and from_cli.solve is None  # the solve is not saved


@pytest.mark.filterwarnings("ignore")
def test_report_of_an_opencv_calibration_on_its_session(cli_files, tmp_path, capsys):
    _, ds, _, session = cli_files
    cal = tmp_path / "cal.yaml"
    code, _, err = run_cli(["calibrate", str(session), "--out", str(cal), "-q"], capsys)
    assert code in (0, 3), err
    out = tmp_path / "report.html"
    code, text, err = run_cli(["report", str(cal), str(session), "--out", str(out), "--json"],
                              capsys)
    assert code == 0, err
    summary = json.loads(text)
    page = out.read_text()
    # the verdict the calibration was given comes first, then the camera the file holds
    assert page.index("Verdict: this calibration") < page.index("Camera (OpenCV conventions)")
    held = hmlvs.Calibration.load(cal).sensor
    assert f"{held.fx:.8g}" in page
    # the calibration's own views: residuals at the calibration's level (renders: a few
    # hundredths of a pixel and of a millimetre)
    assert summary["views"] == 3 and 0 < summary["corner_rms_px"] < 1.0
    assert 0 < summary["laser_rms_mm"] < 0.1
    # the solve shown is the board pose's alone, and the page says so (not the calibration's
    # "hand-eye and board pose estimated", nor its unknowns)
    assert summary["evaluated"] is True and summary["unknowns"] == 6
    shown = html.unescape(page)
    assert "hand-eye held, the board's pose in the base estimated" in shown
    assert "solve of the board's pose" in shown and "hand-eye and board pose estimated" not in shown
    # a data set of calibration points is not what an opencv calibration is reported on
    code, _, err = run_cli(["report", str(cal), str(ds), "--out", str(tmp_path / "r2.html")],
                           capsys)
    assert code == 2 and "image session" in err and not (tmp_path / "r2.html").exists()


@pytest.mark.filterwarnings("ignore")
def _counted_manifest_reads(monkeypatch) -> list:
    """Every read of a manifest.json from here on (Path.read_text counted)."""
    from pathlib import Path

    read_text, reads = Path.read_text, []

    def counted(self, *args, **kwargs):
        if self.name == "manifest.json":
            reads.append(self)
        return read_text(self, *args, **kwargs)

    monkeypatch.setattr(Path, "read_text", counted)
    return reads


@pytest.mark.parametrize("command", ["measure", "inspect", "report"])
def test_every_session_command_reads_the_manifest_once(command, cli_files, tmp_path, capsys,
                                                       monkeypatch):
    # as calibrate: the command line loads the manifest once (cli.common.session_of) and
    # passes the Manifest on; measure read it 3 times before, inspect 3, report 2
    _, _, _, session = cli_files
    cal = tmp_path / "cal.yaml"
    code, _, err = run_cli(["calibrate", str(session), "--out", str(cal), "-q"], capsys)
    assert code in (0, 3), err
    reads = _counted_manifest_reads(monkeypatch)
    argv = {"measure": ["measure", str(cal), str(session), "--out", str(tmp_path / "c.ply")],
            "inspect": ["inspect", str(session), "--out", str(tmp_path / "pictures")],
            "report": ["report", str(cal), str(session), "--out", str(tmp_path / "r.html")]}
    code, out, err = run_cli(argv[command], capsys)
    assert code == 0, err
    assert len(reads) == 1, reads
    written = {"measure": "c.ply", "inspect": "pictures", "report": "r.html"}[command]
    assert (tmp_path / written).exists(), out


def test_one_calibrate_reads_the_manifest_once(cli_files, tmp_path, capsys, monkeypatch):
    # the session is read and checked once (hmlvs.data.manifest.load_manifest); every later
    # step takes the Manifest for its path and reads copies of it
    from pathlib import Path

    from hmlvs.data.manifest import Manifest, load_manifest, read_manifest

    _, _, _, session = cli_files
    reads = _counted_manifest_reads(monkeypatch)
    code, _, err = run_cli(["calibrate", str(session), "--out", str(tmp_path / "cal.yaml"),
                            "-q"], capsys)
    assert code in (0, 3), err
    assert len(reads) == 1, reads
    m = load_manifest(session)
    assert load_manifest(m) is m and str(m) == str(session) and Path(m) == Path(session)
    entries, doc, folder = read_manifest(m)
    entries[0]["id"], doc["board"] = "changed", None
    again, doc_again, _ = read_manifest(m)
    assert again[0]["id"] != "changed" and doc_again["board"] is not None
    assert isinstance(m, Manifest) and len(reads) == 2  # load_manifest read it; the rest not
