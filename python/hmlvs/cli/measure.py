"""hmlvs measure: stripe pixels (or images) and poses -> a point cloud."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .common import app, bar, command, finish, inputs_of, is_manifest, load_robot, session_of
from .options import FRAME_OPTION, JSON_OPTION, ROBOT_OPTION, out_option


@app.command()
def measure(
    calibration: Path = typer.Argument(..., help="Calibration file (.yaml or .json)."),
    source: Path = typer.Argument(..., help="A data set (.npz/.json) of stripe pixels and poses, "
                                  "or an image manifest (folder or manifest.json)."),
    out: Path = out_option("cloud.ply", "Point cloud to write (.ply or .csv)."),
    robot: Optional[Path] = ROBOT_OPTION,
    as_json: bool = JSON_OPTION,
    accept_untrusted: bool = typer.Option(
        False, "--accept-untrusted", help="Measure even with a calibration whose verdict "
        "says not to trust it."),
    frame: str = FRAME_OPTION,
) -> None:
    """Measure 3D points in the robot base frame (or the camera frame) with a calibrated
    sensor.

    A calibration marked not trustworthy (its verdict) is refused unless --accept-untrusted.

    Example: hmlvs measure calibration.yaml scan/ --out cloud.ply
    """
    import numpy as np

    from ..data.calibration_file import Calibration
    from ..data.dataset import Dataset
    from ..measurement.measure import checked_frame, measure_images_to
    from ..measurement.measure import measure as measure_points

    with command(as_json) as caught:
        from ..guard import refuse_overwrite

        try:
            checked_frame(frame)
        except ValueError:
            raise ValueError(f"--frame must be base or camera, got {frame!r}") from None
        source = session_of(source)  # a manifest read and checked once
        refuse_overwrite([calibration, *inputs_of(source), robot], [("--out", out)])
        cal = Calibration.load(calibration)
        if cal.trustworthy is False and not accept_untrusted:
            first = (cal.verdict or {}).get("reasons") or ["no reason recorded"]
            raise ValueError(f"{calibration} is marked not trustworthy ({first[0]}); "
                             "calibrate again, or pass --accept-untrusted to measure with it "
                             "anyway")
        if out.suffix not in (".ply", ".csv"):
            raise ValueError(f"--out {out}: point clouds are written as .ply or .csv")
        if is_manifest(source):
            # frame by frame into the cloud file: the memory of one frame, whatever the scan
            streamed = measure_images_to(cal, source, out, robot=load_robot(robot),
                                         image_size_of=f"the calibration {calibration}",
                                         progress=bar("measuring frames", as_json),
                                         frame=frame)
            path, n_valid, n_invalid = streamed.path, streamed.points, streamed.invalid
            info = {**streamed.summary(), "blur_var_px2": cal.blur_var}
        else:
            ds = Dataset.load(source)
            cloud = measure_points(cal, [ds.pixels[i:i + 1] for i in range(len(ds))],
                                   ds.poses if frame == "base" else None, frame=frame)
            # the data set's reference points are in the robot base frame
            err = np.linalg.norm(cloud.points - ds.points, axis=1)[cloud.valid]
            info = {"rms_mm": float(np.sqrt(np.mean(err**2)))
                    if err.size and frame == "base" else None}
            if cloud.num_valid == 0:
                raise ValueError(f"none of the {len(cloud)} stripe pixels' rays meets the laser "
                                 f"plane of {calibration}: nothing to write (is this "
                                 "calibration of the sensor that took these data?)")
            path = cloud.save(out)
            n_valid, n_invalid = cloud.num_valid, len(cloud) - cloud.num_valid
    if finish(caught, as_json, {"cloud": str(path), "points": n_valid, "invalid": n_invalid,
                                "frame": frame, **info}) is None:
        return
    where = "in the robot base frame" if frame == "base" else "in the camera frame"
    typer.echo(f"{n_valid} points measured {where} ({n_invalid} stripe "
               "pixels without a measurement: their rays miss the laser plane, meet it at a "
               "grazing angle or lie outside the image)")
    for pid, why in (info.get("rejected") or {}).items():
        typer.echo(f"{pid}: rejected: {why}")
    if info.get("blur_var_px2") is not None:
        typer.echo(f"stripes corrected at albedo steps for the camera blur the calibration "
                   f"fitted ({info['blur_var_px2']:.3g} px^2)")
    if info.get("rms_mm") is not None:
        typer.echo(f"RMS distance to the reference points: {info['rms_mm']:.4g} mm")
    typer.echo(f"point cloud written to {path}")
