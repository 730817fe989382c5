"""hmlvs inspect: one picture per view of a session, with what was found in it."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .common import app, command, finish, inputs_of, load_robot, session_of
from .options import JSON_OPTION, ROBOT_OPTION, out_option


# -- hmlvs inspect ---------------------------------------------------------------------------
@app.command("inspect")
def inspect_images(
    data: Path = typer.Argument(..., help="An image session: a folder with manifest.json (or "
                                "the manifest), with a board."),
    out: Path = out_option("inspect", "Folder for the pictures: one PNG per view, named by its "
                           "id."),
    robot: Optional[Path] = ROBOT_OPTION,
    as_json: bool = JSON_OPTION,
) -> None:
    """Draw what the image pipeline found in each view, and say why a view was dropped.

    One picture per view: the numbered board corners, the stripe centres and the rejected
    scan lines coloured by status. One line per view on the terminal: used or rejected and
    why, corners, scan lines per stripe status.

    Example: hmlvs inspect session/ --out inspect/
    """
    from ..report.inspect import inspect_session

    with command(as_json) as caught:
        from ..guard import refuse_overwrite

        session = session_of(data)  # a manifest read and checked once
        refuse_overwrite([*inputs_of(session), robot], [], [("--out", out)])
        views = inspect_session(session, out, robot=load_robot(robot))
    if finish(caught, as_json, [v.to_dict() for v in views]) is None:
        return
    for v in views:
        typer.echo(v.line())
    used = sum(v.used for v in views)
    typer.echo(f"{used} of {len(views)} views used; pictures in {out}")
