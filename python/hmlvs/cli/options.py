"""The options several commands share."""

from __future__ import annotations

import typer

#: --json of every command: the summary on stdout as JSON, its warnings included
JSON_OPTION = typer.Option(False, "--json", help="Print a JSON summary, warnings included.")

ROBOT_OPTION = typer.Option(
    None, "--robot", help="Robot description (YAML/JSON, what hmlvs.Robot.to_dict writes) "
    "for joint readings; default: the manifest's robot, else SCORBOT ER-VII.")
