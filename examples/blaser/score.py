"""Score hmlvs calibration files on a Blaser session: stripe planarity and chain reprojection.

    python examples/blaser/score.py SESSION CAL [CAL ...] [--names N ...] [--json]

SESSION is a folder written by make_session.py (manifest.yaml + images/, base_from_hand
poses); each CAL is an hmlvs calibration file of either model, or one of the Blaser authors'
.mat files (converted by authors.py for the session's image size). Two measures, both
independent of how (and by what) the calibration was made:

- planarity (mm): the board and its sheet do not move, so every stripe point of every view
  (board frames and laser-only frames alike), mapped pixel -> ray -> laser plane ->
  hand_from_camera -> base_from_hand by the calibration (hmlvs.measure), must lie on one
  plane: the RMS distance of all of them to their least-squares (SVD) plane, and per view.
- chain reprojection (px): on the frames where all the board's inner corners are found, each
  view's board pose from cv2.solvePnP (the calibration's intrinsics) is carried to the base
  (base_from_hand @ hand_from_camera @ camera_from_board); the poses are averaged into one
  (chordal mean of the rotations, mean of the translations), and the corners reprojected
  through it, each view's robot pose, hand_from_camera and the camera model: the RMS pixel
  distance to the detected corners over all views.

The stripe pixels come from stripe_extractor.py, which knows nothing of any calibration nor of
hmlvs' own extractor; they (and the board corners) are cached per session in --cache-dir
(default: a folder in the system's temporary directory), never in the session folder, so
every calibration scored on a session sees the same pixels.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import hashlib
import json
import math
import os
from pathlib import Path
import sys
import tempfile
from typing import Any

import cv2
import hmlvs
from hmlvs import Calibration, OpenCvSensor
from hmlvs.data.export import sensor_of
from hmlvs.data.manifest import read_manifest
import numpy as np
from stripe_extractor import extract_stripe

# Bump when the extractor or the corner detection changes: it names the cache entries.
EXTRACTOR_VERSION = "blaser-score-2"



@dataclass(frozen=True)
class View:
    """One image of the session and the robot's pose when it was taken."""

    id: str
    image: Path
    base_from_hand: np.ndarray  # 4x4, mm


@dataclass(frozen=True)
class Board:
    """A checkerboard: rows x cols inner corners, square in mm."""

    rows: int
    cols: int
    square: float

    @property
    def pattern(self) -> tuple[int, int]:
        """OpenCV's patternSize: (corners per row, corners per column)."""
        return (self.cols, self.rows)

    def object_points(self) -> np.ndarray:
        """The inner corners in the board frame (mm), OpenCV's order (row by row)."""
        r, c = np.mgrid[0:self.rows, 0:self.cols]
        return np.c_[c.ravel() * self.square, r.ravel() * self.square,
                     np.zeros(self.rows * self.cols)]


@dataclass
class Session:
    """A session's views with the calibration-free measurements of its images."""

    folder: Path
    views: list[View]
    board: Board
    image_size: tuple[int, int]
    stripes: dict[str, np.ndarray] = field(default_factory=dict)  # id -> (k, 2) pixels
    corners: dict[str, np.ndarray] = field(default_factory=dict)  # id -> (n, 2), board views

    @property
    def num_stripe_points(self) -> int:
        return int(sum(s.shape[0] for s in self.stripes.values()))


class InputError(ValueError):
    """Bad input (session, calibration, arguments): reported in one line, exit status 2."""


# ------------------------------------------------------------------ session

def read_views(folder: Path) -> tuple[list[View], Board]:
    """The session's views (image, base_from_hand in mm) and its board."""
    try:
        entries, doc, base = read_manifest(folder)
    except ValueError as e:
        raise InputError(str(e)) from None
    spec = doc.get("board")
    if not isinstance(spec, dict) or not all(k in spec for k in ("rows", "cols", "square")):
        raise InputError(f"{folder}: the manifest has no board (rows, cols, square)")
    board = Board(int(spec["rows"]), int(spec["cols"]), float(spec["square"]))
    views = []
    for e in entries:
        if "on" not in e:
            raise InputError(f"{folder}: entry {e['id']} has no laser-on image ('on')")
        if "pose" not in e:
            raise InputError(f"{folder}: entry {e['id']} has joint readings, not a pose: this "
                             "scorer needs base_from_hand poses")
        views.append(View(str(e["id"]), base / str(e["on"]), np.asarray(e["pose"], float)))
    if not views:
        raise InputError(f"{folder}: the manifest lists no images")
    return views, board


def read_image(path: Path) -> np.ndarray:
    """A colour image (BGR, uint8); an InputError naming it if it cannot be read."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise InputError(f"{path}: missing or not an image")
    return img


# ------------------------------------------------------------------ stripe extractor

def detect_corners(gray: np.ndarray, board: Board) -> np.ndarray | None:
    """All inner corners (n, 2) by cv2.findChessboardCornersSB, else cv2.findChessboardCorners
    + cornerSubPix; None when either misses any."""
    ok, found = cv2.findChessboardCornersSB(gray, board.pattern, flags=cv2.CALIB_CB_EXHAUSTIVE
                                            | cv2.CALIB_CB_ACCURACY)
    if ok:
        return found.reshape(-1, 2).astype(float)
    ok, found = cv2.findChessboardCorners(gray, board.pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                          | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    win = max(3, int(round(5 * gray.shape[1] / 640.0)))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    found = cv2.cornerSubPix(gray, found, (win, win), (-1, -1), criteria)
    return found.reshape(-1, 2).astype(float)


# ------------------------------------------------------------------ cache

def cache_key(views: list[View], board: Board) -> str:
    """Names the measurements of these images: the extractor's version, the board and every
    image's path, size and modification time."""
    h = hashlib.sha256(f"{EXTRACTOR_VERSION}|{board}".encode())
    for v in views:
        try:
            st = v.image.stat()
        except OSError as e:
            raise InputError(f"{v.image}: cannot read ({e.strerror})") from None
        h.update(f"|{v.id}|{v.image.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()[:20]


def load_cache(path: Path, session: Session) -> bool:
    """Fill the session's stripes and corners from a cache file; False if there is none."""
    try:
        with np.load(path, allow_pickle=False) as z:
            ids = [str(i) for i in z["ids"]]
            if ids != [v.id for v in session.views]:
                return False
            px, index = z["stripe_pixels"], z["stripe_view"]
            session.stripes = {vid: px[index == k] for k, vid in enumerate(ids)}
            session.corners = {ids[k]: c for k, c in zip(z["corner_view"], z["corners"])}
            return True
    except (OSError, KeyError, ValueError):
        return False


def save_cache(path: Path, session: Session) -> None:
    """Write the session's stripes and corners atomically (best effort: a failure only
    costs the next run the extraction)."""
    ids = [v.id for v in session.views]
    px = np.vstack([session.stripes[i] for i in ids] + [np.empty((0, 2))])
    index = np.concatenate([np.full(session.stripes[i].shape[0], k) for k, i in enumerate(ids)]
                           + [np.empty(0, int)]).astype(int)
    board_ids = [k for k, i in enumerate(ids) if i in session.corners]
    n = session.board.rows * session.board.cols
    corners = np.array([session.corners[ids[k]] for k in board_ids]).reshape(-1, n, 2)
    tmp: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, ids=np.array(ids), stripe_pixels=px, stripe_view=index,
                     corner_view=np.array(board_ids, dtype=int), corners=corners)
        os.replace(tmp, path)
    except OSError as e:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        print(f"warning: cannot write the cache {path} ({e.strerror})", file=sys.stderr)


def measure_images(session: Session) -> None:
    """Extract every view's stripe and board corners."""
    for v in session.views:
        img = read_image(v.image)
        h, w = img.shape[:2]
        if (w, h) != session.image_size:
            raise InputError(f"{v.image}: {w} x {h} pixels, but the session's first image is "
                             f"{session.image_size[0]} x {session.image_size[1]}")
        session.stripes[v.id] = extract_stripe(img)
        corners = detect_corners(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), session.board)
        if corners is not None:
            session.corners[v.id] = corners


def load_session(folder: Path, cache_dir: Path | None) -> Session:
    """The session with its stripes and corners, from the cache when it has them."""
    views, board = read_views(folder)
    h, w = read_image(views[0].image).shape[:2]
    session = Session(folder, views, board, (w, h))
    cache = None if cache_dir is None else \
        cache_dir / f"{folder.resolve().name}-{cache_key(views, board)}.npz"
    if cache is not None and load_cache(cache, session):
        return session
    measure_images(session)
    if cache is not None:
        save_cache(cache, session)
    return session


# ------------------------------------------------------------------ planarity

@dataclass(frozen=True)
class Planarity:
    rms_mm: float
    num_points: int  # mapped (valid) points
    per_view_mm: dict[str, float]  # RMS distance to the common plane; NaN without points
    per_view_points: dict[str, int]


def plane_distances(points: np.ndarray) -> np.ndarray:
    """Signed distances of points to their least-squares plane (through the centroid, normal
    the direction of least spread: the last right singular vector)."""
    centred = points - points.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    return centred @ normal


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def planarity(cal: Calibration, session: Session) -> Planarity:
    """All views' stripe points in the base by the calibration; their scatter about one plane."""
    ids = [v.id for v in session.views]
    poses = np.array([v.base_from_hand for v in session.views])
    cloud = hmlvs.measure(cal, [session.stripes[i] for i in ids], poses=poses,
                          on_invalid="mask")
    valid = cloud.valid
    if valid.sum() < 3:
        raise InputError("fewer than 3 stripe pixels map to the laser plane with this "
                         "calibration")
    dist = plane_distances(cloud.points[valid])
    view = cloud.pose_index[valid]
    per_view = {vid: rms(dist[view == k]) for k, vid in enumerate(ids)}
    counts = {vid: int((view == k).sum()) for k, vid in enumerate(ids)}
    return Planarity(rms(dist), int(valid.sum()), per_view, counts)


# ------------------------------------------------------------------ chain reprojection

@dataclass(frozen=True)
class Chain:
    rms_px: float
    per_view_px: dict[str, float]
    flipped: list[str]  # views whose corner numbering was turned by 180 degrees
    behind: int  # reprojected corners behind the camera (the chain is then meaningless)


def transform(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = cv2.Rodrigues(rvec)[0]
    t[:3, 3] = np.ravel(tvec)
    return t


def camera_from_board(sensor: OpenCvSensor, obj: np.ndarray, corners: np.ndarray
                      ) -> np.ndarray:
    """The board's pose in the camera from its corners (cv2.solvePnP, the sensor's camera)."""
    ok, rvec, tvec = cv2.solvePnP(obj, corners, sensor.camera_matrix, sensor.dist_coeffs,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise InputError("cv2.solvePnP failed on a board view")
    return transform(rvec, tvec)


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (rad) of the rotation between two rotation matrices."""
    c = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.acos(max(-1.0, min(1.0, c)))


def chordal_mean(rotations: list[np.ndarray]) -> np.ndarray:
    """The rotation nearest (Frobenius) to the rotations' sum: their chordal L2 mean."""
    u, _, vt = np.linalg.svd(np.sum(rotations, axis=0))
    d = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(u @ vt)))])
    return u @ d @ vt


def mean_pose(poses: list[np.ndarray]) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = chordal_mean([p[:3, :3] for p in poses])
    t[:3, 3] = np.mean([p[:3, 3] for p in poses], axis=0)
    return t


def consistent_numbering(options: list[tuple[np.ndarray, np.ndarray]]) -> list[int]:
    """Per view, which of its two board-in-base poses (as numbered, turned 180 degrees) to
    use: seeded by the pose closest, in rotation, to the other views' (the median angle to
    their nearer option), then each view takes the option nearer the mean, until stable."""
    candidates = [p for pair in options for p in pair]

    def spread(c: np.ndarray) -> float:
        return float(np.median([min(rotation_angle(c[:3, :3], p[:3, :3]) for p in pair)
                                for pair in options]))

    reference = min(candidates, key=spread)
    choice: list[int] = []
    for _ in range(20):
        new = [int(rotation_angle(b[:3, :3], reference[:3, :3])
                   < rotation_angle(a[:3, :3], reference[:3, :3])) for a, b in options]
        if new == choice:
            break
        choice = new
        reference = mean_pose([pair[k] for pair, k in zip(options, choice)])
    return choice


def chain_reprojection(sensor: OpenCvSensor, session: Session) -> Chain | None:
    """The board corners reprojected through one board pose in the base (see module doc);
    None without board views."""
    views = [v for v in session.views if v.id in session.corners]
    if not views:
        return None
    obj = session.board.object_points()
    hfc = sensor.hand_from_camera
    # the corners as found, and numbered from the opposite corner (the board turned 180 deg)
    numbered = [(session.corners[v.id], session.corners[v.id][::-1]) for v in views]
    options = [(v.base_from_hand @ hfc @ camera_from_board(sensor, obj, a),
                v.base_from_hand @ hfc @ camera_from_board(sensor, obj, b))
               for v, (a, b) in zip(views, numbered)]
    choice = consistent_numbering(options)
    base_from_board = mean_pose([pair[k] for pair, k in zip(options, choice)])
    camera_from_hand = np.linalg.inv(hfc)
    errors, per_view, behind = [], {}, 0
    for v, pair, k in zip(views, numbered, choice):
        cfb = camera_from_hand @ np.linalg.inv(v.base_from_hand) @ base_from_board
        behind += int(np.sum((obj @ cfb[:3, :3].T + cfb[:3, 3])[:, 2] <= 0))
        rvec = cv2.Rodrigues(cfb[:3, :3])[0]
        px = cv2.projectPoints(obj, rvec, cfb[:3, 3], sensor.camera_matrix,
                               sensor.dist_coeffs)[0].reshape(-1, 2)
        d = np.linalg.norm(px - pair[k], axis=1)
        errors.append(d)
        per_view[v.id] = rms(d)
    flipped = [v.id for v, k in zip(views, choice) if k]
    return Chain(rms(np.concatenate(errors)), per_view, flipped, behind)


# ------------------------------------------------------------------ scoring

@dataclass(frozen=True)
class Score:
    name: str
    path: str
    model: str
    planarity: Planarity
    chain: Chain | None


def authors_mat(path: Path, image_size: tuple[int, int]) -> Calibration:
    """The Blaser authors' .mat calibration (authors.py, beside this script), for images of
    the session's size."""
    from authors import authors_calibration, state_from_mat

    try:
        data = path.read_bytes()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    return authors_calibration(state_from_mat(data, str(path)), image_size, path.name)


def load_cal(path: Path, image_size: tuple[int, int]) -> tuple[Calibration, OpenCvSensor]:
    """The calibration and its camera (a paper model's by hmlvs.data.export.sensor_of). A
    .mat file is taken for the Blaser authors' calibration (authors.authors_sensor)."""
    try:
        if path.suffix.lower() == ".mat":
            cal = authors_mat(path, image_size)
        else:
            cal = hmlvs.data.calibration_file.load_calibration(path)
        sensor = sensor_of(cal, image_size)
    except (OSError, ValueError) as e:
        msg = str(e)
        raise InputError(msg if str(path) in msg else f"{path}: {msg}") from None
    if tuple(sensor.image_size) != tuple(image_size):
        w, h = sensor.image_size
        raise InputError(f"{path}: calibrated for {w} x {h} images, but the session's are "
                         f"{image_size[0]} x {image_size[1]}")
    return cal, sensor


def score(path: Path, name: str, session: Session) -> Score:
    cal, sensor = load_cal(path, session.image_size)
    return Score(name, str(path), cal.model, planarity(cal, session),
                 chain_reprojection(sensor, session))


# ------------------------------------------------------------------ output

def fmt(x: float | None, digits: int) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def table(session: Session, scores: list[Score]) -> str:
    """The summary and the per-view planarity, as text."""
    width = max(12, *(len(s.name) for s in scores))
    lines = [f"session {session.folder}: {len(session.views)} images, "
             f"{session.num_stripe_points} stripe points, {len(session.corners)} board frames",
             "",
             f"{'calibration':<{width}} {'planarity mm':>12} {'chain px':>9} "
             f"{'points':>7} {'boards':>6}"]
    for s in scores:
        lines.append(f"{s.name:<{width}} {fmt(s.planarity.rms_mm, 3):>12} "
                     f"{fmt(s.chain.rms_px if s.chain else None, 2):>9} "
                     f"{s.planarity.num_points:>7} {len(session.corners):>6}")
    for s in scores:
        if s.chain is not None and s.chain.behind:
            lines.append(f"note: {s.name}: {s.chain.behind} reprojected corners fall behind the "
                         "camera, so its chain figure is meaningless")
    lines += ["", "per-view planarity RMS (mm) to each calibration's common plane "
              "(B: board frame)"]
    head = f"{'view':<8} {'points':>6}  " + " ".join(f"{s.name[:12]:>12}" for s in scores)
    lines.append(head)
    for v in session.views:
        mark = "B" if v.id in session.corners else " "
        row = " ".join(f"{fmt(s.planarity.per_view_mm[v.id], 3):>12}" for s in scores)
        lines.append(f"{v.id:<6} {mark} {session.stripes[v.id].shape[0]:>6}  {row}")
    return "\n".join(lines)


def as_json(session: Session, scores: list[Score]) -> dict[str, Any]:
    def clean(x: float) -> float | None:
        return x if math.isfinite(x) else None

    return {
        "session": str(session.folder),
        "extractor": EXTRACTOR_VERSION,
        "images": len(session.views),
        "stripe_points": session.num_stripe_points,
        "stripe_points_per_view": {i: int(s.shape[0]) for i, s in session.stripes.items()},
        "board_frames": sorted(session.corners, key=[v.id for v in session.views].index),
        "calibrations": [{
            "name": s.name, "path": s.path, "model": s.model,
            "planarity_mm": s.planarity.rms_mm, "mapped_points": s.planarity.num_points,
            "chain_px": None if s.chain is None else s.chain.rms_px,
            "per_view_planarity_mm": {k: clean(x) for k, x in s.planarity.per_view_mm.items()},
            "per_view_chain_px": None if s.chain is None else s.chain.per_view_px,
            "flipped_numbering": None if s.chain is None else s.chain.flipped,
            "corners_behind_camera": None if s.chain is None else s.chain.behind,
        } for s in scores],
    }


def default_cache_dir() -> Path:
    return Path(tempfile.gettempdir()) / "hmlvs-blaser-score"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("session", type=Path, help="a session folder (manifest.yaml + images/)")
    ap.add_argument("cal", type=Path, nargs="+", help="hmlvs calibration files")
    ap.add_argument("--names", nargs="+", help="a name per calibration (default: file names)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of tables")
    ap.add_argument("--cache-dir", type=Path, default=default_cache_dir(),
                    help="where the session's stripe pixels and corners are cached "
                    f"(default {default_cache_dir()})")
    ap.add_argument("--no-cache", action="store_true", help="extract again, write no cache")
    a = ap.parse_args(argv)
    names = a.names or [p.name for p in a.cal]
    try:
        if len(names) != len(a.cal):
            raise InputError(f"{len(a.cal)} calibrations but {len(names)} --names")
        if not a.session.is_dir():
            raise InputError(f"{a.session}: not a folder (give a session folder)")
        session = load_session(a.session, None if a.no_cache else a.cache_dir)
        scores = [score(p, n, session) for p, n in zip(a.cal, names)]
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        print(json.dumps(as_json(session, scores), indent=2) if a.json
              else table(session, scores))
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into head: not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


if __name__ == "__main__":
    sys.exit(main())
