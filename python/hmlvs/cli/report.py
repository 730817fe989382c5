"""hmlvs report: a calibration file evaluated on a data set or an image session, as HTML."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer

from .common import app, command, finish, inputs_of, load_robot, session_of
from .options import JSON_OPTION, ROBOT_OPTION, out_option


@app.command()
def report(
    calibration: Path = typer.Argument(..., help="Calibration file (.yaml or .json)."),
    data: Path = typer.Argument(..., help="Data set to evaluate on (.npz or .json), or an "
                                "image manifest (a folder with manifest.json, or the file)."),
    test: Optional[Path] = typer.Option(None, help="Held-out data set."),
    out: Path = out_option("report.html", "HTML file to write."),
    mode: str = typer.Option("corners", help="Calibration points from images: corners or "
                             "homography (as for calibrate)."),
    robot: Optional[Path] = ROBOT_OPTION,
    as_json: bool = JSON_OPTION,
) -> None:
    """Write a self-contained HTML report for a calibration file on a data set or images.

    A paper-model calibration is evaluated on calibration points (a data set, or those its
    images give); an opencv-model one on an image session: its camera, laser plane and
    hand-eye transform held, the board's pose estimated. Either way the verdict the file
    holds is shown first.

    Example: hmlvs report calibration.yaml session.npz --out report.html
    """
    from ..data.calibration_file import Calibration
    from ..report.calibration import write_calibration_report

    with command(as_json) as caught:
        from ..guard import refuse_overwrite

        session = session_of(data)  # a manifest read and checked once
        refuse_overwrite([calibration, *inputs_of(session), test, robot], [("--out", out)])
        cal = Calibration.load(calibration)
        if cal.model == "opencv" and test is not None:
            raise ValueError("--test takes a data set of calibration points, which only "
                             "paper-model calibrations use; this calibration is opencv")
        if cal.model == "paper" and cal.params is None:
            raise ValueError(f"{calibration}: a calibration of the {cal.model} model has no "
                             "paper parameters to report on")
        written = write_calibration_report(
            cal, out, session, test=None if test is None else _dataset(test),
            robot=load_robot(robot), mode=mode)
    result, path = written.result, written.path
    if finish(caught, as_json, {"report": str(path), **result.to_dict()}) is None:
        return
    if cal.model == "opencv":
        typer.echo(f"on {data.name}: corners {result.corner_rms_px:.4g} px RMS, laser "
                   f"{result.laser_rms_mm:.4g} mm RMS over {len(result.per_view)} views "
                   "(camera, laser plane and hand-eye held; the board's pose estimated)")
    else:
        typer.echo(f"RMS on {data.name}: {result.fit_rms:.4g} mm over {len(written.dataset)} "
                   "points")
        if result.test_rms is not None:
            typer.echo(f"RMS on {test.name}: {result.test_rms:.4g} mm over "
                       f"{len(written.test)} points")
    typer.echo(f"report written to {path}")


def _dataset(path: Path) -> Any:
    from ..data.dataset import Dataset

    return Dataset.load(path)
