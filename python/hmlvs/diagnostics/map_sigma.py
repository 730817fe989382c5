"""The predicted 3D uncertainty (mm) of the points a general-model calibration measures.

The joint solve's covariance (intrinsics, distortion, laser plane, hand-eye transform; the
board's pose does not enter a measurement) and the stripe's own pixel noise are carried to
the 3D points of the stripe pixels the calibration saw (the laser line's image footprint
over the working range of the session) by numerical Jacobians (central differences in the
solve's own tangent coordinates):

    Sigma_p = J_theta Cov J_theta^T + sigma_v^2 J_v J_v^T

and summarised as the RMS and the 95th percentile of sqrt(trace Sigma_p). With robot poses
the points are taken in the flange frame (their distance to the truth does not depend on
the robot pose); without, in the camera frame.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

#: stripe pixels sampled over the footprint (enough for a stable 95th percentile)
SAMPLES = 600


def _householder_tangent(n: np.ndarray) -> np.ndarray:
    """d(n [+] delta)/d delta of Ceres' SphereManifold<3> at ``n`` (3 x 2): half the first
    two columns of the Householder matrix that maps n to the last axis, times |n|
    (ceres/internal/sphere_manifold_functions.h)."""
    x = np.asarray(n, float)
    sigma = float(x[:2] @ x[:2])
    v = x.copy()
    v[2] = 1.0
    beta = 0.0
    pivot = x[2]
    if sigma <= np.finfo(float).eps:
        beta = 2.0 if pivot < 0 else 0.0
    else:
        mu = math.sqrt(pivot * pivot + sigma)
        vp = pivot - mu if pivot <= 0 else -sigma / (pivot + mu)
        beta = 2.0 * vp * vp / (sigma + vp * vp)
        v[:2] /= vp
    h = np.eye(3) - beta * np.outer(v, v)
    return 0.5 * np.linalg.norm(x) * h[:, :2]


def _rodrigues(w: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(w, float).reshape(3, 1))[0]


_INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _perturbed(sensor: Any, names: Sequence[str], delta: np.ndarray) -> Any:
    """The sensor moved by ``delta`` along the solve's unknowns ``names`` (tangent
    coordinates: rotations as rotation vectors applied on the left, i.e. in the hand frame;
    the plane normal by Ceres' sphere manifold; the rest additive)."""
    from ..models.opencv import OpenCvSensor

    intr = sensor.intrinsics_vector().astype(float)
    hfc = np.array(sensor.hand_from_camera, float)
    plane = np.array(sensor.laser_plane, float)
    rot = np.zeros(3)
    nt = np.zeros(2)
    for name, d in zip(names, delta):
        if d == 0.0:
            continue
        if name in _INTRINSICS:
            intr[_INTRINSICS.index(name)] += d
        elif name.startswith("hand_r"):
            rot["xyz".index(name[-1])] += d
        elif name.startswith("hand_t"):
            hfc[:3, 3]["xyz".index(name[-1])] += d
        elif name in ("plane_n1", "plane_n2"):
            nt[int(name[-1]) - 1] += d
        elif name == "plane_d":
            plane[3] += d
    if rot.any():
        hfc[:3, :3] = _rodrigues(rot) @ hfc[:3, :3]
    if nt.any():
        n = plane[:3] + _householder_tangent(plane[:3]) @ nt
        plane[:3] = n / np.linalg.norm(n)
    k = np.array([[intr[0], 0.0, intr[2]], [0.0, intr[1], intr[3]], [0.0, 0.0, 1.0]])
    return OpenCvSensor(k, intr[4:], sensor.image_size, plane, hfc, sensor.base_from_board)


def _points(sensor: Any, px: np.ndarray, chain: bool) -> np.ndarray:
    pts, valid = sensor.points_in_camera(px, on_invalid="mask")
    pts = np.where(valid[:, None], pts, np.nan)
    if chain:
        h = sensor.hand_from_camera
        pts = pts @ h[:3, :3].T + h[:3, 3]
    return pts


def footprint(result: Any, samples: int = SAMPLES, seed: int = 0) -> np.ndarray:
    """Stripe pixels of the calibration's views (those its solve used), at most ``samples``
    of them drawn evenly: the laser line's image footprint over the session's working
    range."""
    sets = [r["laser_pixels"] for r in result.residuals.values() if len(r["laser_pixels"])]
    px = np.concatenate(sets) if sets else np.empty((0, 2))
    if len(px) > samples:
        px = px[np.random.default_rng(seed).choice(len(px), samples, replace=False)]
    return np.ascontiguousarray(px, float)


def point_sigmas(result: Any, pixels: np.ndarray, stripe_sigma_px: float) -> np.ndarray:
    """Predicted 3D standard deviation (mm, sqrt of the covariance's trace) of the points of
    ``pixels`` measured with ``result``'s sensor."""
    sensor = result.sensor
    chain = result.mode == "chain"
    names = list(result.names)
    cov = np.asarray(result.covariance, float)
    relevant = [k for k, n in enumerate(names) if n in _INTRINSICS or n.startswith("hand_")
                and chain or n.startswith("plane_")]
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    jac = np.zeros((len(pixels), 3, len(relevant)))
    for col, k in enumerate(relevant):
        h = max(std[k], 1e-9) * 1e-2
        d = np.zeros(len(names))
        d[k] = h
        plus = _points(_perturbed(sensor, names, d), pixels, chain)
        minus = _points(_perturbed(sensor, names, -d), pixels, chain)
        jac[:, :, col] = (plus - minus) / (2 * h)
    c = cov[np.ix_(relevant, relevant)]
    var = np.einsum("nij,jk,nik->n", jac, c, jac)
    if stripe_sigma_px > 0:
        dv = np.array([0.0, 0.5])
        jv = (_points(sensor, pixels + dv, chain) - _points(sensor, pixels - dv, chain))
        var = var + stripe_sigma_px**2 * np.sum(jv**2, axis=1)
    return np.sqrt(np.clip(var, 0, None))


def predicted_map(result: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """The footprint's pixels (k, 2) and their predicted 3D standard deviations (k, mm), the
    stripe noise measured from the stripes themselves
    (:func:`hmlvs.diagnostics.verdict.stripe_noise_px`); None without stripe pixels."""
    from .verdict import stripe_noise_px

    px = footprint(result)
    if len(px) == 0:
        return None
    sets = [r["laser_pixels"] for r in result.residuals.values()]
    sig = stripe_noise_px(sets)
    s = point_sigmas(result, px, sig if math.isfinite(sig) else 0.0)
    ok = np.isfinite(s)
    return (px[ok], s[ok]) if ok.any() else None


def summary(sigmas: np.ndarray) -> dict[str, float]:
    """{"rms", "p95"} of predicted standard deviations (mm)."""
    return {"rms": float(np.sqrt(np.mean(sigmas**2))), "p95": float(np.percentile(sigmas, 95))}


def map_sigma_mm(result: Any, views: Sequence[Any] | None = None) -> dict[str, float] | None:
    """{"rms", "p95"}: the predicted 3D uncertainty (mm) over the laser line's image
    footprint (:func:`predicted_map`); None without stripe pixels."""
    m = predicted_map(result)
    return None if m is None else summary(m[1])
