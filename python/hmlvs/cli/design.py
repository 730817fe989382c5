"""hmlvs design: the paper's design analysis (Figs. 4-6) for a sensor's parameters."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .._io import atomic_write
from .common import app, echo_json, interrupted
from .options import JSON_OPTION


@app.command()
def design(
    f: float = typer.Option(8.0, "--f", help="Effective focal length (mm)."),
    pitch: float = typer.Option(0.0074, help="Pixel pitch (mm/px), square pixels."),
    width: int = typer.Option(640, help="Image width (px)."),
    height: int = typer.Option(480, help="Image height (px)."),
    baseline: float = typer.Option(100.0, "--H", "--baseline", help="Laser baseline H (mm)."),
    theta: float = typer.Option(25.0, help="Laser projection angle (deg; like every angle "
                                "given on the command line; results are in rad)."),
    k: float = typer.Option(0.0, help="Radial distortion k (1/mm^2), division model."),
    true_h: Optional[float] = typer.Option(
        None, "--true-H", help="The real H for the Fig. 6 error (mm); default H - 1."),
    true_theta: Optional[float] = typer.Option(
        None, "--true-theta", help="The real theta for the Fig. 6 error (deg); default "
        "theta - 2.5."),
    out: Optional[Path] = typer.Option(
        None, "--out", help="Folder for the PNG plots and design.md (a Markdown summary)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Sensor design analysis: measurement ranges, resolution, error from a wrong H or theta.

    Example: hmlvs design --H 100 --theta 25 --out design-out
    """
    import math

    from ..paper import design as dsg

    try:
        sensor = dsg.Sensor.make(f=f, pixel_pitch=pitch, image_size=(width, height), H=baseline,
                                 theta=math.radians(theta), k=k)
        report = dsg.analyze(sensor=sensor)
        errors = [
            dsg.error_from_wrong(sensor=sensor, H_true=baseline - 1.0 if true_h is None
                                 else true_h),
            dsg.error_from_wrong(sensor=sensor, theta_true=math.radians(
                theta - 2.5 if true_theta is None else true_theta)),
        ]
        files = []
        if out is not None:
            from contextlib import nullcontext

            from rich.console import Console

            from .._io import atomic_folder

            status = nullcontext() if as_json else Console(stderr=True).status(
                f"writing the design plots to {out} (about 10-30 s)")
            # the plots and design.md as one: a run stopped while writing leaves none of them
            with status, atomic_folder(out, last=("design.md",)) as tmp:
                plots = dsg.plot(report, tmp, errors=errors)
                with atomic_write(tmp / "design.md") as fh:
                    fh.write(report.markdown(errors=errors, files=plots))
            files = [out / p.name for p in plots] + [out / "design.md"]
            if not as_json:
                typer.echo(f"plots written to {out}", err=True)
    except ValueError as e:
        typer.echo(f"error: {' '.join(str(e).split())}", err=True)
        raise typer.Exit(2) from None
    except KeyboardInterrupt as e:
        raise interrupted(e) from None
    if as_json:
        summary = report.to_dict()
        summary["errors"] = [e.to_dict() for e in errors]
        summary["files"] = [str(p) for p in files]
        echo_json(summary)
    else:
        typer.echo(str(report))
        for e in errors:
            typer.echo(str(e))
        if files:
            typer.echo(f"written to {out}: " + ", ".join(p.name for p in files))
