"""The options several commands share."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

#: --json of every command: the summary on stdout as JSON, its warnings included
JSON_OPTION = typer.Option(False, "--json", help="Print a JSON summary, warnings included.")

ROBOT_OPTION = typer.Option(
    None, "--robot", help="Robot description (YAML/JSON, what hmlvs.Robot.to_dict writes) "
    "for joint readings; default: the manifest's robot, else SCORBOT ER-VII.")


def out_option(default: str, help: str) -> Any:
    """The --out (-o) option of a command that writes one file or folder, ``default``
    unless given."""
    return typer.Option(Path(default), "--out", "-o", help=help)


FRAME_OPTION = typer.Option(
    "base", "--frame", help="base: the points in the robot base frame (needs each frame's "
    "robot pose and a calibrated hand-eye); camera: each frame's profile in the camera frame, "
    "without robot poses (what a bench calibration measures).")
