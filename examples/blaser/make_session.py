"""Turn a checkout of the public Blaser calibration data into an hmlvs session.

An example of bringing one's own data to hmlvs: a folder of laser-on images taken by a sensor
on a UR5e, and the controller's poses (tool0 in the base: position in metres, quaternion
x, y, z, w), three lines per image in `data.txt`:

    [x, y, z]
    [qx, qy, qz, qw]
    im0.png

become `manifest.yaml` (board, pose format, one entry per image) beside an `images/` folder
holding a copy of each image. Nothing here is specific to hmlvs' internals: the manifest is
the documented format (docs/file-formats.md), so the same few lines serve any robot that logs
its poses beside its images.

    python examples/blaser/make_session.py CHECKOUT OUT [--resolution 640|1280]

CHECKOUT is a checkout (work tree) of the Blaser repository; it has no licence, so neither its
images nor anything derived from them belong in this repository: OUT is a folder of your own.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path
import shutil
import sys

import yaml

# The printed board: 10 x 7 squares of 5 mm (9 x 6 inner corners) on a larger white sheet.
BOARD = {"type": "checkerboard", "rows": 6, "cols": 9, "square": 5.0}
FOLDERS = {"640": "640_unified", "1280": "1280_unified"}


def read_data_txt(path: Path) -> list[tuple[str, list[float], list[float]]]:
    """(image name, position [m], quaternion xyzw) per image, in the file's order."""
    lines = [ln.strip() for ln in path.read_text().splitlines() if ln.strip()]
    if len(lines) % 3:
        raise ValueError(f"{path}: {len(lines)} non-empty lines, not three per image")
    out = []
    for k in range(0, len(lines), 3):
        pos, quat, name = lines[k], lines[k + 1], lines[k + 2]
        try:
            p, q = ast.literal_eval(pos), ast.literal_eval(quat)
        except (ValueError, SyntaxError) as e:
            raise ValueError(f"{path}: line {k + 1}: not a list of numbers ({e})") from None
        if len(p) != 3 or len(q) != 4:
            raise ValueError(f"{path}: image {name}: a position needs 3 numbers and a "
                             "quaternion 4")
        out.append((name, [float(x) for x in p], [float(x) for x in q]))
    return out


def make_session(checkout: Path, out: Path, resolution: str = "640") -> Path:
    """Write OUT/manifest.yaml and OUT/images/; returns the manifest's path."""
    src = checkout / "blaser_data" / FOLDERS[resolution]
    data = read_data_txt(src / "data.txt")
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} is not empty: give a new folder")
    (out / "images").mkdir(parents=True, exist_ok=True)
    entries = []
    for name, pos, quat in data:
        shutil.copyfile(src / name, out / "images" / name)
        entries.append({"id": Path(name).stem, "on": f"images/{name}",
                        "pose": {"position": pos, "quaternion": quat}})
    manifest = {"format": "hmlvs-images", "version": 1,
                "pose_format": {"unit": "m", "quaternion_order": "xyzw"},
                "board": dict(BOARD), "poses": entries}
    path = out / "manifest.yaml"
    path.write_text(yaml.safe_dump(manifest, sort_keys=False, default_flow_style=None))
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkout", type=Path, help="a checkout of the Blaser repository")
    ap.add_argument("out", type=Path, help="a new folder for the session")
    ap.add_argument("--resolution", choices=sorted(FOLDERS), default="640")
    a = ap.parse_args(argv)
    try:
        path = make_session(a.checkout, a.out, a.resolution)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"session written: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
