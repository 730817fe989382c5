"""hmlvs scenario: measurement scenarios (cylinder scan, gauge block)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .common import app, echo_json, guard
from .options import JSON_OPTION


@app.command()
def scenario(
    name: str = typer.Argument(..., help="gauge-block (the paper's Table 3) or cylinder "
                               "(Fig. 13, a scan of a tube with holes)."),
    out: Optional[Path] = typer.Option(
        None, "--out", "-o", help="Folder for the rendered images, manifest.json and the "
        "results (gauge_block.json; cloud.ply and cloud.png for the cylinder)."),
    seed: int = typer.Option(0, help="Random seed (calibration session, robot, images)."),
    trials: int = typer.Option(10, help="gauge-block: trials per corner."),
    step: float = typer.Option(3.0, help="cylinder: scan step along the axis (mm)."),
    calibration: Optional[Path] = typer.Option(
        None, help="Calibration file to measure with; default: calibrate a simulated noisy "
        "checkerboard session of the true sensor first."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Simulate a measurement scenario of the paper end to end with rendered images.

    Example: hmlvs scenario gauge-block --out gauge-out --seed 0
    """
    from ..data.calibration_file import Calibration
    from ..paper import scenarios as scenes

    with guard(as_json):
        if name not in ("gauge-block", "cylinder"):
            raise ValueError(f"unknown scenario {name!r}; choose gauge-block or cylinder")
        from ..guard import refuse_overwrite

        refuse_overwrite([calibration], [], [("--out", out)])
        cal = Calibration.load(calibration) if calibration is not None else None
        bar = None
        if not as_json:
            from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
            bar = Progress(TextColumn("{task.description}"), BarColumn(),
                           TextColumn("{task.completed}/{task.total}"), TimeRemainingColumn(),
                           transient=True)
        task = None

        def progress(done: int, total: int) -> None:
            nonlocal task
            if bar is not None:
                if task is None:
                    task = bar.add_task("rendering", total=total)
                bar.update(task, completed=done, total=total)

        try:
            if bar is not None:
                bar.start()
            if name == "gauge-block":
                result = scenes.gauge_block(cal, trials=trials, seed=seed, out_dir=out,
                                            progress=progress)
            else:
                result = scenes.cylinder_scan(cal, seed=seed, step=step, out_dir=out,
                                              progress=progress)
        finally:
            if bar is not None:
                bar.stop()
    if as_json:
        echo_json(result.to_dict())
        return
    typer.echo(result.summary())
    if result.files:
        typer.echo(f"written to {out}: " + ", ".join(Path(str(f)).name
                                                    for f in result.files.values()))
