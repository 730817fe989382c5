"""Turn a calibration folder of the public openlmd/etna repository into an hmlvs session.

A second real sensor, unlike the Blaser one in every way hmlvs was not tuned on: a 1280 x
1024 grey camera (frames stored as three equal channels) with a red line laser on an ABB
arm's flange, a **near-vertical stripe** that falls on the plate beside the checkerboard
(7 x 6 inner corners, 10 mm squares) rather than across it, laser-on frames only. Each frame
`frameNNNN.png` has its pose `poseNNNN.txt`, one line written by ROS tf:
`((x, y, z), (qx, qy, qz, qw))`, tool0 in the base, metres. Files named with a leading
underscore are the authors' discards and are left out; frames are paired with poses by
number (not by sorted position: some folders lack a pose or a frame).

    python examples/etna/make_session.py CHECKOUT/etna_calib/data/calib3 OUT

OUT (a new folder) receives `manifest.yaml` and `images/`. The repository's package files
declare a BSD licence but it holds no licence file: keep its images and anything derived
from them out of this repository, as with the Blaser data.
"""
from __future__ import annotations

import argparse
import ast
from pathlib import Path
import shutil
import sys

import yaml

BOARD = {"type": "checkerboard", "rows": 6, "cols": 7, "square": 10.0}


def read_pose(path: Path) -> tuple[list[float], list[float]]:
    """(position [m], quaternion xyzw) of one pose file."""
    try:
        p, q = ast.literal_eval(path.read_text().strip())
    except (ValueError, SyntaxError, TypeError) as e:
        raise ValueError(f"{path}: not ((x, y, z), (qx, qy, qz, qw)) ({e})") from None
    if len(p) != 3 or len(q) != 4:
        raise ValueError(f"{path}: a position needs 3 numbers and a quaternion 4")
    return [float(x) for x in p], [float(x) for x in q]


def make_session(folder: Path, out: Path) -> tuple[Path, list[str]]:
    """Write OUT/manifest.yaml and OUT/images/; (the manifest's path, frames without a pose)."""
    frames = sorted(folder.glob("frame[0-9]*.png"))
    if not frames:
        raise ValueError(f"{folder}: no frameNNNN.png files")
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} is not empty: give a new folder")
    entries, unposed = [], []
    for f in frames:  # every pose read before anything is written
        pose_file = folder / f"pose{f.stem[len('frame'):]}.txt"
        if not pose_file.is_file():
            unposed.append(f.name)
            continue
        pos, quat = read_pose(pose_file)
        entries.append({"id": f.stem, "on": f"images/{f.name}",
                        "pose": {"position": pos, "quaternion": quat}})
    if not entries:
        raise ValueError(f"{folder}: no frame has its pose file")
    (out / "images").mkdir(parents=True, exist_ok=True)
    for e in entries:
        shutil.copyfile(folder / Path(e["on"]).name, out / e["on"])
    manifest = {"format": "hmlvs-images", "version": 1,
                "pose_format": {"unit": "m", "quaternion_order": "xyzw"},
                "board": dict(BOARD), "poses": entries}
    path = out / "manifest.yaml"
    path.write_text(yaml.safe_dump(manifest, sort_keys=False, default_flow_style=None))
    return path, unposed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path, help="a calibN folder of etna_calib/data")
    ap.add_argument("out", type=Path, help="a new folder for the session")
    a = ap.parse_args(argv)
    try:
        path, unposed = make_session(a.folder, a.out)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for name in unposed:
        print(f"{name}: no pose file, left out")
    print(f"session written: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
