"""The saddle-point corner refinement (``hmlvs.image.saddle.saddle_refine``) on synthetic
X-junctions whose corner is known exactly."""

from __future__ import annotations

import cv2
from hmlvs.image.corner_base import refine_subpix
from hmlvs.image.saddle import saddle_refine
import numpy as np
import pytest


def _junction(centre: tuple[float, float], angles: tuple[float, float], size: int = 64,
              blur: float = 0.8, ss: int = 8, period: float | None = None,
              light=None) -> np.ndarray:
    """An 8-bit X-junction: two straight edges through ``centre`` at ``angles`` (rad), dark
    and light quadrants (40 / 200), area-integrated over ``ss`` x ``ss`` samples a pixel
    (pixel centres at integers), then a Gaussian blur of ``blur`` px. With ``period`` a
    skewed checkerboard: edges every ``period`` px along both directions. ``light(u, v)``:
    the illumination multiplying the print."""
    off = (np.arange(ss) + 0.5) / ss - 0.5
    v, u = np.mgrid[0:size * ss, 0:size * ss] / ss
    u, v = u + off[0], v + off[0]
    x, y = u - centre[0], v - centre[1]
    s1 = np.sin(angles[0]) * x - np.cos(angles[0]) * y
    s2 = np.sin(angles[1]) * x - np.cos(angles[1]) * y
    if period is not None:
        s1, s2 = np.sin(np.pi * s1 / period), np.sin(np.pi * s2 / period)
    img = np.where(s1 * s2 > 0, 40.0, 200.0)
    if light is not None:
        img = img * light(u, v)
    img = img.reshape(size, ss, size, ss).mean(axis=(1, 3))
    return np.rint(cv2.GaussianBlur(img, (0, 0), blur)).astype(np.uint8)


@pytest.mark.parametrize("angles", [(0.35, 1.75), (-0.6, 0.5), (1.2, 2.9)])
def test_the_saddle_of_a_skewed_junction_is_its_corner(angles):
    """Edges 80 degrees, 63 degrees and 97 degrees apart, from starts up to 0.6 px off.
    Measured: within 0.007-0.010 px of the true corner, cornerSubPix (8 px half-window)
    within 0.025-0.030 px. What is left is the sampling of a 0.8 px blur (about 4 % of its
    spectrum lies past the Nyquist frequency): it moves with the corner's sub-pixel phase
    and does not fall with finer interpolation (bicubic gave the same)."""
    rng = np.random.default_rng(3)
    for _ in range(4):
        c = np.array([31.0, 30.0]) + rng.uniform(-0.5, 0.5, 2)
        img = _junction(tuple(c), angles)
        start = c + rng.uniform(-0.6, 0.6, 2)
        got = saddle_refine(img, start[None], spacing=40.0)[0]
        classic = refine_subpix(img, start[None], 8)[0]
        assert np.linalg.norm(got - c) < 0.015, (got, c)
        assert np.linalg.norm(got - c) < 0.6 * np.linalg.norm(classic - c)


def test_what_is_no_saddle_stays_where_it_was():
    """A flat patch, a straight edge and a point at the border are returned unchanged, and
    no points give no points."""
    flat = np.full((48, 48), 120, np.uint8)
    edge = np.where(np.arange(48)[None, :] + 0 * np.arange(48)[:, None] < 24.3, 40, 200
                    ).astype(np.uint8)
    pts = np.array([[20.2, 22.7], [3.4, 1.0]])
    for img in (flat, edge):
        np.testing.assert_array_equal(saddle_refine(img, pts, spacing=40.0), pts)
    assert saddle_refine(flat, np.empty((0, 2)), spacing=40.0).shape == (0, 2)
    # a junction too close to the border for the window keeps its start
    img = _junction((2.2, 30.0), (0.35, 1.75))
    start = np.array([[2.5, 30.3]])
    np.testing.assert_array_equal(saddle_refine(img, start, spacing=40.0), start)


def test_a_small_board_gets_a_small_window():
    """A skewed checkerboard with edges every 12 px (corners ~12-13 px apart: window
    half-size 2 px, smoothing 0.75 px, so the neighbouring corners stay out of it), blur
    0.6 px. Measured: 0.008-0.027 px from the corner, cornerSubPix (2 px half-window)
    0.028-0.059 px."""
    rng = np.random.default_rng(5)
    for _ in range(4):
        c = np.array([20.0, 20.0]) + rng.uniform(-0.5, 0.5, 2)
        img = _junction(tuple(c), (0.3, 1.8), size=40, blur=0.6, period=12.0)
        start = c + rng.uniform(-0.5, 0.5, 2)
        got = saddle_refine(img, start[None], spacing=12.0)[0]
        assert np.linalg.norm(got - c) < 0.05, (got, c)
        assert np.linalg.norm(got - c) < np.linalg.norm(refine_subpix(img, start[None], 2)[0] - c)


def _grid(centre: np.ndarray, angles: tuple[float, float], period: float, size: int,
          margin: float) -> tuple[np.ndarray, np.ndarray]:
    """The corners of :func:`_junction`'s skewed checkerboard at least ``margin`` px inside
    the image, and their parity (which diagonal is dark)."""
    m = np.array([[np.sin(a), -np.cos(a)] for a in angles])
    pts, parity = [], []
    for k in range(-8, 9):
        for n in range(-8, 9):
            p = np.linalg.solve(m, [k * period, n * period]) + centre
            if (p >= margin).all() and (p <= size - 1 - margin).all():
                pts.append(p)
                parity.append((k + n) % 2)
    return np.array(pts), np.array(parity)


@pytest.mark.parametrize("centre", [(80.3, 79.6), (81.1, 78.45), (79.7, 80.2)])
def test_uneven_light_is_taken_out_of_the_saddles(centre):
    """A vignette (30 % darker at the corner of a 640 x 480 image; this is its top-left
    160 x 160 px) tilts the smoothed image at every corner and moves its saddle. Measured
    on the 19-20 corners of an 80 degree skewed board: 0.0092-0.0164 px RMS from the truth
    without the correction, 0.0056-0.0057 with it (0.0049-0.0055 unlit). On the unlit
    board the correction moves the corners by less than 0.001 px RMS: the parity term
    takes the alternating value of the non-square corners, which a fit without it took for
    light (then 0.0073-0.0119 px); so without the parity nothing is corrected."""
    size, period, angles = 160, 30.0, (0.35, 1.75)
    c = np.array(centre)
    truth, parity = _grid(c, angles, period, size, 12.0)
    assert len(truth) >= 19

    def vignette(u, v):
        return 1.0 - 0.3 * ((u - 320) ** 2 + (v - 240) ** 2) / (320 ** 2 + 240 ** 2)

    lit = _junction(tuple(c), angles, size=size, period=period, light=vignette)
    unlit = _junction(tuple(c), angles, size=size, period=period)
    start = truth + np.random.default_rng(0).uniform(-0.3, 0.3, truth.shape)

    def rms(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.sqrt(np.mean((a - b) ** 2)))

    plain = saddle_refine(lit, start, period, illumination=False, parity=parity)
    corrected = saddle_refine(lit, start, period, parity=parity)
    assert rms(corrected, truth) < 0.7 * rms(plain, truth)
    assert rms(corrected, truth) < 0.008
    unlit_plain = saddle_refine(unlit, start, period, illumination=False)
    assert rms(saddle_refine(unlit, start, period, parity=parity), unlit_plain) < 0.002
    # without the parity there is no correction (a fit without it made these 0.0073-0.0119)
    np.testing.assert_array_equal(saddle_refine(lit, start, period), plain)
