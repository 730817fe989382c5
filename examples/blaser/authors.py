"""Turn the Blaser authors' own calibration (a MATLAB .mat) into an hmlvs calibration file.

The authors' MATLAB pipeline (unified_proc.m) stores its result as `state`, an 18-vector

    [fx fy cx cy k1 k2 p1 p2 k3 r p w x y z A B D]

- fx, fy, cx, cy: pinhole intrinsics in pixels, with MATLAB's 1-based pixel centres (cx, cy
  are 1 more than OpenCV's 0-based ones);
- k1 k2 p1 p2 k3: Brown-Conrady distortion, OpenCV's order and formula;
- r p w, x y z: hand_from_camera (the camera in the tool0 frame) as R = eul2rotm([w p r]),
  MATLAB's ZYX convention R = Rz(w) Ry(p) Rx(r), and t = [x y z] in metres;
- A B D: the laser plane A x + B y - 100 z + D / 1000 = 0, camera frame, x y z in metres.

The result is an opencv-model hmlvs calibration (hmlvs.OpenCvSensor, lengths in mm, 0-based
pixels, unit plane normal with d < 0), with no base_from_board (the authors' state has none).

    python examples/blaser/authors.py STATE.mat OUT.yaml --resolution 640|1280
    python examples/blaser/authors.py state_finalv2.mat OUT.yaml --git CHECKOUT [--commit C]

With --git, STATE is a path inside commit C (default b68553c) of the Blaser repository's
checkout CHECKOUT, read with `git show C:STATE` (the .mat files are no longer in its tip). The
repository has no licence: write OUT outside this repository.
"""

from __future__ import annotations

import argparse
import datetime
import io
from pathlib import Path
import subprocess
import sys

import hmlvs
from hmlvs import Calibration, OpenCvSensor
import numpy as np
import scipy.io

IMAGE_SIZES: dict[str, tuple[int, int]] = {"640": (640, 480), "1280": (1280, 960)}
DEFAULT_COMMIT = "b68553c"
STATE_LENGTH = 18


def rotation_zyx(w: float, p: float, r: float) -> np.ndarray:
    """MATLAB's eul2rotm([w p r]) (default 'ZYX'): Rz(w) @ Ry(p) @ Rx(r)."""
    cw, sw, cp, sp, cr, sr = np.cos(w), np.sin(w), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    rz = np.array([[cw, -sw, 0.0], [sw, cw, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def state_from_mat(data: bytes, source: str) -> np.ndarray:
    """The 18-vector `state` of a MATLAB v5 .mat file's bytes; a ValueError naming `source`
    when it is not one."""
    try:
        mat = scipy.io.loadmat(io.BytesIO(data))
    except (ValueError, TypeError, OSError, NotImplementedError) as e:
        raise ValueError(f"{source}: not a readable MATLAB .mat file ({e})") from None
    if "state" not in mat:
        keys = ", ".join(k for k in mat if not k.startswith("__")) or "none"
        raise ValueError(f"{source}: no 'state' variable (variables: {keys})")
    state = np.asarray(mat["state"], dtype=float).ravel()
    if state.size != STATE_LENGTH or not np.all(np.isfinite(state)):
        raise ValueError(f"{source}: 'state' must be {STATE_LENGTH} finite numbers, got "
                         f"{state.size}")
    return state


def read_mat_bytes(source: str, checkout: Path | None, commit: str) -> bytes:
    """The .mat file's bytes: a file, or `git show COMMIT:SOURCE` in `checkout`."""
    if checkout is None:
        try:
            return Path(source).read_bytes()
        except OSError as e:
            raise ValueError(f"{source}: cannot read ({e.strerror})") from None
    try:
        done = subprocess.run(["git", "-C", str(checkout), "show", f"{commit}:{source}"],
                              capture_output=True, check=False)
    except OSError as e:
        raise ValueError(f"cannot run git ({e.strerror})") from None
    if done.returncode != 0:
        msg = done.stderr.decode(errors="replace").strip().splitlines()
        raise ValueError(f"git show {commit}:{source} in {checkout} failed: "
                         f"{msg[0] if msg else 'exit ' + str(done.returncode)}")
    return done.stdout


def authors_sensor(state: np.ndarray, image_size: tuple[int, int]) -> OpenCvSensor:
    """The authors' calibration `state` (see the module doc) as an hmlvs OpenCvSensor."""
    s = np.asarray(state, dtype=float).ravel()
    if s.size != STATE_LENGTH:
        raise ValueError(f"state must hold {STATE_LENGTH} numbers, got {s.size}")
    fx, fy, cx, cy = s[0:4]
    camera_matrix = np.array([[fx, 0.0, cx - 1.0], [0.0, fy, cy - 1.0], [0.0, 0.0, 1.0]])
    r, p, w = s[9:12]
    hand_from_camera = np.eye(4)
    hand_from_camera[:3, :3] = rotation_zyx(w, p, r)
    hand_from_camera[:3, 3] = 1000.0 * s[12:15]  # m -> mm
    # A x + B y - 100 z + D/1000 = 0 (m)  ==  A x + B y - 100 z + D = 0 (mm); the sensor
    # normalises the normal and turns it so that d < 0
    plane = np.array([s[15], s[16], -100.0, s[17]])
    return OpenCvSensor(camera_matrix=camera_matrix, dist_coeffs=s[4:9], image_size=image_size,
                        laser_plane=plane, hand_from_camera=hand_from_camera)


def authors_calibration(state: np.ndarray, image_size: tuple[int, int],
                        source: str) -> Calibration:
    """An opencv-model Calibration holding the authors' sensor, with its provenance."""
    return Calibration(params=None, sensor=authors_sensor(state, image_size), model="opencv",
                       method=f"authors (Blaser unified_proc.m state, {source})",
                       created=datetime.datetime.now(datetime.timezone.utc).isoformat(
                           timespec="seconds"),
                       hmlvs_version=hmlvs.__version__)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("state", help="the authors' .mat file (with --git: its path in the commit)")
    ap.add_argument("out", type=Path, help="the hmlvs calibration file to write (.yaml/.json)")
    ap.add_argument("--resolution", choices=sorted(IMAGE_SIZES), default="640",
                    help="the images' size: 640 (640x480) or 1280 (1280x960)")
    ap.add_argument("--git", type=Path, metavar="CHECKOUT",
                    help="read STATE from a commit of this git checkout")
    ap.add_argument("--commit", default=DEFAULT_COMMIT,
                    help=f"the commit holding the .mat files (default {DEFAULT_COMMIT})")
    a = ap.parse_args(argv)
    if a.out.suffix not in (".yaml", ".yml", ".json"):
        print(f"error: {a.out}: a calibration file ends in .yaml, .yml or .json",
              file=sys.stderr)
        return 2
    source = a.state if a.git is None else f"{a.commit}:{a.state}"
    try:
        state = state_from_mat(read_mat_bytes(a.state, a.git, a.commit), source)
        cal = authors_calibration(state, IMAGE_SIZES[a.resolution], Path(a.state).name)
        path = cal.save(a.out)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"calibration written: {path}")
    print(cal.table())
    return 0


if __name__ == "__main__":
    sys.exit(main())
