"""A command never overwrites one of its own inputs: an output that is an input (also through a
symbolic link), or an output folder that holds one, is refused with exit 2 naming both, and
every input is left byte for byte as it was; output kinds are checked before the first
write."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from conftest import run_cli as _run  # noqa: E402
import pytest


def _digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()
            if p.is_file()}


@pytest.fixture(scope="module")
def files(cli_files):
    return cli_files


@pytest.mark.parametrize("case", [
    lambda d, ds, cal, sess: (["export", str(cal), "--format", "opencv", "--out", str(cal)],
                              "--out"),
    lambda d, ds, cal, sess: (["calibrate", str(ds), "--method", "lm", "--out", str(ds)],
                              "--out"),
    lambda d, ds, cal, sess: (["calibrate", str(sess), "--model", "paper", "--save-data",
                               str(sess / "manifest.json"), "--out", str(d / "x.yaml")],
                              "--save-data"),
    lambda d, ds, cal, sess: (["calibrate", str(sess), "--out", str(sess / "v000_on.png")],
                              "--out"),
    lambda d, ds, cal, sess: (["measure", str(cal), str(sess), "--out",
                               str(sess / "v001_off.png")], "--out"),
    lambda d, ds, cal, sess: (["inspect", str(sess), "--out", str(sess)], "--out"),
    lambda d, ds, cal, sess: (["report", str(cal), str(ds), "--out", str(cal)], "--out"),
    lambda d, ds, cal, sess: (["scenario", "gauge-block", "--calibration", str(cal), "--out",
                               str(d)], "--out"),
])
def test_an_output_that_is_an_input_is_refused(files, capsys, case):
    d, ds, cal, sess = files
    argv, option = case(d, ds, cal, sess)
    before = {**_digest(d), **_digest(sess)}
    code, _, err = _run(argv, capsys)
    assert code == 2, err
    assert err.startswith(f"error: {option} ") and ("is one of this command's inputs" in err
                                                     or "holds this command's input" in err)
    assert {**_digest(d), **_digest(sess)} == before


def test_a_link_to_an_input_is_an_input(files, tmp_path, capsys):
    _, _, cal, _ = files
    link = tmp_path / "link.yaml"
    link.symlink_to(cal)
    before = cal.read_bytes()
    code, _, err = _run(["export", str(cal), "--format", "json", "--out", str(link)], capsys)
    assert code == 2 and "is one of this command's inputs" in err
    assert cal.read_bytes() == before and link.is_symlink()


def test_every_output_kind_is_checked_before_the_first_write(files, tmp_path, capsys):
    _, ds, _, _ = files
    existing = tmp_path / "existing.yaml"
    existing.write_text("keep me\n")
    code, _, err = _run(["calibrate", str(ds), "--method", "lm", "--out", str(existing),
                         "--report", str(tmp_path / "r.txt")], capsys)
    assert code == 2 and "--report" in err and "HTML report" in err
    assert existing.read_text() == "keep me\n"


def test_an_output_beside_the_inputs_is_fine(files, tmp_path, capsys):
    _, _, cal, sess = files
    code, _, err = _run(["inspect", str(sess), "--out", str(sess / "pictures")], capsys)
    assert code in (0, None), err
    assert (sess / "pictures").is_dir()
    code, _, err = _run(["export", str(cal), "--format", "json", "--out",
                         str(tmp_path / "cal.json")], capsys)
    assert code in (0, None), err
    json.loads((tmp_path / "cal.json").read_text())
