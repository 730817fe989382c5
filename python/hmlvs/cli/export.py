"""hmlvs export: a calibration file in another tool's format."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .common import app, collect_warnings, gather, guard, show_warnings

# -- end hmlvs inspect -----------------------------------------------------------------------


@app.command("export")
def export_calibration(
    calibration: Path = typer.Argument(..., help="Calibration file (.yaml or .json)."),
    fmt: str = typer.Option(..., "--format", "-f", help="opencv (cv::FileStorage YAML), ros "
                            "(camera_info YAML) or json."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="File to write (atomically); "
                                       "default: print to stdout."),
    image_size: Optional[tuple[int, int]] = typer.Option(
        None, "--image-size", help="Image width and height (px) for a paper-model "
        "calibration's distortion fit; default 2 Cu x 2 Cv."),
    camera_name: str = typer.Option("hmlvs_camera", help="camera_name of the ros format."),
) -> None:
    """Export a calibration for OpenCV (YAML), ROS (camera_info) or any JSON reader.

    The camera, the laser plane and the hand-eye transform; a paper-model calibration is
    converted to OpenCV's camera model.

    Example: hmlvs export calibration.yaml --format ros --out camera_info.yaml
    """
    from ..data.export import export, export_text

    with guard(), collect_warnings() as caught:
        from ..guard import refuse_overwrite

        refuse_overwrite([calibration], [("--out", out)])
        if out is None:
            text = export_text(calibration, fmt, image_size=image_size,
                               camera_name=camera_name)
        else:
            path = export(calibration, fmt, out, image_size=image_size,
                          camera_name=camera_name)
    show_warnings(gather(caught))  # on stderr: stdout may be the export itself
    if out is None:
        typer.echo(text, nl=False)
    else:
        typer.echo(f"{fmt} export written to {path}")
