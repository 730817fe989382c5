"""The README's Python quickstart runs as written, without a warning, and what it measures is
right; the README stays short."""

from pathlib import Path
import re
import warnings

import numpy as np
import pytest

README = Path(__file__).resolve().parents[2] / "README.md"


def test_the_readme_is_short():
    assert len(README.read_text().splitlines()) <= 200


@pytest.mark.slow
@pytest.mark.smoke
def test_quickstart_runs(tmp_path, monkeypatch, capsys):
    text = README.read_text()
    block = re.search(r"## Python quickstart\s+```python\n(.*?)```", text, re.S).group(1)
    assert len(block.strip().splitlines()) <= 14  # a short quickstart
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the quickstart runs without a warning
        exec(compile(block, "README quickstart", "exec"), ns)
    assert (tmp_path / "calibration.yaml").exists()
    assert "model opencv, chain mode" in capsys.readouterr().out
    # the frame's stripe, measured, lies on the board's plane (the stripe's noise, about
    # 0.1 mm RMS at these distances: tests/unit/test_measurer.py)
    s, prof = ns["session"], ns["profile"]
    bfb = s.sensor.base_from_board
    d = (prof.points[prof.measured] - bfb[:3, 3]) @ bfb[:3, 2]
    assert prof.measured.sum() > 200
    assert np.sqrt(np.mean(d**2)) < 0.3


@pytest.mark.slow
def test_every_command_block_runs(tmp_path):
    """Each shell block of the README, line by line as a user types it (the set-up lines
    `make ...` are what CI itself runs), with the installed `hmlvs` and `python` first on the
    path: every command exits 0 and writes what it says."""
    import os
    import subprocess
    import sys

    blocks = re.findall(r"```(?:bash|sh)\n(.*?)```", README.read_text(), re.S)
    lines = [ln.split("  #")[0].strip() for b in blocks for ln in b.splitlines()]
    lines = [ln for ln in lines if ln and not ln.startswith(("#", "make "))]
    assert any(ln.startswith("hmlvs calibrate") for ln in lines)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    for line in lines:
        r = subprocess.run(line, shell=True, cwd=tmp_path, env=env, capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == 0, (line, r.stdout[-2000:], r.stderr[-2000:])
    for out in ("mysensor/manifest.json", "cal.yaml", "report.html", "camera.yaml",
                "cloud.ply"):
        assert (tmp_path / out).is_file(), out
    assert list((tmp_path / "inspect").glob("*.png"))
