"""hmlvs simulate: a simulated calibration session (data set, optionally images)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .common import MOUNTING_DEG, app, bar, command, finish, mounted_truth
from .options import JSON_OPTION


@app.command()
def simulate(
    out: Path = typer.Argument(..., help="Data set file to write (.npz or .json)."),
    poses: int = typer.Option(30, help="Number of robot poses in the session."),
    pixel_noise: float = typer.Option(
        0.0, help="Noise added to the stripe pixels of the data set, standard deviation (px). "
        "It does not apply to rendered images (--images): they carry --image-noise instead, "
        "and the pixels extracted from them have the extractor's own error."),
    point_noise: float = typer.Option(0.0, help="Reference-point noise, std (mm)."),
    images: Optional[Path] = typer.Option(
        None, help="Also render laser on/off images of every pose into this folder, with a "
        "manifest.json pairing each image pair with its joint readings."),
    image_noise: float = typer.Option(
        0.0, help="Sensor noise of the rendered images, standard deviation (grey levels of "
        "0-255; default 0: noise-free images)."),
    mounting: tuple[float, float, float] = typer.Option(
        MOUNTING_DEG, help="The true hand-eye rotation as ZYZ Euler angles omega phi varphi "
        "(deg); the rest of the true sensor is the paper's nominal (Table 2)."),
    seed: int = typer.Option(0, help="Random seed."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar and no warnings "
                               "on the terminal (--json collects them)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Simulate a checkerboard calibration session (SCORBOT ER-VII, paper set-up).

    Example: hmlvs simulate session.npz --poses 60 --images session
    """
    from .. import sim
    from ..sim.render import RenderOptions

    with command(as_json) as caught:
        # every refusal before anything is written
        if out.suffix not in (".npz", ".json"):  # as Dataset.save, before any image is made
            raise ValueError(f"{out}: data sets are saved as .npz or .json, not "
                             f"{out.suffix or 'a file without a suffix'}")
        if images is not None and images.is_dir() and any(images.iterdir()):
            raise ValueError(f"--images {images}: the folder exists and is not empty; its "
                             "manifest and images would be replaced: give a new or empty folder")
        s = sim.session(mounted_truth(mounting), num_poses=poses, pixel_noise=pixel_noise,
                        point_noise=point_noise, seed=seed)
        manifest = None
        new_folder = images is not None and not images.exists()
        if images is not None:  # the images first: an interrupted run leaves neither output
            manifest = sim.render_session(
                s, images, options=RenderOptions(noise=image_noise), seed=seed,
                progress=bar(f"rendering {poses} image pairs", as_json or quiet)).manifest
        try:
            s.dataset.save(out)
        except BaseException:
            if new_folder and images is not None:
                import shutil

                shutil.rmtree(images, ignore_errors=True)
            raise
    if finish(caught, as_json, {"file": str(out), "points": len(s.dataset),
                                "poses": s.dataset.num_poses,
                                "manifest": None if manifest is None else str(manifest)},
              quiet=quiet) is None:
        return
    typer.echo(s.summary())
    typer.echo(f"written to {out}" + (f" and {manifest}" if manifest else ""))
