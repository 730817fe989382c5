"""The README's Python quickstart runs as written."""

from pathlib import Path
import re

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"


@pytest.mark.smoke
@pytest.mark.filterwarnings("ignore::hmlvs.HmlvsDataWarning")
def test_quickstart_runs(tmp_path, monkeypatch, capsys):
    text = README.read_text()
    block = re.search(r"## Python quickstart\s+```python\n(.*?)```", text, re.S).group(1)
    assert len(block.strip().splitlines()) <= 12  # a ~10-line quickstart
    monkeypatch.chdir(tmp_path)
    exec(compile(block, "README quickstart", "exec"), {})
    out = capsys.readouterr().out.strip().splitlines()
    assert float(out[-1]) < 1.0  # held-out 3D error below 1 mm with 0.1 px of pixel noise
    assert (tmp_path / "calibration.yaml").exists()
