"""The command line's error policy: bad input and environment faults exit 2 with one line
naming the problem, internal errors exit 1 without a traceback (unless --debug), JSON output is
always valid JSON, and a failed write leaves nothing behind."""

from __future__ import annotations

import json
import os
from pathlib import Path

from conftest import run_cli
from hmlvs import _io
from hmlvs.cli import main
import pytest


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("policy")
    path = d / "sim.npz"
    with pytest.raises(SystemExit):
        main(["simulate", str(path), "--poses", "8", "--seed", "1"])
    return path


def test_output_path_that_is_a_folder_exits_2_naming_it(data, tmp_path, capsys):
    target = tmp_path / "existing_dir.yaml"
    target.mkdir()
    code, _, err = run_cli(["calibrate", str(data), "--method", "lm", "-o", str(target)], capsys)
    assert code == 2
    assert err.strip().splitlines() == [f"error: {target}: is a folder: give a file name"]


def test_output_under_a_file_exits_2(data, tmp_path, capsys):
    parent = tmp_path / "afile"
    parent.write_text("x")
    code, _, err = run_cli(["calibrate", str(data), "--method", "lm", "-o",
                         str(parent / "cal.yaml")], capsys)
    assert code == 2 and "a part of this path is a file, not a folder" in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes through read-only permissions")
def test_read_only_location_exits_2(data, tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        code, _, err = run_cli(["calibrate", str(data), "--method", "lm", "-o",
                             str(ro / "cal.yaml")], capsys)
    finally:
        ro.chmod(0o700)
    assert code == 2 and "permission denied" in err
    assert list(ro.iterdir()) == []


@pytest.mark.parametrize("command", ["calibrate", "simulate", "measure", "export"])
def test_every_command_on_a_read_only_file_system_exits_2(data, tmp_path, capsys, monkeypatch,
                                                          command):
    import errno
    import tempfile

    cal = tmp_path / "cal.yaml"
    assert run_cli(["calibrate", str(data), "--method", "lm", "-o", str(cal)], capsys)[0] == 0
    out = tmp_path / "out"
    out.mkdir()

    def read_only(*a, **k):
        raise OSError(errno.EROFS, "Read-only file system", str(out))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    argv = {"calibrate": ["calibrate", str(data), "--method", "lm", "-o", str(out / "c.yaml")],
            "simulate": ["simulate", str(out / "s.npz"), "--poses", "4"],
            "measure": ["measure", str(cal), str(data), "-o", str(out / "cloud.ply")],
            "export": ["export", str(cal), "--format", "json", "--out", str(out / "e.json")]}
    code, _, err = run_cli(argv[command], capsys)
    assert code == 2, err
    assert err.strip().splitlines() == [
        f"error: {out}: the file system is read-only: choose another location"]
    assert list(out.iterdir()) == []


def test_disk_full_exits_2_and_leaves_nothing(data, tmp_path, capsys, monkeypatch):
    import errno

    real_fsync = os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    code, _, err = run_cli(["calibrate", str(data), "--method", "lm", "-o",
                         str(tmp_path / "cal.yaml")], capsys)
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert code == 2 and "the disk is full" in err
    assert list(tmp_path.iterdir()) == []  # no target, no temporary file


def test_a_long_legal_file_name_works(tmp_path):
    name = "c" * 240 + ".yaml"  # 245 characters: legal on Linux (255), temp name must fit
    with _io.atomic_write(tmp_path / name) as fh:
        fh.write("x: 1\n")
    assert (tmp_path / name).read_text() == "x: 1\n"


def test_stale_temporary_files_of_killed_writes_are_cleaned(tmp_path):
    import subprocess
    import sys

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # a process that has ended: its temporaries are stale
    stale = tmp_path / f".hmlvs-tmp-{gone.pid}-abc12345.tmp"
    stale.write_text("half")
    os.utime(stale, (1, 1))  # as if left by a write killed long ago
    fresh = tmp_path / f".hmlvs-tmp-{gone.pid}-def45678.tmp"
    fresh.write_text("in progress")  # too recent: kept
    users = tmp_path / ".hmlvs-abc123.tmp"  # not a name of ours: a user's file, kept
    users.write_text("mine")
    os.utime(users, (1, 1))
    with _io.atomic_write(tmp_path / "out.txt") as fh:
        fh.write("ok")
    assert not stale.exists() and fresh.exists() and users.read_text() == "mine"


def test_internal_error_exits_1_with_one_line_and_debug_shows_it(data, tmp_path, capsys,
                                                                  monkeypatch):
    import hmlvs.calibration.solvers as solvers

    def broken(*a, **k):
        raise KeyError("boom")

    monkeypatch.setattr(solvers, "calibrate", broken)
    code, _, err = run_cli(["calibrate", str(data), "-o", str(tmp_path / "c.yaml")], capsys)
    assert code == 1
    assert err.strip().splitlines() == [
        "error: internal error (KeyError: 'boom'); this is a bug in hmlvs: run again with "
        "--debug for the traceback and report it"]
    with pytest.raises(KeyError):
        main(["--debug", "calibrate", str(data), "-o", str(tmp_path / "c.yaml")])


def test_json_output_is_valid_json_with_null_for_missing_figures():
    text = _io.json_text({"rms": float("nan"), "x": [1.0, float("inf")], "ok": 2})
    assert json.loads(text) == {"rms": None, "x": [1.0, None], "ok": 2}
    assert "NaN" not in text and "Infinity" not in text


def test_json_error_output_is_valid_json(tmp_path, capsys):
    code, out, err = run_cli(["calibrate", str(tmp_path / "missing.npz"), "--json"], capsys)
    assert code == 2
    assert "error" in json.loads(out)
    assert Path(tmp_path / "missing.npz").exists() is False


def _third_png_raises(monkeypatch, error: BaseException) -> dict:
    """The image writer raises ``error`` at its third image (the others are written); the
    count of calls, for the test to check."""
    import hmlvs.data.manifest as manifest

    real = manifest.write_png
    calls = {"n": 0}

    def third_raises(path, image):
        calls["n"] += 1
        if calls["n"] == 3:
            raise error
        real(path, image)

    monkeypatch.setattr(manifest, "write_png", third_raises)
    return calls


def test_simulate_with_images_is_all_or_nothing(tmp_path, capsys, monkeypatch):
    _third_png_raises(monkeypatch, OSError(28, "No space left on device"))
    code, _, err = run_cli(["simulate", str(tmp_path / "s.npz"), "--poses", "4", "--images",
                         str(tmp_path / "imgs")], capsys)
    assert code == 2 and "the disk is full" in err
    assert list(tmp_path.iterdir()) == []  # no data set, no image folder, no temporary folder
    monkeypatch.undo()  # the real image writer again
    code, _, _ = run_cli(["simulate", str(tmp_path / "s.npz"), "--poses", "4", "--images",
                       str(tmp_path / "imgs")], capsys)
    assert code == 0
    assert {p.name for p in tmp_path.iterdir()} == {"s.npz", "imgs"}
    assert (tmp_path / "imgs" / "manifest.json").is_file()
    assert (tmp_path / "imgs" / "truth.npz").is_file()


def test_calibration_is_not_left_without_its_report(data, tmp_path, capsys, monkeypatch):
    import hmlvs.report.html as html

    def full(*a, **k):
        raise OSError(28, "No space left on device", str(tmp_path / "r.html"))

    monkeypatch.setattr(html, "write_report", full)
    code, _, err = run_cli(["calibrate", str(data), "--method", "lm", "-o",
                         str(tmp_path / "cal.yaml"), "--report", str(tmp_path / "r.html")],
                        capsys)
    assert code == 2 and "the disk is full" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, message", [
    (["--holdout", "-0.5"], r"--holdout must be a fraction in \[0, 1\), got -0.5"),
    (["--holdout", "nan"], r"--holdout must be a fraction in \[0, 1\), got nan"),
    (["--mode", "bogus"], "--mode must be corners or homography, got 'bogus'"),
    # values pybind11 refused with a TypeError traceback
    (["--seed", "-1"], r"calibrate.seed must be an integer >= 0, got -1"),
    (["--iterations", "1099511627776"],
     r"pso.iterations must be at most 2147483647, got 1099511627776"),
    (["--threads", "2147483648"], r"calibrate.threads must be at most 2147483647, got 2147483648"),
])
def test_options_are_checked_whatever_the_input(data, tmp_path, capsys, args, message):
    import re

    code, _, err = run_cli(["calibrate", str(data), "-o", str(tmp_path / "c.yaml"), *args], capsys)
    assert code == 2 and re.search(message, err), err
    assert not (tmp_path / "c.yaml").exists()


def test_measuring_with_a_calibration_whose_plane_no_ray_meets(data, tmp_path, capsys):
    from hmlvs import Calibration, Parameters

    cal = Calibration(params=Parameters.nominal().replace(theta=-0.5)).save(tmp_path / "c.yaml")
    code, _, err = run_cli(["measure", str(cal), str(data), "-o", str(tmp_path / "cloud.ply")],
                        capsys)
    assert code == 2 and "none of the" in err and "meets the laser plane" in err
    assert not (tmp_path / "cloud.ply").exists()


def test_empty_or_fractional_subsets_are_refused(data):
    from hmlvs import Dataset

    ds = Dataset.load(data)
    with pytest.raises(ValueError, match="the subset is empty"):
        ds.subset([])
    with pytest.raises(ValueError, match="whole numbers"):
        ds.subset([0.5])


def test_held_out_rms_is_not_available_or_over_the_rays_that_meet_the_plane(data):
    """An empty held-out set, or one whose rays all miss the plane, has no RMS (None, with a
    note saying why), never NaN; rays that miss are counted and left out of the RMS."""
    import hmlvs
    from hmlvs import Dataset
    from hmlvs.calibration.solvers import evaluate
    import numpy as np

    ds = Dataset.load(data)
    q = hmlvs.Parameters.nominal()
    empty = Dataset(np.zeros((0, 2)), np.zeros((0, 4, 4)), np.zeros((0, 3)))
    r = evaluate(q, ds, empty)
    assert r.test_rms is None
    assert "held-out RMS not available: the held-out set is empty" in r.notes
    test = ds.subset(np.arange(20))
    errors = evaluate(q, ds, test).test_errors
    assert np.isfinite(errors).all()
    miss = test.pixels.copy()
    miss[:5, 1] = 0.0  # rows far above the laser line: rays parallel to or away from the plane
    missing = Dataset(miss, test.poses, test.points, ids=test.ids)
    q_miss = q.replace(theta=0.01)  # the plane's trace moves to the image's lower half
    full = evaluate(q_miss, ds, test)
    part = evaluate(q_miss, ds, missing)
    n_miss = int((~np.isfinite(part.test_errors)).sum())
    assert n_miss == 5 and np.isfinite(full.test_errors).all()
    assert "5 of 20 held-out points have rays that miss the laser plane at these parameters; " \
        "the held-out RMS is over the others" in part.notes
    want = np.sqrt(np.mean(full.test_errors[5:] ** 2))
    assert part.test_rms == pytest.approx(want, rel=1e-12)
    allmiss = Dataset(np.c_[test.pixels[:, 0], np.zeros(20)], test.poses, test.points)
    r = evaluate(q_miss, ds, allmiss)
    assert r.test_rms is None and any("every held-out point's ray misses" in n for n in r.notes)
    text = _io.json_text({"test_rms_mm": r.test_rms})
    assert json.loads(text) == {"test_rms_mm": None}


def test_measure_in_text_mode_names_the_rejected_pairs(data, tmp_path, capsys):
    """A pair rejected by measure is named on the terminal, not only in --json."""
    import hmlvs
    from hmlvs import Dataset, cli
    import numpy as np

    ds = Dataset.load(data)
    cal = hmlvs.Calibration(params=cli.mounted_truth(cli.MOUNTING_DEG)).save(tmp_path / "cal.yaml")
    entries = []
    for k in range(3):
        rows = ds.pose_index == k if ds.pose_index is not None else np.arange(len(ds)) == k
        np.savetxt(tmp_path / f"p{k}.csv", ds.pixels[rows], delimiter=",", header="u,v",
                   comments="")
        entries.append({"id": f"p{k}", "stripe": f"p{k}.csv",
                        "pose": ds.poses[rows][0].tolist()})
    entries[1]["stripe"] = "gone.csv"
    (tmp_path / "manifest.json").write_text(json.dumps(
        {"format": "hmlvs-images", "version": 1, "poses": entries}))
    code, out, err = run_cli(["measure", str(cal), str(tmp_path), "-o", str(tmp_path / "c.csv")],
                          capsys)
    assert code == 0, err
    rejected = [x for x in out.splitlines() if x.startswith("p1: rejected: ")]
    assert len(rejected) == 1 and "gone.csv" in rejected[0], out
    assert not any(x.startswith(("p0: rejected", "p2: rejected")) for x in out.splitlines())


def test_simulate_with_images_interrupted_leaves_nothing(tmp_path, capsys, monkeypatch):
    """Ctrl-C while the images are rendered: exit 130, neither the data set nor the images."""
    calls = _third_png_raises(monkeypatch, KeyboardInterrupt())
    code, out, _ = run_cli(["simulate", str(tmp_path / "s.npz"), "--poses", "4", "--images",
                         str(tmp_path / "imgs")], capsys)
    assert code == 130 and calls["n"] == 3
    assert list(tmp_path.iterdir()) == []  # no s.npz, no image folder, no temporary folder
