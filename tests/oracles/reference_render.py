"""The NumPy shading of the board that ``hmlvs.sim.render`` ran before the C++ core's
``ShadeBoard`` (``hmlvs._core._shade_board``): the reference of the parity test
(``tests/parity/test_render_shading.py``) and of the render row of ``make bench``."""

from __future__ import annotations

from typing import Any

from hmlvs.sim.scene import _soft_sign  # the cubic ramp across an edge
import numpy as np


def albedo(x: np.ndarray, y: np.ndarray, gx: np.ndarray, gy: np.ndarray,
           board: Any, o: Any) -> np.ndarray:
    """Albedo at board coordinates (x, y) mm, edges pre-smoothed analytically.

    ``gx``, ``gy`` are |grad x| and |grad y| in mm per pixel, so that every edge is smoothed
    over +-1.5/supersample px: the supersamples then integrate the pixel area without the
    aliasing that makes point-sampled squares bias corner positions by ~0.1 px.
    """
    sq = board.square
    width = 1.5 / o.supersample

    def soft_sign(c: np.ndarray, g: np.ndarray) -> np.ndarray:
        # (-1)^floor(c/sq) smoothed across the lines c = n * sq
        k = np.floor(c / sq)
        f = c / sq - k
        dist = sq * np.minimum(f, 1.0 - f) / g
        return np.where(k % 2 == 0, 1.0, -1.0) * _soft_sign(dist, width)

    def inside(c: np.ndarray, g: np.ndarray, lo: float, hi: float) -> np.ndarray:
        return (0.25 * (1.0 + _soft_sign((c - lo) / g, width))
                * (1.0 + _soft_sign((hi - c) / g, width)))

    black = 0.5 + 0.5 * soft_sign(x, gx) * soft_sign(y, gy)
    pattern = inside(x, gx, -sq, board.rows * sq) * inside(y, gy, -sq, board.cols * sq)
    m = o.margin * sq
    on_board = inside(x, gx, -sq - m, board.rows * sq + m) * \
        inside(y, gy, -sq - m, board.cols * sq + m)
    white_part = o.table + (o.white - o.table) * on_board
    return white_part + (o.black - o.white) * black * pattern


def board_exposures(rays: np.ndarray, bfc: np.ndarray, board: Any, o: Any,
                    laser_distance: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ambient and laser exposure (h, w) of the board plane, and the laser-plane distance
    (mm) at the pixel centres (NaN where a ray misses the plane).

    ``rays`` (h*s, w*s, 3) are the camera rays of the supersample positions (s =
    ``o.supersample``, the centre sample of each pixel at its integer position), ``bfc`` the
    4x4 board_from_camera transform and ``laser_distance`` maps camera-frame points (..., 3)
    to their signed distance (mm) from the laser plane. The sensor model enters only through
    these two, so any camera model renders with the same shading.
    """
    s = o.supersample
    h, w = rays.shape[0] // s, rays.shape[1] // s
    ambient = np.empty((h, w))
    laser = np.empty((h, w))
    d_centres = np.empty((h, w))
    u_sub = ((np.arange(w * s) + 0.5) / s - 0.5)
    chunk = 40  # pixel rows per block, to bound memory
    for r0 in range(0, h, chunk):
        r1 = min(h, r0 + chunk)
        ray = rays[r0 * s:r1 * s]
        rb = ray @ bfc[:3, :3].T
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -bfc[2, 3] / rb[..., 2]
        hit = np.isfinite(t) & (t > 0)
        t = np.where(hit, t, np.nan)
        x = bfc[0, 3] + t * rb[..., 0]
        y = bfc[1, 3] + t * rb[..., 1]
        gxv, gxu = np.gradient(x, 1.0 / s)
        gyv, gyu = np.gradient(y, 1.0 / s)
        with np.errstate(invalid="ignore"):
            alb = albedo(np.nan_to_num(x), np.nan_to_num(y),
                         np.nan_to_num(np.hypot(gxu, gxv), nan=1.0),
                         np.nan_to_num(np.hypot(gyu, gyv), nan=1.0), board, o)
        alb = np.where(hit, alb, 0.0)
        d = laser_distance(ray * t[..., None])
        # distance to the stripe curve in pixels: d (mm) over its gradient (mm per px)
        gv, gu = np.gradient(d, 1.0 / s)
        dpx = d / np.hypot(gu, gv)
        prof = np.exp(-0.5 * (dpx / o.stripe_sigma) ** 2)
        if o.spurious > 0:
            lo, hi = o.spurious_columns
            inside = (u_sub >= lo * w) & (u_sub <= hi * w)
            prof = prof + o.spurious * inside[None, :] * np.exp(
                -0.5 * ((dpx - o.spurious_offset) / o.stripe_sigma) ** 2)
        lz = np.nan_to_num(o.laser * alb * prof)
        az = o.ambient * alb
        ambient[r0:r1] = az.reshape(r1 - r0, s, w, s).mean(axis=(1, 3))
        laser[r0:r1] = lz.reshape(r1 - r0, s, w, s).mean(axis=(1, 3))
        d_centres[r0:r1] = d[s // 2::s, s // 2::s]
    return ambient, laser, d_centres


def board_exposures_of_plane(rays: np.ndarray, bfc: np.ndarray, board: Any, o: Any,
                             plane: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`board_exposures` called as ``hmlvs.sim.render.board_exposures`` is: the laser
    plane as (a, b, c, d), ``a x + b y + c z + d`` the signed distance (mm)."""
    return board_exposures(rays, bfc, board, o, lambda cam: cam @ plane[:3] + plane[3])
