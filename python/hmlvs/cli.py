"""The ``hmlvs`` command line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

app = typer.Typer(
    name="hmlvs",
    help="Calibrate and use a hand-mounted laser-vision sensor.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.command()
def simulate(
    out: Path = typer.Argument(..., help="Data set file to write (.npz or .json)."),
    poses: int = typer.Option(30, help="Number of robot poses in the session."),
    pixel_noise: float = typer.Option(0.0, help="Pixel noise, standard deviation (px)."),
    point_noise: float = typer.Option(0.0, help="Reference-point noise, std (mm)."),
    seed: int = typer.Option(0, help="Random seed."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
) -> None:
    """Simulate a checkerboard calibration session (SCORBOT ER-VII, paper set-up).

    Example: hmlvs simulate session.npz --poses 40 --pixel-noise 0.1
    """
    from . import simulate as sim

    s = sim.session(num_poses=poses, pixel_noise=pixel_noise, point_noise=point_noise,
                    seed=seed)
    s.dataset.save(out)
    if as_json:
        typer.echo(json.dumps({"file": str(out), "points": len(s.dataset),
                               "poses": s.dataset.num_poses}))
    else:
        typer.echo(s.summary())
        typer.echo(f"written to {out}")


@app.command()
def demo(
    seed: int = typer.Option(0, help="Random seed."),
    poses: int = typer.Option(30, help="Number of robot poses."),
) -> None:
    """Simulate a SCORBOT ER-VII calibration session and summarise it.

    Example: hmlvs demo --seed 1
    """
    from . import simulate as sim

    s = sim.session(num_poses=poses, pixel_noise=0.1, seed=seed)
    typer.echo(s.summary())


def main(argv: Optional[list[str]] = None) -> None:
    app(args=argv)
