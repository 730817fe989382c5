"""An independent renderer of laser on/off sessions, written from docs/model.md and
docs/file-formats.md alone (it shares no code with ``hmlvs.sim``), to measure the image
pipeline on images the project did not make.

The scene: the paper's Table 2 sensor (640 x 480 px, 7.4 um pixels, f = 8 mm, H = 140 mm,
theta = 25 deg) with the division-model radial distortion k = 4.8e-4 / mm^2 (docs/model.md step 2)
on a hand moved by random poses (yaw, tilt, camera 230-400 mm above the board) over the
paper's checkerboard (6 x 8 inner corners, 30 mm squares, on the plane z = 0 of the base).

Image formation, per pixel: the area of the pixel is integrated (``ss`` x ``ss`` samples,
each of which takes the print averaged over its share of the pixel, so the sum is exact at
the print's edges); every sample's ray (docs/model.md steps 1-2, inverted to a ray) meets the
board plane, whose printed albedo (dark 0.07, light 0.85, a white margin and a grey table
around it) is lit by vignetted ambient light. The laser sheet has a Gaussian thickness
profile (1-sigma 0.45 mm across the plane) and falls off as 1 / range; its return is the
surface's albedo *at the laser's wavelength* (dark 0.25, light 0.9: not proportional to the
ambient albedo, as with a real red laser on printed toner). Then a slight optical blur,
multiplicative laser speckle correlated over about 2 px, 1 grey level of Gaussian sensor
noise, rounding and clipping to 8 bits (so the stripe saturates where it is bright on white
squares at short range).

The truth of every view: the hand pose and, for every image column, the row where the
centre plane of the laser sheet meets the board (``true_centres``).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
import shutil

import cv2
import numpy as np

#: the rendered sensor: Table 2 nominal values with k = 4.8e-4 / mm^2 (docs/model.md units)
TRUE = {"f": 8.0, "Su": 0.0074, "Sv": 0.0074, "Cu": 320.0, "Cv": 240.0, "k": 4.8e-4,
        "H": 140.0, "theta": 5 * np.pi / 36, "omega": 0.0, "phi": 0.0, "varphi": 0.0,
        "tx": 60.0, "ty": 0.0, "tz": -45.0}
#: the paper's board, in the manifest's form (docs/file-formats.md)
BOARD = {"rows": 6, "cols": 8, "square": 30.0, "origin": [700.0, 90.0, 0.0],
         "row_direction": [-1.0, 0.0, 0.0], "col_direction": [0.0, -1.0, 0.0]}
SIZE = (640, 480)
ORDER = ("f", "Su", "Sv", "Cu", "Cv", "k", "H", "theta", "omega", "phi", "varphi",
         "tx", "ty", "tz")

ALBEDO = {"dark": 0.07, "light": 0.85, "table": 0.35}        # ambient (visible)
LASER_ALBEDO = {"dark": 0.25, "light": 0.9, "table": 0.45}   # at the laser's wavelength


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _axis_angle(axis: np.ndarray, a: float) -> np.ndarray:
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * kx + (1 - np.cos(a)) * kx @ kx


def hand_from_camera(p: dict) -> np.ndarray:
    """docs/model.md step 4: R_C = Rz(omega) Ry(phi) Rz(varphi), t = (tx, ty, tz)."""
    t = np.eye(4)
    t[:3, :3] = _rz(p["omega"]) @ _ry(p["phi"]) @ _rz(p["varphi"])
    t[:3, 3] = [p["tx"], p["ty"], p["tz"]]
    return t


def camera_rays(p: dict, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(..., 3) camera-frame ray directions (Xu, Yu, f) of pixels (u, v): docs/model.md 1-2."""
    xd, yd = p["Su"] * (u - p["Cu"]), p["Sv"] * (v - p["Cv"])
    s = 1.0 + p["k"] * (xd * xd + yd * yd)
    return np.stack([xd / s, yd / s, np.full(np.shape(xd), p["f"])], axis=-1)


def board_hits(p: dict, pose: np.ndarray, u: np.ndarray, v: np.ndarray):
    """Where the rays of pixels (u, v) meet the board plane z = 0: (base points (..., 3),
    camera-frame points (..., 3)); NaN where the ray points away from the plane."""
    bc = pose @ hand_from_camera(p)
    d = camera_rays(p, u, v)
    db = d @ bc[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -bc[2, 3] / db[..., 2]
    s = np.where(s > 0, s, np.nan)
    return bc[:3, 3] + s[..., None] * db, s[..., None] * d


def plane_offset(p: dict, pc: np.ndarray) -> np.ndarray:
    """Signed distance (mm) of camera-frame points from the laser plane y + z tan(theta) = H."""
    t = np.tan(p["theta"])
    return (pc[..., 1] + pc[..., 2] * t - p["H"]) / np.hypot(1.0, t)


def board_coords(pts: np.ndarray, board: dict = BOARD) -> np.ndarray:
    """(..., 2) board coordinates (mm along the row and column directions) of base points."""
    rel = pts - np.asarray(board["origin"])
    return np.stack([rel @ np.asarray(board["row_direction"]),
                     rel @ np.asarray(board["col_direction"])], axis=-1)


def _below(z: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """P(X <= z) for X the sum of two centred uniform variables of widths p and q: the
    share of a parallelogram footprint whose coordinate lies at most z from its centre
    (trapezoidal distribution; a step where both widths are 0)."""
    z, p, q = np.broadcast_arrays(z, p, q)
    out = (z > 0).astype(float)
    ramp = np.abs(z) < 0.5 * (p + q)  # within the footprint: its share (most points: none)
    if ramp.any():
        z, p, q = z[ramp], np.maximum(p[ramp], q[ramp]), np.minimum(p[ramp], q[ramp])
        a, b = 0.5 * (p - q), 0.5 * (p + q)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[ramp] = np.where(z < -a, (z + b) ** 2 / (2 * p * q),
                                 np.where(z <= a, 0.5 + z / p, 1.0 - (b - z) ** 2 / (2 * p * q)))
    return out


def albedos(xy: np.ndarray, board: dict = BOARD, laser_albedo: dict | None = None,
            footprint: tuple[np.ndarray, np.ndarray] | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """(ambient, laser) albedo at board coordinates: squares from -1 to rows (cols) square
    widths, a white margin (``board["margin"]`` squares wide, default half a square), the
    table beyond; the laser's from ``laser_albedo``
    (default :data:`LASER_ALBEDO`).

    ``footprint``: the two edge vectors (..., 2) (board mm) of the parallelogram each point
    stands for. The albedo is then its mean over that area (exact for the straight edges of
    the print away from the squares' corners), so that a pixel's samples add up to its area
    integral; point samples of the sharp print err by up to half a sample spacing at every
    edge."""
    la = LASER_ALBEDO if laser_albedo is None else laser_albedo
    sq = board["square"]
    x, y = xy[..., 0] / sq, xy[..., 1] / sq
    if footprint is None:
        wx = wy = np.zeros((2,) + x.shape)
    else:
        a, b = (np.nan_to_num(np.abs(np.asarray(f, float))) / sq for f in footprint)
        wx, wy = np.stack([a[..., 0], b[..., 0]]), np.stack([a[..., 1], b[..., 1]])

    def above(t: np.ndarray, w: np.ndarray, edge: float) -> np.ndarray:
        """Share of the footprint beyond ``edge`` along one board axis."""
        return 1.0 - _below(edge - t, w[0], w[1])

    def inside(t: np.ndarray, w: np.ndarray, lo: float, hi: float) -> np.ndarray:
        return above(t, w, lo) - above(t, w, hi)

    def wave(t: np.ndarray, w: np.ndarray, count: int) -> np.ndarray:
        """+1 on even squares, -1 on odd ones, averaged over the footprint at the nearest
        edge between two of the ``count`` + 1 squares along the axis (the outer edges are
        the squares' area's)."""
        n = np.clip(np.round(np.nan_to_num(t)), 0, count - 1)
        return np.where(n % 2 == 0, 1.0, -1.0) * (2.0 * above(t, w, n) - 1.0)

    rows, cols = board["rows"], board["cols"]
    squares = inside(x, wx, -1.0, rows) * inside(y, wy, -1.0, cols)
    m = float(board.get("margin", 0.5))
    paper = inside(x, wx, -1.0 - m, rows + m) * inside(y, wy, -1.0 - m, cols + m)
    dark = squares * 0.5 * (1.0 + wave(x, wx, rows) * wave(y, wy, cols))

    def mix(level: dict) -> np.ndarray:
        return level["table"] * (1.0 - paper) + level["light"] * (paper - dark) + \
            level["dark"] * dark  # the print's own levels, exactly, away from its edges

    bad = ~np.isfinite(xy).all(axis=-1)
    return np.where(bad, 0.0, mix(ALBEDO)), np.where(bad, 0.0, mix(la))


def true_centres(p: dict, pose: np.ndarray, size: tuple[int, int] = SIZE) -> np.ndarray:
    """(width,) the exact stripe centre row of every column: the row whose ray meets the
    board on the centre plane of the laser sheet (NaN where none inside the image)."""
    u = np.arange(size[0], dtype=float)
    lo, hi = np.full_like(u, -0.5), np.full_like(u, size[1] - 0.5)

    def g(v: np.ndarray) -> np.ndarray:
        return plane_offset(p, board_hits(p, pose, u, v)[1])

    glo, ghi = g(lo), g(hi)
    ok = np.isfinite(glo) & np.isfinite(ghi) & (np.sign(glo) != np.sign(ghi))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        gm = g(mid)
        same = np.sign(gm) == np.sign(glo)
        lo, glo = np.where(same, mid, lo), np.where(same, gm, glo)
        hi = np.where(same, hi, mid)
    return np.where(ok, 0.5 * (lo + hi), np.nan)


def project(p: dict, pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(..., 2) pixels of base points ``pts`` (..., 3): docs/model.md steps 1-4 forward (the
    division model inverted by fixed-point iteration, 20 steps: converged to 1e-12 px at
    this distortion)."""
    bc = pose @ hand_from_camera(p)
    pc = (np.asarray(pts, float) - bc[:3, 3]) @ bc[:3, :3]
    xu, yu = p["f"] * pc[..., 0] / pc[..., 2], p["f"] * pc[..., 1] / pc[..., 2]
    s = np.ones_like(xu)
    for _ in range(20):  # Xu = Xd / (1 + k rd^2), so Xd = Xu (1 + k rd^2)
        s = 1.0 + p["k"] * ((xu * s) ** 2 + (yu * s) ** 2)
    return np.stack([xu * s / p["Su"] + p["Cu"], yu * s / p["Sv"] + p["Cv"]], axis=-1)


def board_corners(board: dict = BOARD) -> np.ndarray:
    """(rows * cols, 3) the inner corners in the base, row by row (docs/file-formats.md)."""
    r, c = np.meshgrid(np.arange(board["rows"]), np.arange(board["cols"]), indexing="ij")
    sq = board["square"]
    return (np.asarray(board["origin"], float) + (r.ravel() * sq)[:, None] *
            np.asarray(board["row_direction"], float) + (c.ravel() * sq)[:, None] *
            np.asarray(board["col_direction"], float))


def _whole_board_seen(p: dict, pose: np.ndarray, board: dict, size: tuple[int, int],
                      margin: float) -> bool:
    """Whether the board's squares (one square beyond the inner corners) and half a square
    of its white margin lie inside the image, ``margin`` px from its border."""
    sq = board["square"]
    r, c = np.meshgrid([-1.5, board["rows"] + 0.5], [-1.5, board["cols"] + 0.5], indexing="ij")
    outer = (np.asarray(board["origin"], float) + (r.ravel() * sq)[:, None] *
             np.asarray(board["row_direction"], float) + (c.ravel() * sq)[:, None] *
             np.asarray(board["col_direction"], float))
    bc = pose @ hand_from_camera(p)
    if not ((outer - bc[:3, 3]) @ bc[:3, 2] > 0).all():
        return False
    px = project(p, pose, outer)
    return bool((px > margin).all() and (px[:, 0] < size[0] - 1 - margin).all() and
                (px[:, 1] < size[1] - 1 - margin).all())


def random_pose(rng: np.random.Generator, p: dict = TRUE, board: dict = BOARD,
                max_tilt: float = np.radians(15), size: tuple[int, int] = SIZE,
                heights: tuple[float, float] = (230.0, 400.0), min_columns: int = 250,
                whole_board: bool = False) -> np.ndarray:
    """A base_from_hand pose: camera looking down at a random yaw, tilted up to ``max_tilt``
    about a random horizontal axis, ``heights`` (mm) above the board, placed so that the
    stripe's middle lands on a random point of the board's inner area and crosses it for at
    least ``min_columns`` columns; ``whole_board``: drawn again until the board's squares
    lie wholly inside the image (a margin of 4 px)."""
    sq = board["square"]
    w, h = size
    while True:
        yaw = rng.uniform(-np.pi, np.pi)
        r0 = np.column_stack([[np.cos(yaw), np.sin(yaw), 0], [np.sin(yaw), -np.cos(yaw), 0],
                              [0, 0, -1.0]])
        a = rng.uniform(0, 2 * np.pi)
        r = _axis_angle([np.cos(a), np.sin(a), 0], rng.uniform(0, max_tilt)) @ r0
        bc = np.eye(4)
        bc[:3, :3], bc[:3, 3] = r, [0.0, 0.0, rng.uniform(*heights)]
        pose = bc @ np.linalg.inv(hand_from_camera(p))
        v = true_centres(p, pose, size)
        mid_u = w // 2
        if not np.isfinite(v[mid_u]) or not 30 < v[mid_u] < h - 30:
            continue
        mid = board_hits(p, pose, np.array(float(mid_u)), np.array(v[mid_u]))[0]
        target = np.asarray(board["origin"]) + rng.uniform(0.5, board["rows"] - 1.5) * sq * \
            np.asarray(board["row_direction"]) + rng.uniform(0.5, board["cols"] - 1.5) * sq * \
            np.asarray(board["col_direction"])
        pose[:2, 3] += (target - mid)[:2]
        u = np.arange(w, dtype=float)
        v = true_centres(p, pose, size)
        xy = board_coords(board_hits(p, pose, u, v)[0], board)
        inner = (xy[:, 0] > 0) & (xy[:, 0] < (board["rows"] - 1) * sq) & \
            (xy[:, 1] > 0) & (xy[:, 1] < (board["cols"] - 1) * sq) & np.isfinite(v) & \
            (v > 10) & (v < h - 11)
        if inner.sum() >= min_columns and (not whole_board or
                                           _whole_board_seen(p, pose, board, size, 4.0)):
            return pose


def render_view(p: dict, pose: np.ndarray, rng: np.random.Generator, *, ss: int = 4,
                ambient: float = 150.0, laser: float = 110.0, sheet_sigma: float = 0.45,
                blur: float = 0.5, speckle: float = 0.1, noise: float = 1.0,
                board: dict = BOARD, laser_albedo: dict | None = None,
                size: tuple[int, int] = SIZE) -> tuple[np.ndarray, np.ndarray]:
    """(laser-on, laser-off) 8-bit images of one pose. Pixels are integrated over their area
    with ``ss`` x ``ss`` samples wherever the albedo changes within the pixel's neighbourhood
    and wherever the laser sheet can reach (elsewhere the scene is constant over a pixel).
    ``laser_albedo``: the print's albedo at the laser's wavelength (keys dark, light, table;
    default :data:`LASER_ALBEDO`); one value for all three removes the albedo steps from the
    stripe while the board stays visible to the camera. ``size``: the image's (width,
    height)."""
    w, h = size
    off = (np.arange(ss) + 0.5) / ss - 0.5
    sub_u, sub_v = np.meshgrid(off, off)

    def samples(u: np.ndarray, v: np.ndarray):
        """Area samples of pixels (u, v): ambient albedo and laser return, (n, ss * ss).
        Each sample stands for its 1/ss x 1/ss share of the pixel (``albedos``' footprint,
        from the board's coordinates one pixel to the right of and below the centre)."""
        uu, vv = u[:, None] + sub_u.ravel(), v[:, None] + sub_v.ravel()
        pts, pc = board_hits(p, pose, uu, vv)
        centre = board_coords(board_hits(p, pose, u, v)[0], board)
        step = [(board_coords(board_hits(p, pose, u + du, v + dv)[0], board) - centre)
                [:, None, :] / ss for du, dv in ((1.0, 0.0), (0.0, 1.0))]
        amb, las = albedos(board_coords(pts, board), board, laser_albedo,
                           footprint=(step[0], step[1]))
        d = plane_offset(p, pc)
        dist = np.linalg.norm(pc - np.array([0.0, p["H"], 0.0]), axis=-1)
        beam = np.nan_to_num(np.exp(-0.5 * (d / sheet_sigma) ** 2) * 300.0 / dist)
        return amb, las * beam

    vg, ug = np.mgrid[0:h, 0:w].astype(float)
    amb_img = albedos(board_coords(board_hits(p, pose, ug, vg)[0], board), board)[0]
    kernel = np.ones((3, 3), np.uint8)
    a8 = np.rint(amb_img * 100).astype(np.uint8)
    mixed = cv2.dilate(a8, kernel) != cv2.erode(a8, kernel)
    rows = true_centres(p, pose, size)
    band = np.zeros((h, w), bool)
    if np.isfinite(rows).any():
        lo, hi = np.nanmin(rows), np.nanmax(rows)
        band[max(0, int(lo) - 20):min(h, int(hi) + 21)] = True
    sel = mixed | band
    amb_s, las_s = samples(ug[sel], vg[sel])
    amb_img[sel] = amb_s.mean(axis=1)
    las_img = np.zeros((h, w))
    las_img[sel] = las_s.mean(axis=1)
    yy, xx = np.mgrid[0:h, 0:w]
    vignette = 1.0 - 0.3 * ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    amb_img *= ambient * vignette
    las_img *= laser
    if speckle > 0:
        field = cv2.GaussianBlur(rng.standard_normal((h, w)), (0, 0), 1.0)
        las_img *= np.clip(1.0 + speckle * field / field.std(), 0.0, None)
    if blur > 0:
        amb_img = cv2.GaussianBlur(amb_img, (0, 0), blur)
        las_img = cv2.GaussianBlur(las_img, (0, 0), blur)

    def shoot(img: np.ndarray) -> np.ndarray:
        return np.clip(np.rint(img + noise * rng.standard_normal(img.shape)), 0, 255
                       ).astype(np.uint8)

    return shoot(amb_img + las_img), shoot(amb_img)


def render_session(folder: str | Path, seed: int = 0, views: int = 16, held_out: int = 4,
                   noise_seed: int | None = None, params: dict | None = None,
                   board: dict | None = None, size: tuple[int, int] = SIZE,
                   pose_options: dict | None = None, board_pose: bool = True,
                   **options) -> dict:
    """Render ``views`` image pairs into ``folder`` (manifest.json, p000_on.png, ...) and
    draw ``held_out`` further poses for testing (no images). Returns the truth: ``params``,
    ``poses`` (views + held_out, 4, 4), ``centres`` (views + held_out, width) and ``ids``;
    also saved as ``truth.npz`` in ``folder``. ``noise_seed``: the images' noise and speckle
    drawn from their own stream, so that the same scene (``seed``: the poses) can be taken
    again with other noise; None: one stream for both, as it always was.

    Another scene: ``params`` (the sensor, default :data:`TRUE`), ``board`` (default
    :data:`BOARD`), ``size`` (the images' width and height), ``pose_options`` (for
    :func:`random_pose`, e.g. ``whole_board=True``); ``board_pose=False`` leaves the board's
    pose out of the manifest (rows, cols and square only: a board whose place nobody
    measured).

    With the environment variable ``HMLVS_TEST_RENDER_CACHE`` naming a folder (``make test``
    sets it), a session rendered once is copied from there when asked for again with the
    same arguments by the same renderer (the key: this file's text and the arguments), so
    the suite's second pass under another BLAS kernel reads the images the first one drew."""
    args = dict(seed=seed, views=views, held_out=held_out, noise_seed=noise_seed,
                params=params, board=board, size=size, pose_options=pose_options,
                board_pose=board_pose, **options)
    cache = os.environ.get("HMLVS_TEST_RENDER_CACHE")
    if not cache:
        return _render_session(Path(folder), **args)
    key = hashlib.sha256(Path(__file__).read_bytes()
                         + repr(sorted(args.items())).encode()).hexdigest()[:24]
    stored = Path(cache) / key
    if not stored.is_dir():
        part = Path(cache) / f"{key}.{os.getpid()}.part"
        shutil.rmtree(part, ignore_errors=True)
        _render_session(part, **args)
        try:
            part.rename(stored)  # whole or not at all: another worker may have won
        except OSError:
            shutil.rmtree(part, ignore_errors=True)
    shutil.copytree(stored, folder, dirs_exist_ok=True)
    truth = dict(np.load(Path(folder) / "truth.npz"))
    truth["views"] = int(truth["views"])
    return truth


def _render_session(folder: Path, seed: int, views: int, held_out: int,
                    noise_seed: int | None, params: dict | None, board: dict | None,
                    size: tuple[int, int], pose_options: dict | None, board_pose: bool,
                    **options) -> dict:
    """:func:`render_session`, rendered."""
    folder.mkdir(parents=True, exist_ok=True)
    p = TRUE if params is None else params
    b = BOARD if board is None else board
    rng = np.random.default_rng(seed)
    poses = np.array([random_pose(rng, p, b, size=size, **(pose_options or {}))
                      for _ in range(views + held_out)])
    centres = np.array([true_centres(p, q, size) for q in poses])
    if noise_seed is not None:
        rng = np.random.default_rng([seed, 104729, int(noise_seed)])
    entries = []
    for i in range(views):
        on, off = render_view(p, poses[i], rng, board=b, size=size, **options)
        pid = f"p{i:03d}"
        cv2.imwrite(str(folder / f"{pid}_on.png"), on)
        cv2.imwrite(str(folder / f"{pid}_off.png"), off)
        entries.append({"id": pid, "on": f"{pid}_on.png", "off": f"{pid}_off.png",
                        "pose": poses[i].tolist()})
    placed = b if board_pose else {k: b[k] for k in ("rows", "cols", "square")}
    manifest = {"format": "hmlvs-images", "version": 1, "image_size": list(size),
                "board": placed, "poses": entries}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=1))
    ids = [f"p{i:03d}" for i in range(views)] + [f"h{i:03d}" for i in range(held_out)]
    truth = {"params": np.array([p[n] for n in ORDER]), "poses": poses,
             "centres": centres, "ids": np.array(ids), "views": views}
    np.savez(folder / "truth.npz", **truth)
    return truth
