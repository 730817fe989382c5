"""The ``hmlvs`` command line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from ._io import atomic_write

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


@app.command()
def design(
    f: float = typer.Option(8.0, "--f", help="Effective focal length (mm)."),
    pitch: float = typer.Option(0.0074, help="Pixel pitch (mm/px), square pixels."),
    width: int = typer.Option(640, help="Image width (px)."),
    height: int = typer.Option(480, help="Image height (px)."),
    baseline: float = typer.Option(100.0, "--H", "--baseline", help="Laser baseline H (mm)."),
    theta: float = typer.Option(25.0, help="Laser projection angle (deg)."),
    k: float = typer.Option(0.0, help="Radial distortion k (1/mm^2), division model."),
    true_h: Optional[float] = typer.Option(
        None, "--true-H", help="The real H for the Fig. 6 error (mm); default H - 1."),
    true_theta: Optional[float] = typer.Option(
        None, "--true-theta", help="The real theta for the Fig. 6 error (deg); default "
        "theta - 2.5."),
    out: Optional[Path] = typer.Option(
        None, "--out", help="Folder for the PNG plots and design.md (a Markdown summary)."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
) -> None:
    """Sensor design analysis: measurement ranges, resolution, error from a wrong H or theta.

    Example: hmlvs design --H 100 --theta 25 --out design-out
    """
    import math

    from . import design as dsg

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
            files = dsg.plot(report, out, errors=errors)
            md = out / "design.md"
            with atomic_write(md) as fh:
                fh.write(report.markdown(errors=errors, files=files))
            files.append(md)
    except ValueError as e:
        typer.echo(f"error: {' '.join(str(e).split())}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        summary = report.to_dict()
        summary["errors"] = [e.to_dict() for e in errors]
        summary["files"] = [str(p) for p in files]
        typer.echo(json.dumps(summary, indent=2))
    else:
        typer.echo(str(report))
        for e in errors:
            typer.echo(str(e))
        if files:
            typer.echo(f"written to {out}: " + ", ".join(p.name for p in files))


@app.command()
def study(
    quick: bool = typer.Option(
        False, "--quick", help="Fewer runs: 30 LM starts, 5 PSO runs and 200,000 random-search "
        "evaluations per s (about 20 s on 2 cores)."),
    runs_lm: Optional[int] = typer.Option(
        None, "--runs-lm", help="LM starts per s, the same for paper-mode and modern LM "
        "(default 1000, the paper's; quick 30)."),
    runs_pso: Optional[int] = typer.Option(
        None, "--runs-pso", help="PSO runs per s, also polished for PSO+LM (default 10; "
        "quick 5)."),
    evaluations: Optional[int] = typer.Option(
        None, "--evaluations", help="Random-search evaluations per s (default 1,000,000; "
        "quick 200,000)."),
    spreads: Optional[list[float]] = typer.Option(
        None, "--s", help="A spread s of the initial candidates (Eq. 22); repeat for several "
        "(default 0.0001 0.001 0.01 0.1 0.2)."),
    seed: int = typer.Option(0, help="Random seed of the data and of every method."),
    threads: Optional[int] = typer.Option(
        None, help="Worker threads (default: all cores); results do not depend on it."),
    out: Optional[Path] = typer.Option(
        None, "--out", help="Folder for study.md (the tables) and the PNG plots."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
    progress: bool = typer.Option(
        True, "--progress/--no-progress", help="Show a progress bar on stderr."),
) -> None:
    """The paper's simulation study (Table 1, Fig. 8): RS, paper-mode LM, PSO, modern LM and
    PSO+LM from the same initial candidates, for each spread s.

    Example: hmlvs study --quick --out study-out
    """
    from . import study as st

    try:
        result = st.study(s_values=st.PAPER_S if not spreads else spreads, runs_lm=runs_lm,
                          runs_pso=runs_pso, evaluations=evaluations, quick=quick, seed=seed,
                          threads=threads, progress=progress, out_dir=out)
    except ValueError as e:
        typer.echo(f"error: {' '.join(str(e).split())}", err=True)
        raise typer.Exit(2) from None
    except KeyboardInterrupt:
        typer.echo("interrupted: no results written", err=True)
        raise typer.Exit(130) from None
    if as_json:
        typer.echo(json.dumps(result.to_dict(), indent=2))
    else:
        typer.echo(result.table())
        if result.files:
            typer.echo(f"written to {out}: " + ", ".join(p.name for p in result.files))


def main(argv: Optional[list[str]] = None) -> None:
    app(args=argv)
