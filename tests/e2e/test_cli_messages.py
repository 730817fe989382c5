"""What a user sees on the command line: warnings once and formatted, the default gauge,
--version, help lines, per-view accounts, the HTML report and the demo's verdict."""

import json
import math
import os
import subprocess
import sys
import warnings

from conftest import run_cli
import hmlvs
from hmlvs import cli
from hmlvs.cli import common as cli_common
from hmlvs.models.params import Parameters
import numpy as np
import pytest
import typer


def _hmlvs(*args, cwd=None):
    """The CLI in a fresh interpreter, as a user runs it (Python warnings not filtered)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    return subprocess.run([sys.executable, "-m", "hmlvs", *args], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=120)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A 6-pose session: too few points for 10 free parameters, so a data warning fires."""
    d = tmp_path_factory.mktemp("small")
    s = hmlvs.simulate.session(cli.mounted_truth(cli.MOUNTING_DEG), num_poses=6, seed=3)
    return s, s.dataset.save(d / "small.npz")


def test_version(capsys):
    code, out, _ = run_cli(["--version"], capsys)
    assert code == 0 and out.strip() == f"hmlvs {hmlvs.__version__}"


COMMANDS = ["simulate", "demo", "calibrate", "design", "report", "measure", "inspect",
            "export", "study", "scenario"]


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_help_has_no_bool_placeholder(command, capsys):
    code, out, _ = run_cli(([command] if command else []) + ["--help"], capsys)
    assert code == 0 and "Show this message and exit." in out
    assert "<bool>" not in out


@pytest.mark.parametrize("command", COMMANDS)
def test_help_paragraphs_flow_to_the_terminal_width(command, capsys, monkeypatch):
    """Each paragraph of a command's description is one line on a wide terminal, not broken
    where the docstring's source lines break (ragged help on every width)."""
    import inspect

    monkeypatch.setenv("COLUMNS", "400")
    code, out, _ = run_cli([command, "--help"], capsys)
    assert code == 0
    lines = [" ".join(line.split()) for line in out.splitlines()]
    doc = inspect.getdoc(next(c.callback for c in cli.app.registered_commands
                              if (c.name or c.callback.__name__) == command))
    paragraphs = [" ".join(p.split()) for p in doc.split("\n\n")]
    assert len(paragraphs) >= 2  # a summary line and an example at least
    for p in paragraphs:
        assert p in lines, (p, out)
    # and every option's help text is shown whole (markup eats nothing, e.g. "<id>")
    command_obj = typer.main.get_command(cli.app).commands[command]
    flat = " ".join(out.split())
    for param in command_obj.params:
        if getattr(param, "help", None):
            assert " ".join(param.help.split()) in flat, (param.name, param.help)


def test_a_data_warning_appears_once_without_a_source_line(small, tmp_path):
    _, data = small
    r = _hmlvs("calibrate", str(data), "--iterations", "300", "--out", str(tmp_path / "c.yaml"))
    assert r.returncode == 0, r.stderr
    text = r.stdout + r.stderr
    assert text.count("too few points") == 1, text
    assert ".py:" not in text and "HmlvsDataWarning:" not in text  # no source line
    assert "warning too-few-points: too few points" in r.stderr
    assert "docs/glossary.md#too-few-points" in r.stderr


def test_json_and_quiet_collect_the_warnings(small, tmp_path):
    _, data = small
    r = _hmlvs("calibrate", str(data), "--iterations", "300", "--out", str(tmp_path / "c.yaml"),
               "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    kinds = [w["kind"] for w in doc["warnings"]]
    assert "too-few-points" in kinds and len(kinds) == len(set(w["message"]
                                                              for w in doc["warnings"]))
    assert "too few points" not in r.stderr and "warning" not in r.stderr
    q = _hmlvs("calibrate", str(data), "--iterations", "300", "--out",
               str(tmp_path / "c2.yaml"), "--quiet")
    assert q.returncode == 0 and "too few points" not in q.stdout + q.stderr


def test_fixed_adds_to_the_default_gauge(small, tmp_path, capsys):
    _, data = small
    code, out, _ = run_cli(["calibrate", str(data), "--iterations", "300", "--fixed", "Sv",
                         "--fixed", "k", "--out", str(tmp_path / "c.yaml"), "--json"], capsys)
    assert code == 0
    doc = json.loads(out)
    assert set(doc["fixed"]) == {"Su", "Sv", "Cu", "Cv", "k"}
    assert not any("scale gauge" in w["message"] for w in doc["warnings"])
    code, out, _ = run_cli(["calibrate", str(data), "--iterations", "300", "--free", "Cu",
                         "--out", str(tmp_path / "c.yaml"), "--json"], capsys)
    assert code == 0 and set(json.loads(out)["fixed"]) == {"Su", "Sv", "Cv"}
    code, _, err = run_cli(["calibrate", str(data), "--fixed", "Sw"], capsys)
    assert code == 2 and "unknown parameter 'Sw'" in err


def test_text_output_says_what_is_fixed_and_why(small, tmp_path, capsys):
    _, data = small
    code, out, _ = run_cli(["calibrate", str(data), "--iterations", "300", "--fixed", "Sv",
                         "--out", str(tmp_path / "c.yaml"), "--quiet"], capsys)
    assert code == 0
    line = next(x for x in out.splitlines() if x.startswith("held fixed: "))
    assert "Su: scale gauge" in line and "Sv:" in line and "Cv:" in line
    assert "rotation vector" in out


def test_warning_classes_are_in_errors_and_classify_every_message(small):
    s, _ = small
    for name in ("FlatDirectionWarning", "TooFewPointsWarning", "PoseVarietyWarning",
                 "GimbalLockWarning", "AtBoundWarning", "SetupWarning"):
        assert issubclass(getattr(hmlvs.errors, name), hmlvs.HmlvsDataWarning)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", hmlvs.HmlvsDataWarning)
        result = hmlvs.calibrate(s.dataset, fixed=("Su", "Sv", "Cu"), iterations=300, seed=0,
                                 judge=False).solve
    assert len(result.warnings) >= 2  # too few points, and a flat direction (Cv free)
    for w in result.warnings:
        assert hmlvs.errors.warning_category(w) is not hmlvs.HmlvsDataWarning, w
    assert hmlvs.errors.warning_category(result.warnings[0]) is hmlvs.errors.TooFewPointsWarning


def test_rotation_vector_is_well_defined_at_the_gimbal_lock():
    p = Parameters.nominal().replace(omega=0.3, phi=0.0, varphi=0.0)
    np.testing.assert_allclose(cli_common.rotation_vector(p), [0.0, 0.0, 0.3], atol=1e-12)
    # omega = -varphi = 1.546 (what an LM at phi ~ 0 can return) is a tilt of phi only
    p = Parameters.nominal().replace(omega=-1.546, phi=0.02, varphi=1.546)
    rv = cli_common.rotation_vector(p)
    assert math.isclose(float(np.linalg.norm(rv)), 0.02, rel_tol=1e-9)
    text = cli_common.rotation_text(p)
    assert "rotation vector" in text and "glossary.md#zyz-gimbal-lock" in text


def test_simulator_warns_when_the_board_cannot_suit_the_sensor():
    with pytest.warns(hmlvs.errors.SetupWarning, match=r"3 of 3 views cannot be used"):
        hmlvs.simulate.session(num_poses=3, seed=0, board=hmlvs.Checkerboard(square=1.5))
    with warnings.catch_warnings():
        warnings.simplefilter("error", hmlvs.errors.SetupWarning)
        hmlvs.simulate.session(num_poses=3, seed=0)


def test_report_shows_pixels_hand_eye_and_paper_columns_only_for_the_paper_sensor(small,
                                                                                     tmp_path,
                                                                                     capsys):
    s, data = small
    cal = hmlvs.Calibration(params=s.truth).save(tmp_path / "cal.yaml")
    code, _, _ = run_cli(["report", str(cal), str(data), "--out", str(tmp_path / "r.html")],
                      capsys)
    assert code == 0
    page = (tmp_path / "r.html").read_text()
    assert "0 threads" not in page and "0.000 s" not in page and "no solve" in page
    assert "hand_from_camera" in page and "f/Su" in page and "f/Sv" in page
    assert f"{s.truth.f / s.truth.Su:.6g} px" in page
    assert "paper best fit" in page  # the paper's sensor
    from hmlvs.calibration.solvers import evaluate
    from hmlvs.report.html import render_report

    other = s.truth.replace(f=16.0, H=300.0)  # another sensor
    page = render_report(evaluate(other, s.dataset), s.dataset)
    assert "paper best fit" not in page and "not those of the paper's sensor" in page


@pytest.mark.scene
def test_views_rejected_one_line_each_and_report_from_images(tmp_path, capsys):
    out = tmp_path / "imgs"
    session = hmlvs.simulate.session(num_poses=3, seed=5)
    hmlvs.simulate.render_session(session, out)
    cal = hmlvs.Calibration(params=session.truth).save(tmp_path / "cal.yaml")
    code, _, _ = run_cli(["report", str(cal), str(out), "--out", str(tmp_path / "r.html")], capsys)
    assert code == 0
    page = (tmp_path / "r.html").read_text()
    assert "of 3 image pairs used" in page and page.count("<td>p00") == 3

    doc = json.loads((out / "manifest.json").read_text())
    for p in doc["poses"]:
        p["off"] = "missing.png"
    bad = out / "bad.json"
    bad.write_text(json.dumps(doc))
    code, _, err = run_cli(["calibrate", str(bad), "--out", str(tmp_path / "c.yaml")], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert lines[0] == "error: no image pair gave a calibration point:"
    assert [x.split(":")[0].strip() for x in lines[1:]] == ["p000", "p001", "p002"]
    assert all("missing.png does not exist" in x for x in lines[1:])


@pytest.mark.slow
@pytest.mark.scene
def test_demo_is_determined_accurate_and_warning_free(tmp_path):
    r = _hmlvs("demo", "--out", str(tmp_path / "demo-out"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    text = r.stdout + r.stderr
    assert "warning" not in text.lower(), text
    assert "(not determined)" not in text and "NOT determined" not in text
    line = next(x for x in r.stdout.splitlines() if x.startswith("- determined by the data"))
    assert "all 10 free parameters" in line
    within = float(line.split("within ")[1].split(" standard")[0])
    assert within < 4.0, line
    held = float(next(x for x in r.stdout.splitlines()
                      if x.startswith("held-out RMS")).split()[2])
    assert held < 0.2
    # judged as every calibration is: the verdict first on the terminal, and in the file
    lines = r.stdout.splitlines()
    first = next(i for i, x in enumerate(lines) if x.startswith("VERDICT:"))
    assert lines[first].startswith("VERDICT: this calibration can be trusted")
    assert first < next(i for i, x in enumerate(lines) if x.startswith("method pso+lm"))
    cal = hmlvs.Calibration.load(tmp_path / "demo-out" / "calibration.yaml")
    assert cal.trustworthy is True and cal.verdict["map_sigma_mm"]["p95"] < 0.2
