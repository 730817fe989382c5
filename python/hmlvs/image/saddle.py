"""Sub-pixel checkerboard corners as saddle points of the image (:func:`saddle_refine`)."""

from __future__ import annotations

import numpy as np

from .._arrays import robust_sigma

#: blur variance (px^2) of the image itself (the pixel's area, 1/12, and a slight optical
#: blur) assumed by the illumination correction of :func:`saddle_refine`; its result
#: changes little with it (on independent renders the same from 1 to 2 times this)
IMAGE_BLUR_VAR = 0.33


#: the largest illumination gradient (|grad log L|, 1/px) the correction takes: 0.5 % per
#: pixel, 10 times a strong vignette's; a larger fitted one is clipped to it
MAX_LIGHT_GRADIENT = 0.005


def saddle_refine(gray: np.ndarray, pts: np.ndarray, spacing: float,
                  illumination: bool = True, parity: np.ndarray | None = None) -> np.ndarray:
    """Corners ``pts`` (k, 2) moved to the saddle point of the Gaussian-smoothed image.

    A checkerboard corner is point-symmetric (opposite quadrants alike, whatever the
    perspective), so the smoothed image is too and its gradient vanishes at the corner. A
    quadratic fitted to a (2h+1)^2 window of the smoothed image, resampled (bilinear) around
    the current estimate, gives its saddle; 8 Newton steps of at most 1 px each. The window
    scales with the corner ``spacing`` (h = 0.12 spacing, 2..4 px; smoothing 0.375 h), so
    with its smoothing it reaches about a fifth of a square. ``cornerSubPix`` aligns the
    gradients over a larger window and is pulled by the blur of perspective-distorted
    edges: measured on independent renders (3 sessions of 16 views, 1 grey level of noise),
    0.022-0.023 px RMS per axis against 0.010-0.012 px for the saddle (0.008-0.010 px with
    the illumination correction below); on OpenCV's real left/right sample images the
    calibration RMS falls from 0.18/0.19 px to 0.17/0.16 px.

    ``illumination``: uneven light (vignetting, a lamp to one side) multiplies the print by
    a smooth L, which breaks the symmetry: to first order in g = grad log L the smoothed
    image gains the gradient (F0 + s2 H) g at the corner (F0 its value there, H its Hessian,
    s2 the smoothing's and the image's blur variance, :data:`IMAGE_BLUR_VAR`), and the
    saddle moves. With 6 or more corners, log F0 is fitted over them (a quadratic in the
    pixel position, linear with fewer than 10 corners; points more than 3 robust standard
    deviations (1.4826 MAD) off dropped once), its gradient taken as g (at most
    :data:`MAX_LIGHT_GRADIENT`), and the saddles are found again with that gradient taken
    out. It needs ``parity`` (k,), the corners' (row + column) on the board
    (``find_corners`` passes it; without it the corners are not corrected): where the
    squares are not square, F0 alternates from corner to corner (by 14 % at 80 degrees) with
    which diagonal is dark, which a fit without a term for it takes for light. Measured on
    independent renders with a 30 % vignette (seed 3, 16 views): 0.0075 -> 0.0047 px RMS per
    axis without noise (0.0040 with no vignette, where it changes nothing); with 1 grey
    level of noise 0.0097 -> 0.0076, 0.0114 -> 0.0097, 0.0097 -> 0.0076 px (seeds 0, 1, 3);
    on OpenCV's real left/right images the calibration RMS does not move (0.1661 / 0.1630 px
    -> 0.1663 / 0.1626 px).

    A corner is left where it was when its fit is no saddle (Hessian not indefinite), does
    not converge, reaches the image border, or would move by more than min(1 px, 0.05
    spacings)."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return pts.copy()
    import cv2
    half = int(np.clip(round(0.12 * spacing), 2, 4))
    f = cv2.GaussianBlur(np.asarray(gray, np.float32), (0, 0), 0.375 * half).astype(float)
    q, value, ok = _saddles(f, pts, spacing, half)
    if not illumination or parity is None:
        return q
    g = _light_gradient(q, value, ok, parity)
    return q if g is None else _saddles(f, pts, spacing, half, g)[0]


def _saddles(f: np.ndarray, pts: np.ndarray, spacing: float, half: int,
             light: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The saddle iteration of :func:`saddle_refine` from ``pts`` on the smoothed image
    ``f`` (window half-width ``half``), with the illumination gradient ``light`` (k, 2)
    (grad log L, 1/px) taken out if given: (the refined corners, the smoothed image's value
    at each, which of them converged)."""
    s2 = (0.375 * half) ** 2 + IMAGE_BLUR_VAR
    h, w = f.shape
    ys, xs = np.mgrid[-half:half + 1, -half:half + 1].astype(float)
    x, y = xs.ravel(), ys.ravel()
    wt = np.exp(-0.5 * (x * x + y * y) / (0.5 * half) ** 2)
    design = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1) * wt[:, None]
    fit = np.linalg.pinv(design) * wt[None, :]  # (6, K): coefficients from grey values
    q = pts.copy()
    step = np.full(len(q), np.inf)
    ok = np.ones(len(q), bool)
    value = np.full(len(q), np.nan)
    for _ in range(8):
        sx, sy = q[:, :1] + x, q[:, 1:] + y
        x0, y0 = np.floor(sx), np.floor(sy)
        inside = ((x0 >= 0) & (x0 <= w - 2) & (y0 >= 0) & (y0 <= h - 2)).all(axis=1)
        ok &= inside
        ix = np.clip(x0, 0, w - 2).astype(int)
        iy = np.clip(y0, 0, h - 2).astype(int)
        fx, fy = sx - x0, sy - y0
        z = ((1 - fx) * (1 - fy) * f[iy, ix] + fx * (1 - fy) * f[iy, ix + 1] +
             (1 - fx) * fy * f[iy + 1, ix] + fx * fy * f[iy + 1, ix + 1])
        c = z @ fit.T
        value = c[:, 5]
        if light is not None:  # the light's share of the gradient: (F0 + s2 H) g
            c[:, 3] -= c[:, 5] * light[:, 0] + s2 * (2 * c[:, 0] * light[:, 0] +
                                                      c[:, 1] * light[:, 1])
            c[:, 4] -= c[:, 5] * light[:, 1] + s2 * (c[:, 1] * light[:, 0] +
                                                      2 * c[:, 2] * light[:, 1])
        det = 4.0 * c[:, 0] * c[:, 2] - c[:, 1] ** 2
        ok &= det < 0
        safe = np.where(det < 0, det, -1.0)
        d = np.stack([-(2 * c[:, 2] * c[:, 3] - c[:, 1] * c[:, 4]),
                      -(2 * c[:, 0] * c[:, 4] - c[:, 1] * c[:, 3])], axis=1) / safe[:, None]
        d = np.clip(np.where(ok[:, None], d, 0.0), -1.0, 1.0)
        q += d
        step = np.abs(d).max(axis=1)
    ok &= (step < 1e-3) & (np.linalg.norm(q - pts, axis=1) < min(1.0, 0.05 * spacing))
    return np.where(ok[:, None], q, pts), value, ok


def _light_gradient(px: np.ndarray, value: np.ndarray, ok: np.ndarray,
                    parity: np.ndarray) -> np.ndarray | None:
    """grad log L (k, 2) at corners ``px`` from the smoothed image's ``value`` at those that
    converged (``ok``): log value fitted by a quadratic in the pixel position (linear with
    fewer than 10 corners, None with fewer than 6), refitted once without the points more
    than 3 robust standard deviations off, the gradient clipped to :data:`MAX_LIGHT_GRADIENT`."""
    good = ok & np.isfinite(value) & (value > 0)
    if good.sum() < 6:
        return None
    centre = px[good].mean(axis=0)
    scale = max(float(px[good].std()), 1.0)
    quadratic = good.sum() >= 10

    def terms(p: np.ndarray) -> np.ndarray:
        u, v = ((p - centre) / scale).T
        return np.stack([np.ones_like(u), u, v] + ([u * u, u * v, v * v] if quadratic else []),
                        axis=1)

    a, b = terms(px[good]), np.log(value[good])
    # which diagonal is dark: the value differs unless the squares are square
    a = np.hstack([a, np.where(np.asarray(parity)[good] % 2 == 0, 1.0, -1.0)[:, None]])
    coef = np.linalg.lstsq(a, b, rcond=None)[0]
    r = b - a @ coef
    keep = np.abs(r - np.median(r)) <= 3.0 * max(robust_sigma(r), 1.4826e-6)
    if keep.sum() >= a.shape[1] + 2:
        coef = np.linalg.lstsq(a[keep], b[keep], rcond=None)[0]
    u, v = ((px - centre) / scale).T
    g = np.stack([coef[1] + (2 * coef[3] * u + coef[4] * v if quadratic else 0.0 * u),
                  coef[2] + (coef[4] * u + 2 * coef[5] * v if quadratic else 0.0 * v)],
                 axis=1) / scale
    norm = np.linalg.norm(g, axis=1, keepdims=True)
    return g * np.minimum(1.0, MAX_LIGHT_GRADIENT / np.maximum(norm, 1e-12))
