"""The ``hmlvs design`` command: exit codes, JSON and files (numbers as in test_design.py)."""

import json

from hmlvs.cli import app
import pytest
from typer.testing import CliRunner

runner = CliRunner()


def test_cli_json():
    res = runner.invoke(app, ["design", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["ranges_mm"]["z"] == pytest.approx(263.164978, rel=1e-8)
    assert d["ranges_mm"]["x_growth"] == pytest.approx(155.550239, rel=1e-8)
    assert d["errors"][0]["max_mm"] == pytest.approx(4.355231151, rel=1e-8)
    assert d["errors"][1]["max_mm"] == pytest.approx(117.752992, rel=1e-7)
    assert d["files"] == []


@pytest.mark.slow
def test_cli_out_writes_pngs_and_markdown(tmp_path):
    out = tmp_path / "d"
    res = runner.invoke(app, ["design", "--width", "64", "--height", "48", "--pitch", "0.074",
                              "--H", "100", "--theta", "25", "--out", str(out)])
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in out.iterdir())
    assert names == ["design.md", "design_error_H.png", "design_error_theta.png",
                     "design_footprint.png", "design_resolution.png", "design_sweep_H.png",
                     "design_sweep_theta.png"]
    md = (out / "design.md").read_text()
    # 64 x 48 px of 74 um is the same sensor area with 10x coarser pixels: row 0 at
    # Yd = -23.5 * 0.074 = -1.739 mm, D = 1.991461, z = 401.7151; row 47: D = 5.469461,
    # z = 146.2667; range 255.4484
    assert "| z, extent over the usable image | 255.45 |" in md
    assert "written to" in res.stdout


@pytest.mark.parametrize(
    "args, match",
    [(["--H", "-1"], "error: H must be a finite number > 0 (mm), got -1.0"),
     (["--theta", "95"], "error: theta must lie in (-pi/2, pi/2) rad"),
     (["--width", "0"], "error: image width must be an integer >= 2 (px), got 0"),
     (["--pitch", "0"], "error: the horizontal pixel pitch Su must be"),
     (["--H", "1", "--true-H", "0"], "error: the true value is invalid: H must be")],
)
def test_cli_bad_input_exits_2_with_one_line(args, match):
    res = runner.invoke(app, ["design", *args])
    assert res.exit_code == 2
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(match)
