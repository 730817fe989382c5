"""hmlvs report: a calibration file evaluated on a data set or an image session, as HTML."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer

from .common import app, command, finish, inputs_of, is_manifest, load_robot
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
    hand-eye transform held, the board's pose estimated, its verdict shown first.

    Example: hmlvs report calibration.yaml session.npz --out report.html
    """
    from ..calibration.solvers import evaluate
    from ..data.calibration_file import Calibration
    from ..data.dataset import Dataset
    from ..report.html import write_report

    with command(as_json) as caught:
        from ..guard import refuse_overwrite

        refuse_overwrite([calibration, *inputs_of(data), test, robot], [("--out", out)])
        cal = Calibration.load(calibration)
        if cal.model == "opencv":
            if test is not None:
                raise ValueError("--test takes a data set of calibration points, which only "
                                 "paper-model calibrations use; this calibration is opencv")
            path, ev = _report_opencv(cal, data, out, robot)
    if cal.model == "opencv":
        if finish(caught, as_json, {"report": str(path), **ev.to_dict()}) is None:
            return
        typer.echo(f"on {data.name}: corners {ev.corner_rms_px:.4g} px RMS, laser "
                   f"{ev.laser_rms_mm:.4g} mm RMS over {len(ev.per_view)} views (camera, "
                   "laser plane and hand-eye held; the board's pose estimated)")
        typer.echo(f"report written to {path}")
        return
    with command(as_json) as caught:
        image_reports = None
        if is_manifest(data):
            from ..image.paper_session import dataset_from_images

            ds, image_reports = dataset_from_images(data, mode=mode, robot=load_robot(robot))
        else:
            ds = Dataset.load(data)
        test_ds = Dataset.load(test) if test is not None else None
        if cal.params is None:
            raise ValueError(f"{calibration}: a calibration of the {cal.model} model has no "
                             "paper parameters to report on")
        result = evaluate(cal.params, ds, test_ds, method=cal.method or "loaded",
                          fixed=cal.fixed)
        path = write_report(result, ds, out, test=test_ds, std=cal.std,
                            image_reports=image_reports)
    if finish(caught, as_json, {"report": str(path), **result.to_dict()}) is None:
        return
    typer.echo(f"RMS on {data.name}: {result.fit_rms:.4g} mm over {len(ds)} points")
    if result.test_rms is not None:
        typer.echo(f"RMS on {test.name}: {result.test_rms:.4g} mm over {len(test_ds)} points")
    typer.echo(f"report written to {path}")


def _report_opencv(cal: Any, data: Path, out: Path, robot: Optional[Path]) -> tuple[Path, Any]:
    """hmlvs report for an opencv-model calibration: the calibration on the session's images
    (camera, laser plane and hand-eye held; the board's pose estimated), its verdict first."""
    from ..calibration.joint import evaluate_sensor
    from ..diagnostics.verdict import Verdict
    from ..image.views import views_from_images
    from ..report.joint import write_joint_report

    if not is_manifest(data):
        raise ValueError(f"{data}: an opencv-model calibration is reported on an image session "
                         "(a folder with manifest.json/yaml, or the manifest file)")
    views, board, size, _, reports = views_from_images(data, robot=load_robot(robot))
    if not views:
        raise ValueError(f"{data}: no view has a detected board and a stripe")
    result = evaluate_sensor(cal.sensor, views, board, size, std=cal.std)
    verdict = Verdict.from_dict(cal.verdict) if cal.verdict else None
    return write_joint_report(result, out, image_reports=reports, verdict=verdict), result
