"""The installed `hmlvs` script, run as a user runs it: in a fresh process, from the
environment the suite runs in (make test's .venv, and .venv-lowest with the declared lower
bounds of the dependencies), so a package the code imports but pyproject.toml does not declare
fails here, not on a user's machine."""

import os
from pathlib import Path
import subprocess
import sys

import hmlvs
from hmlvs import cli
import pytest
import typer

pytestmark = pytest.mark.smoke

SCRIPT = Path(sys.executable).parent / "hmlvs"
COMMANDS = sorted(typer.main.get_command(cli.app).commands)


def _script(*args, cwd=None):
    assert SCRIPT.exists(), (f"no installed hmlvs script beside {sys.executable}: the suite "
                             "must run in the environment the package was installed into")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    return subprocess.run([str(SCRIPT), *args], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=300)


def test_the_command_list_is_the_documented_one():
    # every command is covered by the --help test below; a new one joins it by itself
    assert {"calibrate", "demo", "measure", "report", "simulate"} <= set(COMMANDS)


def test_version():
    r = _script("--version")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"hmlvs {hmlvs.__version__}"
    assert r.stderr == ""


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_help(command):
    r = _script(*([command] if command else []), "--help")
    assert r.returncode == 0, r.stderr
    assert "Show this message and exit." in r.stdout
    assert r.stderr == ""


def test_bad_input_is_an_error_not_a_crash(tmp_path):
    # the command line's error policy with whatever typer (and click) the environment has:
    # a missing input is exit 2 with one line naming it, not an internal error
    missing = tmp_path / "no-such-data.npz"
    r = _script("calibrate", str(missing), "--out", str(tmp_path / "cal.yaml"))
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "no-such-data.npz" in r.stderr and "internal error" not in r.stderr
    assert not (tmp_path / "cal.yaml").exists()


def test_usage_error_keeps_typers_exit_code(tmp_path):
    r = _script("calibrate", "--no-such-option")
    assert r.returncode == 2 and "No such option" in r.stderr


def test_demo(tmp_path):
    r = _script("demo", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "calibration.yaml").exists()
    assert "determined by the data" in r.stdout


def test_build_group_holds_the_build_requirements():
    # make builds the extension in .venv without build isolation, from the dependency group
    # `build`: it must hold what [build-system] requires
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())
    assert set(project["build-system"]["requires"]) <= set(project["dependency-groups"]["build"])
