"""Turn a checkout of the public hjamal3/Light-Stripe-Calibration repository into an hmlvs
bench session.

A third real sensor, taken on a bench rather than on a robot: a 640 x 480 colour camera (JPEG)
with a strongly distorting lens and a **green** line laser whose stripe runs **down** the
image, and a checkerboard (6 x 8 inner corners, 40 mm squares) held by hand in front of it.
Six laser-on frames `images/N_right.jpg`, no laser-off frames and no poses: hmlvs calibrates
the camera and the laser plane (camera mode), the hand-eye being for a later robot session.

    python examples/light_stripe/make_session.py CHECKOUT OUT

OUT (a new folder) receives `manifest.yaml` and `images/`. The repository holds no licence
file: keep its images and anything derived from them out of this repository.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import shutil
import sys

import yaml

BOARD = {"type": "checkerboard", "rows": 6, "cols": 8, "square": 40.0}


def make_session(checkout: Path, out: Path) -> Path:
    """Write OUT/manifest.yaml and OUT/images/ (every frame, in number order); its path."""
    frames = sorted((checkout / "images").glob("*_right.jpg"),
                    key=lambda p: (len(p.stem), p.stem))
    if not frames:
        raise ValueError(f"{checkout / 'images'}: no N_right.jpg frames")
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} is not empty: give a new folder")
    (out / "images").mkdir(parents=True, exist_ok=True)
    entries = []
    for f in frames:
        shutil.copyfile(f, out / "images" / f.name)
        entries.append({"id": f.stem, "on": f"images/{f.name}"})
    manifest = {"format": "hmlvs-images", "version": 1, "board": dict(BOARD),
                "poses": entries}
    path = out / "manifest.yaml"
    path.write_text(yaml.safe_dump(manifest, sort_keys=False, default_flow_style=None))
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkout", type=Path, help="a checkout of Light-Stripe-Calibration")
    ap.add_argument("out", type=Path, help="a new folder for the session")
    a = ap.parse_args(argv)
    try:
        path = make_session(a.checkout, a.out)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"session written: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
