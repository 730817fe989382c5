"""The Blaser scorer's own stripe extractor (score.py): per image column the red laser's peak,
kept where it is locally consistent and on one smooth curve. It knows nothing of any
calibration nor of hmlvs' own extractor."""

from __future__ import annotations

import cv2
import numpy as np

# all pixel sizes scale with width / 640
RED_SATURATION = (200.0, 240.0)  # red ramps from "not saturated" to "saturated" over this
BLUR_SIGMA_PX = 1.0  # Gaussian smoothing of the feature image (speckle)
MIN_PEAK = 30.0  # a column's peak must stand this far above the column's median ...
NOISE_FACTOR = 6.0  # ... and this many robust sigmas (1.4826 MAD) of the column
NEIGHBOUR_HALF_WIDTH_PX = 10  # local continuity: neighbours within this many columns ...
MIN_NEIGHBOURS = 3  # ... at least this many of them ...
LOCAL_TOLERANCE_PX = 3.0  # ... and within this of their median row
CURVE_DEGREE = 3  # the stripe's smooth curve v(u) (a line bent by lens distortion)
CURVE_TOLERANCES_PX = (16.0, 8.0, 4.0)  # robust fit: drop points farther than these, in turn
CURVE_FINAL_SIGMAS = 4.0  # finally: farther than max(last tolerance / 2, this x robust sigma)
MIN_STRIPE_POINTS = 20  # fewer consistent points: no stripe in the view


def laser_feature(bgr: np.ndarray) -> np.ndarray:
    """The laser's strength per pixel (float32): red minus the mean of green and blue.

    Where red saturates, the laser's excess spills into green and blue (the stripe's core
    turns white), so there green and blue count for the laser instead of against it: their
    sign turns from - to + as red ramps over RED_SATURATION. Smoothed against speckle.
    """
    b, g, r = (bgr[:, :, i].astype(np.float32) for i in range(3))
    other = 0.5 * (g + b)
    lo, hi = RED_SATURATION
    saturated = np.clip((r - lo) / (hi - lo), 0.0, 1.0)
    feature = r - other + 2.0 * saturated * other
    sigma = BLUR_SIGMA_PX * bgr.shape[1] / 640.0
    return cv2.GaussianBlur(feature, (0, 0), sigma)


def column_peak(col: np.ndarray, background: float, peak_row: int) -> float | None:
    """Sub-pixel row of the peak at `peak_row`: the centroid, weighted by the height above the
    half-height level, of the contiguous run above that level around the maximum. None when
    the run touches the image's top or bottom (the stripe is cut off, its centre unknown)."""
    level = background + 0.5 * (float(col[peak_row]) - background)
    j0 = j1 = peak_row
    while j0 > 0 and col[j0 - 1] > level:
        j0 -= 1
    while j1 < col.size - 1 and col[j1 + 1] > level:
        j1 += 1
    if j0 == 0 or j1 == col.size - 1:
        return None
    weights = col[j0:j1 + 1] - level
    return float(np.sum(weights * np.arange(j0, j1 + 1)) / np.sum(weights))


def column_candidates(feature: np.ndarray) -> np.ndarray:
    """(u, v, height) per column whose peak stands out: peak - median > max(MIN_PEAK,
    NOISE_FACTOR x 1.4826 MAD of the column)."""
    background = np.median(feature, axis=0)
    noise = 1.4826 * np.median(np.abs(feature - background), axis=0)
    rows = np.argmax(feature, axis=0)
    cols = np.arange(feature.shape[1])
    height = feature[rows, cols] - background
    out = []
    for u in np.flatnonzero(height > np.maximum(MIN_PEAK, NOISE_FACTOR * noise)):
        v = column_peak(feature[:, u], float(background[u]), int(rows[u]))
        if v is not None:
            out.append((float(u), v, float(height[u])))
    return np.array(out, dtype=float).reshape(-1, 3)


def locally_consistent(u: np.ndarray, v: np.ndarray, scale: float) -> np.ndarray:
    """Points with at least MIN_NEIGHBOURS others within NEIGHBOUR_HALF_WIDTH_PX columns whose
    median row is within LOCAL_TOLERANCE_PX (isolated spikes and specks fail)."""
    half = max(1, int(round(NEIGHBOUR_HALF_WIDTH_PX * scale)))
    keep = np.zeros(u.size, bool)
    for i in range(u.size):
        near = (np.abs(u - u[i]) <= half) & (np.arange(u.size) != i)
        if near.sum() >= MIN_NEIGHBOURS:
            keep[i] = abs(v[i] - float(np.median(v[near]))) <= LOCAL_TOLERANCE_PX * scale
    return keep


def on_smooth_curve(u: np.ndarray, v: np.ndarray, height: np.ndarray, scale: float
                    ) -> np.ndarray:
    """Points on the stripe's smooth curve: a cubic v(u), weighted by the peaks' heights,
    fitted again and again dropping the points farther than a shrinking tolerance."""
    keep = np.ones(u.size, bool)
    tolerances = [t * scale for t in CURVE_TOLERANCES_PX]
    for k in range(len(tolerances) + 1):
        if keep.sum() <= CURVE_DEGREE + 1:
            return np.zeros(u.size, bool)
        coef = np.polyfit(u[keep], v[keep], CURVE_DEGREE, w=np.sqrt(height[keep]))
        res = v - np.polyval(coef, u)
        if k < len(tolerances):
            tol = tolerances[k]
        else:
            sigma = 1.4826 * float(np.median(np.abs(res[keep])))
            tol = max(0.5 * tolerances[-1], CURVE_FINAL_SIGMAS * sigma)
        keep = np.abs(res) <= tol
    return keep


def extract_stripe(bgr: np.ndarray) -> np.ndarray:
    """The laser stripe's centre, at most one (u, v) per image column, sub-pixel in v; an
    empty (0, 2) array when there are fewer than MIN_STRIPE_POINTS."""
    scale = bgr.shape[1] / 640.0
    cand = column_candidates(laser_feature(bgr))
    if cand.shape[0] < MIN_STRIPE_POINTS:
        return np.empty((0, 2))
    u, v, height = cand.T
    keep = locally_consistent(u, v, scale)
    if keep.sum() < MIN_STRIPE_POINTS:
        return np.empty((0, 2))
    u, v, height = u[keep], v[keep], height[keep]
    keep = on_smooth_curve(u, v, height, scale)
    if keep.sum() < MIN_STRIPE_POINTS:
        return np.empty((0, 2))
    return np.c_[u[keep], v[keep]]


# ------------------------------------------------------------------ board corners
