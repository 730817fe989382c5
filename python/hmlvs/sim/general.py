"""Sessions and images of the general sensor (:class:`hmlvs.models.opencv.OpenCvSensor`).

No robot and no inverse kinematics: the board lies on a table at a chosen
``base_from_board``, each view places the camera above it (tilt, azimuth and roll about the
optical axis drawn at random, stand-off such that the whole board and the laser line on it
are in the image with a margin), and the robot's pose follows as
``base_from_hand = base_from_board @ board_from_camera @ inv(hand_from_camera)``.

The truth is computed with OpenCV alone (``cv2.projectPoints``): corner pixels, and per image
column the row where the laser plane meets the board plane. The images are rendered by the
shading of :mod:`hmlvs.sim.render` (anti-aliased checkerboard, Gaussian stripe weighted by the
albedo, speckle, blur, noise, saturation); each pixel's ray comes from
``cv2.undistortPoints``, checked to re-project within 1e-3 px. Nothing here uses the C++ core.

Board frame: x along the rows, y along the columns, z = x cross y towards the camera; inner
corner (r, c) at (r, c) * square (as :class:`hmlvs.Checkerboard`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_folder, atomic_write
from ..data.manifest import FORMAT, NAME, VERSION, write_png
from ..geometry.board import Checkerboard
from ..models.opencv import OpenCvSensor
from .render import RenderOptions, board_exposures, finish_frames

#: reprojection accuracy (px) demanded of the undistorted pixel rays
RAY_TOLERANCE = 1e-3


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def _transform(rot: np.ndarray, t: Any) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, t
    return m


def example_sensor(image_size: tuple[int, int] = (1024, 768)) -> OpenCvSensor:
    """A plausible general sensor for simulations.

    fx = 1100, fy = 1102 px, principal point 6 px and -4 px off the centre, distortion
    (k1, k2, p1, p2, k3) = (-0.165, 0.05, 0.0005, -0.0004, 0); a laser projector 80 mm
    below the camera (-y) whose plane meets the optical axis 380 mm away, its normal turned
    1.5 degrees out of the camera's y-z plane; hand_from_camera turned 93 degrees about the
    flange z axis and 2 degrees about x, translated (60, 0, -45) mm.
    """
    w, h = image_size
    k = np.array([[1100.0, 0.0, (w - 1) / 2 + 6.0], [0.0, 1102.0, (h - 1) / 2 - 4.0],
                  [0.0, 0.0, 1.0]])
    z0, base = 380.0, 80.0
    # the plane through (0, -base, 0) and (0, 0, z0) containing the x axis, its normal then
    # tilted 1.5 degrees out of the y-z plane (about the line through those two points)
    n = np.array([0.0, z0, base]) / math.hypot(z0, base)
    tilt = math.radians(1.5)
    n = np.array([math.sin(tilt), *(math.cos(tilt) * n[1:])])
    plane = np.append(n, -n @ np.array([0.0, 0.0, z0]))
    hfc = _transform(_rot("z", math.radians(93.0)) @ _rot("x", math.radians(2.0)),
                     [60.0, 0.0, -45.0])
    return OpenCvSensor(k, [-0.165, 0.05, 0.0005, -0.0004, 0.0], (w, h), plane, hfc)


@dataclass(frozen=True)
class GeneralSession:
    """A simulated session of the general sensor, with its truth.

    Attributes
    ----------
    sensor : the true sensor (``base_from_board`` set to the board's true pose)
    board : the board, placed in the base frame (``board.corners()`` are base-frame points)
    base_from_hand : (n, 4, 4) robot poses (mm)
    board_from_camera : (n, 4, 4) true camera poses
    corners : (n, rows*cols, 2) true pixels of the inner corners, row-major board order
    stripe_v : (n, w) true row of the laser line in each image column (the laser plane meets
        the board's plane there); NaN where it does not cross the column inside the image
    stripe_on_board : (n, w) bool: that point lies on the board's pattern of squares
        (inner corners extended by one square), not on its white border or the table
    seed : the seed the session was drawn with
    """

    sensor: OpenCvSensor
    board: Checkerboard
    base_from_hand: np.ndarray
    board_from_camera: np.ndarray
    corners: np.ndarray
    stripe_v: np.ndarray
    stripe_on_board: np.ndarray
    seed: int

    def __len__(self) -> int:
        return int(self.base_from_hand.shape[0])

    def stripe_pixels(self, i: int, on_board: bool = True) -> np.ndarray:
        """(k, 2) true stripe pixels (u, v) of view ``i``, one per image column (u integer),
        only those on the board's pattern unless ``on_board`` is False."""
        v = self.stripe_v[i]
        keep = self.stripe_on_board[i] if on_board else np.isfinite(v)
        u = np.nonzero(keep)[0]
        return np.stack([u.astype(float), v[u]], axis=1)


def _project(sensor: OpenCvSensor, camera_from_x: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Pixels (n, 2) of points (n, 3) given in a frame x, by cv2.projectPoints."""
    import cv2
    rvec, _ = cv2.Rodrigues(camera_from_x[:3, :3])
    px, _ = cv2.projectPoints(np.ascontiguousarray(pts, float).reshape(-1, 1, 3), rvec,
                              camera_from_x[:3, 3].copy(), sensor.camera_matrix,
                              sensor.dist_coeffs)
    return px.reshape(-1, 2)


def _laser_line_on_board(sensor: OpenCvSensor, bfc: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray] | None:
    """The line where the laser plane meets the board plane, in board coordinates:
    (point, unit direction), both with z = 0; None if the planes are parallel."""
    plane = sensor.laser_plane
    # laser plane in board coordinates: n_b . p + d_b = 0 with p = bfc @ camera point
    n_b = bfc[:3, :3] @ plane[:3]
    d_b = plane[3] - n_b @ bfc[:3, 3]
    direction = np.array([-n_b[1], n_b[0], 0.0])  # in z = 0 and orthogonal to n_b
    norm = np.linalg.norm(direction)
    if norm < 1e-9:
        return None
    point = np.zeros(3)
    point[:2] = -d_b * n_b[:2] / (n_b[:2] @ n_b[:2])
    return point, direction / norm


def _true_stripe(sensor: OpenCvSensor, bfc: np.ndarray, board: Checkerboard,
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per image column u: the row v where the laser / board line appears (NaN where it does
    not), and whether that point lies on the board's pattern. The line is sampled densely
    in front of the camera and projected with OpenCV; each column's crossing is then found by
    secant steps on the line parameter, re-projecting exactly."""
    w, h = sensor.image_size
    out = np.full(w, np.nan)
    on_board = np.zeros(w, bool)
    line = _laser_line_on_board(sensor, bfc)
    if line is None:
        return out, on_board
    p0, dirn = line
    cfb = np.linalg.inv(bfc)
    # the stretch of the line in front of the camera, far enough to leave the image
    t = np.linspace(-3000.0, 3000.0, 60001)
    pts = p0 + t[:, None] * dirn
    depth = pts @ cfb[2, :3] + cfb[2, 3]
    front = depth > 1.0
    t, pts = t[front], pts[front]
    px = _project(sensor, cfb, pts)
    inside = (px[:, 0] > -1) & (px[:, 0] < w) & (px[:, 1] > -1) & (px[:, 1] < h)
    if inside.sum() < 2:
        return out, on_board
    t, px = t[inside], px[inside]
    if px[-1, 0] < px[0, 0]:
        t, px = t[::-1], px[::-1]
    if np.any(np.diff(px[:, 0]) <= 0):
        raise ValueError("the laser line is not a function of the image column in this view")
    cols = np.arange(math.ceil(px[0, 0]), math.floor(px[-1, 0]) + 1)
    cols = cols[(cols >= 0) & (cols < w)]
    tc = np.interp(cols, px[:, 0], t)
    for _ in range(3):  # secant refinement on u(t) = column
        step = 1e-3
        a = _project(sensor, cfb, p0 + tc[:, None] * dirn)
        b = _project(sensor, cfb, p0 + (tc + step)[:, None] * dirn)
        du = (b[:, 0] - a[:, 0]) / step
        tc = tc - (a[:, 0] - cols) / du
    final = _project(sensor, cfb, p0 + tc[:, None] * dirn)
    assert np.abs(final[:, 0] - cols).max() < 1e-6
    ok = (final[:, 1] >= 0) & (final[:, 1] <= h - 1)
    out[cols[ok]] = final[ok, 1]
    xy = (p0 + tc[:, None] * dirn)[:, :2]
    sq = board.square
    pattern = ((xy[:, 0] >= -sq) & (xy[:, 0] <= board.rows * sq)
               & (xy[:, 1] >= -sq) & (xy[:, 1] <= board.cols * sq))
    on_board[cols[ok]] = pattern[ok]
    return out, on_board


def _board_outline(board: Checkerboard, margin: float) -> np.ndarray:
    """(k, 3) points densely along the outer edge of the board (pattern plus ``margin``
    squares of white border), board frame."""
    sq = board.square
    lo_x, hi_x = -sq - margin * sq, board.rows * sq + margin * sq
    lo_y, hi_y = -sq - margin * sq, board.cols * sq + margin * sq
    s = np.linspace(0.0, 1.0, 41)[:, None]
    corners = np.array([[lo_x, lo_y], [hi_x, lo_y], [hi_x, hi_y], [lo_x, hi_y], [lo_x, lo_y]])
    edges = [a + s * (b - a) for a, b in zip(corners[:-1], corners[1:])]
    xy = np.vstack(edges)
    return np.hstack([xy, np.zeros((len(xy), 1))])


def _camera_pose(look_at: np.ndarray, tilt: float, azimuth: float, roll: float,
                 distance: float) -> np.ndarray:
    """board_from_camera looking at ``look_at`` (board frame) from ``distance`` mm, the
    optical axis ``tilt`` rad off the board normal towards ``azimuth``; at roll 0 the
    camera's x axis (image +u) follows the board's y axis (columns) and its y axis (image +v)
    the board's x axis (rows), so r0c0 appears top-left."""
    back = np.array([math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth),
                     math.cos(tilt)])  # from the target towards the camera
    z = -back
    x = np.array([0.0, 1.0, 0.0]) - z * z[1]
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.stack([x, y, z], axis=1) @ _rot("z", roll)
    return _transform(rot, look_at + distance * back)


def _random_view(rng: np.random.Generator, placed: Any, sq: float,
                 look_range: tuple[float, float], tilt_deg: tuple[float, float],
                 roll_deg: tuple[float, float],
                 distance: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """A random camera looking at a point of the board (its fraction of the board's extent
    drawn from look_range): board_from_camera and its inverse."""
    look = np.array([rng.uniform(*look_range) * (placed.rows - 1) * sq,
                     rng.uniform(*look_range) * (placed.cols - 1) * sq, 0.0])
    bfc = _camera_pose(look, math.radians(rng.uniform(*tilt_deg)),
                       rng.uniform(0.0, 2 * math.pi), math.radians(rng.uniform(*roll_deg)),
                       rng.uniform(*distance))
    return bfc, np.linalg.inv(bfc)


def general_session(sensor: OpenCvSensor | None = None, board: Checkerboard | None = None,
                    views: int = 20, seed: int = 0, *,
                    tilt_deg: tuple[float, float] = (10.0, 40.0),
                    roll_deg: tuple[float, float] = (-60.0, 60.0),
                    distance: tuple[float, float] = (300.0, 520.0),
                    image_margin: float = 20.0, border: float = 1.0,
                    base_from_board: np.ndarray | None = None,
                    max_tries: int = 10000) -> GeneralSession:
    """A session of the general sensor without a robot model.

    Parameters
    ----------
    sensor : the true sensor (default :func:`example_sensor`); its ``base_from_board`` is
        replaced by the board's pose
    board : rows, cols (inner corners) and square (mm) are used (default 7 x 9, 20 mm);
        the returned board is placed at ``base_from_board``
    views : number of views
    seed : random seed (the same seed gives the same session)
    tilt_deg : range of the optical axis' angle to the board normal (degrees)
    roll_deg : range of the rotation about the optical axis (degrees; 0: board rows run
        down the image, columns to the right)
    distance : range of the distance (mm) from the camera to the aimed-at board point
    image_margin : every point of the board's outline (the pattern plus ``border`` squares
        of white border) and of the laser line on the board stays this many px inside the
        image
    base_from_board : the board's pose in the base (default: on the table z = 0, 600 mm in
        front of the robot, turned 20 degrees about z)
    max_tries : candidate views drawn at most before giving up (``ValueError``)
    """
    sensor = example_sensor() if sensor is None else sensor
    spec = Checkerboard(rows=7, cols=9, square=20.0) if board is None else board
    if base_from_board is None:
        base_from_board = _transform(_rot("z", math.radians(20.0)), [600.0, -80.0, 0.0])
    bfb = np.asarray(base_from_board, float)
    placed = Checkerboard(rows=spec.rows, cols=spec.cols, square=spec.square,
                          origin=tuple(bfb[:3, 3]), row_direction=tuple(bfb[:3, 0]),
                          col_direction=tuple(bfb[:3, 1]))
    truth = OpenCvSensor(sensor.camera_matrix, sensor.dist_coeffs, sensor.image_size,
                         sensor.laser_plane, sensor.hand_from_camera, bfb)
    w, h = truth.image_size
    rng = np.random.default_rng(seed)
    outline = _board_outline(placed, border)
    bxy = placed.board_coordinates()
    corners_b = np.hstack([bxy, np.zeros((len(bxy), 1))])
    sq = placed.square
    poses, cams, corners, stripes, on_board = [], [], [], [], []
    tries = 0
    while len(poses) < views:
        tries += 1
        if tries > max_tries:
            raise ValueError(f"only {len(poses)} of {views} views fit after {max_tries} tries: "
                             "the board is too large for the image at these distances, or the "
                             "laser line misses it")
        bfc, cfb = _random_view(rng, placed, sq, (0.2, 0.8), tilt_deg, roll_deg, distance)
        if np.any(outline @ cfb[2, :3] + cfb[2, 3] <= 0):
            continue
        edge = _project(truth, cfb, outline)
        m = image_margin
        if not ((edge[:, 0] >= m) & (edge[:, 0] <= w - 1 - m) & (edge[:, 1] >= m)
                & (edge[:, 1] <= h - 1 - m)).all():
            continue
        try:
            v, on = _true_stripe(truth, bfc, placed)
        except ValueError:  # the line folds back in the image (strong distortion): skip
            continue
        # the laser line must cross the whole pattern, clear of the image border
        if on.sum() < 0.5 * np.ptp(edge[:, 0]):
            continue
        vb = v[on]
        if vb.min() < m or vb.max() > h - 1 - m:
            continue
        poses.append(bfb @ bfc @ np.linalg.inv(truth.hand_from_camera))
        cams.append(bfc)
        corners.append(_project(truth, cfb, corners_b))
        stripes.append(v)
        on_board.append(on)
    return GeneralSession(truth, placed, np.array(poses), np.array(cams), np.array(corners),
                          np.array(stripes), np.array(on_board), int(seed))


def add_partial_views(session: GeneralSession, views: int, seed: int = 0, *,
                      visible: tuple[float, float] = (0.3, 0.75),
                      tilt_deg: tuple[float, float] = (10.0, 35.0),
                      roll_deg: tuple[float, float] = (-60.0, 60.0),
                      distance: tuple[float, float] = (300.0, 520.0),
                      image_margin: float = 20.0, max_tries: int = 20000) -> GeneralSession:
    """``session`` with ``views`` more views in which the board is only partly in the image.

    Each new view aims at a point near the board's edge (up to 40 % of the board beyond
    it), so that a fraction within ``visible`` of the inner corners lies at least
    ``image_margin`` px inside the image and at least one corner lies outside it; the laser
    line must cross the board inside the image over at least a fifth of the image width.
    ``distance`` is the range of the distance (mm) from the camera to the aimed-at point. The
    new views come last; their truth is computed as :func:`general_session`'s."""
    w, h = session.sensor.image_size
    m = image_margin

    def board_seen(px: np.ndarray, edge: np.ndarray) -> bool:
        inside = ((px[:, 0] >= m) & (px[:, 0] <= w - 1 - m) & (px[:, 1] >= m)
                  & (px[:, 1] <= h - 1 - m))
        out = ((px[:, 0] < 0) | (px[:, 0] > w - 1) | (px[:, 1] < 0) | (px[:, 1] > h - 1))
        return bool(visible[0] <= inside.mean() <= visible[1] and out.any())

    return _add_views(session, views, np.random.default_rng([int(seed), 7919]), board_seen,
                      lambda v, on: bool(on.sum() >= 0.2 * w), tilt_deg, roll_deg, distance,
                      max_tries, "partial")


def add_stripe_off_board_views(session: GeneralSession, views: int, seed: int = 0, *,
                               on_board: tuple[float, float] = (0.0, 0.0),
                               tilt_deg: tuple[float, float] = (10.0, 35.0),
                               roll_deg: tuple[float, float] = (-60.0, 60.0),
                               distance: tuple[float, float] = (300.0, 520.0),
                               image_margin: float = 20.0,
                               max_tries: int = 50000) -> GeneralSession:
    """``session`` with ``views`` more views that see the whole board (its outline with one
    square of white border ``image_margin`` px inside the image) while the laser line runs
    off its pattern: the fraction of the line's image columns that lie on the pattern is
    within ``on_board`` ((0, 0): the line misses the pattern and lies on the white border or
    the table around it, in the board's plane; e.g. (0.1, 0.6): it leaves the pattern). The
    line is in the image over at least a third of its width. The new views come last."""
    w, h = session.sensor.image_size
    m = image_margin

    def board_seen(px: np.ndarray, edge: np.ndarray) -> bool:
        return bool(((edge[:, 0] >= m) & (edge[:, 0] <= w - 1 - m) & (edge[:, 1] >= m)
                     & (edge[:, 1] <= h - 1 - m)).all())

    def stripe_off(v: np.ndarray, on: np.ndarray) -> bool:
        seen = np.isfinite(v)
        return bool(seen.sum() >= w / 3 and on_board[0] <= on[seen].mean() <= on_board[1])

    return _add_views(session, views, np.random.default_rng([int(seed), 104729]), board_seen,
                      stripe_off, tilt_deg, roll_deg, distance, max_tries, "stripe-off-board",
                      look_range=(-0.6, 1.6))


def _add_views(session: GeneralSession, views: int, rng: np.random.Generator,
               board_seen: Any, stripe_ok: Any, tilt_deg: tuple[float, float],
               roll_deg: tuple[float, float], distance: tuple[float, float],
               max_tries: int, what: str, *,
               look_range: tuple[float, float] = (-0.4, 1.4)) -> GeneralSession:
    """``session`` with ``views`` more random views aimed at points within ``look_range`` of
    the board's extent, each kept when ``board_seen(corner pixels, outline pixels)`` and
    ``stripe_ok(stripe rows, stripe on pattern)`` hold; their truth is computed as
    :func:`general_session`'s."""
    truth, placed = session.sensor, session.board
    bxy = placed.board_coordinates()
    corners_b = np.hstack([bxy, np.zeros((len(bxy), 1))])
    outline = _board_outline(placed, 1.0)
    bfb = truth.base_from_board
    poses, cams, corners, stripes, on_board = [], [], [], [], []
    tries = 0
    while len(poses) < views:
        tries += 1
        if tries > max_tries:
            raise ValueError(f"only {len(poses)} of {views} {what} views fit after "
                             f"{max_tries} tries")
        bfc, cfb = _random_view(rng, placed, placed.square, look_range, tilt_deg, roll_deg,
                                distance)
        if np.any(outline @ cfb[2, :3] + cfb[2, 3] <= 0):
            continue
        px = _project(truth, cfb, corners_b)
        if not board_seen(px, _project(truth, cfb, outline)):
            continue
        try:
            v, on = _true_stripe(truth, bfc, placed)
        except ValueError:
            continue
        if not stripe_ok(v, on):
            continue
        poses.append(bfb @ bfc @ np.linalg.inv(truth.hand_from_camera))
        cams.append(bfc)
        corners.append(px)
        stripes.append(v)
        on_board.append(on)
    cat = np.concatenate
    return GeneralSession(truth, placed, cat([session.base_from_hand, np.array(poses)]),
                          cat([session.board_from_camera, np.array(cams)]),
                          cat([session.corners, np.array(corners)]),
                          cat([session.stripe_v, np.array(stripes)]),
                          cat([session.stripe_on_board, np.array(on_board)]), session.seed)


# ------------------------------------------------------------------------------------------
# Rendering


_RAYS: dict[tuple, np.ndarray] = {}


def pixel_rays(sensor: OpenCvSensor, supersample: int = 1) -> np.ndarray:
    """Camera rays (h*s, w*s, 3), z = 1, of the supersample positions of every pixel (s =
    ``supersample``, odd: the middle sample at the pixel's integer position), by
    ``cv2.undistortPoints``; raises ``RuntimeError`` unless they re-project (cv2.projectPoints,
    on a regular subset of the samples) within :data:`RAY_TOLERANCE` px. Cached for the last
    sensor."""
    import cv2
    w, h = sensor.image_size
    s = int(supersample)
    key = (sensor.camera_matrix.tobytes(), sensor.dist_coeffs.tobytes(), w, h, s)
    if key in _RAYS:
        return _RAYS[key]
    off = (np.arange(s) + 0.5) / s - 0.5
    us = (np.arange(w)[:, None] + off[None, :]).ravel()
    vs = (np.arange(h)[:, None] + off[None, :]).ravel()
    px = np.empty((len(vs), len(us), 2))  # (u, v) of every sample, row by row
    px[:, :, 0] = us[None, :]
    px[:, :, 1] = vs[:, None]
    px = px.reshape(-1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT, 20, 0.0)  # fixed-point steps; checked below
    # with stopping criteria: cv2.undistortPointsIter up to OpenCV 4.x, undistortPoints from 5
    iterate = getattr(cv2, "undistortPointsIter", None)
    if iterate is not None:
        xy = iterate(px.reshape(-1, 1, 2), sensor.camera_matrix, sensor.dist_coeffs, None,
                     None, crit).reshape(-1, 2)
    else:
        xy = cv2.undistortPoints(px.reshape(-1, 1, 2), sensor.camera_matrix,
                                 sensor.dist_coeffs, None, None, None, crit).reshape(-1, 2)
    rays = np.empty((len(xy), 3))
    rays[:, :2] = xy
    rays[:, 2] = 1.0
    # check every 47th sample: every column of samples is visited (47 is a prime that does
    # not divide the sample grid's width, else 53 is used), and every 47th sample of each row
    # (a failure to invert is a region's, at the strongly distorted rim, never one sample's);
    # the check costs 2 % of the rays' time instead of 36 % at every 7th
    step = 47 if (w * s) % 47 else 53
    back, _ = cv2.projectPoints(rays[::step].reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                sensor.camera_matrix, sensor.dist_coeffs)
    err = float(np.abs(back.reshape(-1, 2) - px[::step]).max())
    if not err < RAY_TOLERANCE:
        raise RuntimeError(f"cv2.undistortPoints re-projects within {err:.2g} px only (needed "
                           f"{RAY_TOLERANCE} px): the distortion is too strong to invert here")
    _RAYS.clear()
    _RAYS[key] = rays.reshape(h * s, w * s, 3)
    return _RAYS[key]


@dataclass(frozen=True)
class RenderedGeneralSession:
    """Rendered images of a :class:`GeneralSession`; ``manifest`` is the written manifest's
    path when the images were written to a folder."""

    session: GeneralSession
    options: RenderOptions
    ids: list[str]
    on: list[np.ndarray]
    off: list[np.ndarray]
    manifest: Path | None = None


def default_options() -> RenderOptions:
    """Rendering defaults for the general sensor: 1.2 px stripe, 0.6 px blur, speckle 0.15,
    noise 1.0 grey level; a bright laser that saturates on white squares at the line's
    centre."""
    return RenderOptions(stripe_sigma=1.2, blur_sigma=0.6, laser=200.0, ambient=120.0,
                         noise=1.0, speckle=0.15, speckle_grain=1.0)


def render_general_view(session: GeneralSession, i: int, options: RenderOptions | None = None,
                        rng: np.random.Generator | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The (laser-on, laser-off) 8-bit frames of view ``i``."""
    o = default_options() if options is None else options
    rng = np.random.default_rng([session.seed, i]) if rng is None else rng
    sensor = session.sensor
    rays = pixel_rays(sensor, o.supersample)
    ambient, laser, _ = board_exposures(rays, session.board_from_camera[i], session.board, o,
                                         sensor.laser_plane)
    return finish_frames(ambient, laser, o, rng)


def render_general_session(session: GeneralSession, out_dir: str | os.PathLike | None = None,
                           options: RenderOptions | None = None) -> RenderedGeneralSession:
    """Render every view's laser-on / laser-off frames, optionally writing them.

    With ``out_dir``: ``vNNN_on.png``, ``vNNN_off.png``, ``manifest.json`` (format
    ``hmlvs-images``; each entry has the ``pose`` base_from_hand, the board block only
    rows, cols and square) and ``truth.json`` (the true sensor, the board's pose, the true
    corner pixels and stripe rows), each written atomically, the manifest last. The same
    session and options give byte-identical images (the noise is seeded with the session's
    seed and the view's index).
    """
    o = default_options() if options is None else options
    ids = [f"v{i:03d}" for i in range(len(session))]
    on, off = [], []
    for i in range(len(session)):
        a, b = render_general_view(session, i, o)
        on.append(a)
        off.append(b)
    manifest = None
    if out_dir is not None:
        manifest = _write_general(Path(out_dir), session, ids, on, off, o)
    return RenderedGeneralSession(session, o, ids, on, off, manifest)


def _write_general(out: Path, session: GeneralSession, ids: list[str], on: list[np.ndarray],
                   off: list[np.ndarray], o: RenderOptions) -> Path:
    with atomic_folder(out) as tmp:  # all files or none
        _write_general_files(tmp, session, ids, on, off, o)
    return out / NAME


def _write_general_files(out: Path, session: GeneralSession, ids: list[str],
                         on: list[np.ndarray], off: list[np.ndarray], o: RenderOptions) -> Path:
    b = session.board
    truth = {"sensor": session.sensor.to_dict(), "seed": session.seed,
             "board": {"rows": b.rows, "cols": b.cols, "square": b.square},
             "views": [{"id": pid, "board_from_camera": session.board_from_camera[i].tolist(),
                        "corners": session.corners[i].tolist(),
                        "stripe_v": [None if not np.isfinite(v) else float(v)
                                     for v in session.stripe_v[i]]}
                       for i, pid in enumerate(ids)]}
    with atomic_write(out / "truth.json", "w") as fh:
        json.dump(truth, fh)
    entries = []
    for i, pid in enumerate(ids):
        names = {"on": f"{pid}_on.png", "off": f"{pid}_off.png"}
        write_png(out / names["on"], on[i])
        write_png(out / names["off"], off[i])
        entries.append({"id": pid, **names, "pose": session.base_from_hand[i].tolist()})
    doc = {"format": FORMAT, "version": VERSION, "image_size": list(session.sensor.image_size),
           "board": {"rows": b.rows, "cols": b.cols, "square": b.square},
           "render_options": asdict(o), "poses": entries}
    manifest = out / NAME
    with atomic_write(manifest, "w") as fh:
        json.dump(doc, fh, indent=1)
    return manifest
