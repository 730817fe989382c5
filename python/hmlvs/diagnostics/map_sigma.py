"""The predicted 3D uncertainty (mm) of the points a calibration measures, for either model.

A calibration maps a stripe pixel to a 3D point through its parameters; :class:`PointModel`
is that mapping with the parameters' covariance, written once for both models
(:func:`of_joint` for the general model's joint solve, :func:`of_paper` for the paper's 14
parameters). The covariance (intrinsics, distortion, laser plane, hand-eye transform; the
board's pose does not enter a measurement) and the stripe's own pixel noise are carried to
the 3D points of the stripe pixels the calibration saw (the laser line's image footprint
over the working range of the session) by numerical Jacobians (central differences in the
parameters' tangent coordinates: rotations as rotation vectors):

    Sigma_p = J_theta Cov J_theta^T + sigma_v^2 J_v J_v^T

and summarised as the RMS and the 95th percentile of sqrt(trace Sigma_p). With robot poses
the points are taken in the flange frame (their distance to the truth does not depend on
the robot pose); without, in the camera frame. A point measured in the base frame also
carries its robot pose's error: with robot poses the map adds it
(``PointModel.pose_sigma_mm``, from how far the views' own board poses, carried through
their robot poses, land from the one board: :func:`hmlvs.diagnostics.checks.pose_error_mm`).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Callable, Sequence

import numpy as np

from ..geometry.transforms import rotation_from_vector, rotation_to_vector
from ..models.opencv import INTRINSIC_NAMES

#: stripe pixels sampled over the footprint (enough for a stable 95th percentile)
SAMPLES = 600


@dataclass
class PointModel:
    """A calibration as a mapping of stripe pixels to 3D points with its uncertainty.

    points : (delta, pixels (k, 2)) -> (k, 3) points (mm; the flange frame when ``chain``,
        else the camera frame) with the parameters moved by ``delta`` (tangent coordinates,
        the order of ``names``); NaN rows where a ray misses the laser plane
    names, covariance : the parameters that enter a measurement and their covariance
    pixel_sets : the stripe pixels the calibration used, one array per view
    stripe_sigma_px : the stripe's own noise across the stripe (px): the RMS of each view's
        rows about a smooth curve, pooled (poor views and tails count, as they count in the
        RMS error of measured points)
    chain : whether the points are in the flange frame (robot poses)
    pose_sigma_mm : the robot's pose error carried to the measured points (mm RMS, 3D),
        added to the map: a point measured in the base frame carries its robot pose's
        error besides the calibration's (0: exact poses, or none)
    """

    points: Callable[[np.ndarray, np.ndarray], np.ndarray]
    names: list[str]
    covariance: np.ndarray
    pixel_sets: list[np.ndarray]
    stripe_sigma_px: float
    chain: bool
    pose_sigma_mm: float = 0.0

    def at(self, pixels: np.ndarray) -> np.ndarray:
        """The calibration's own points of ``pixels`` (no perturbation)."""
        return self.points(np.zeros(len(self.names)), pixels)


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
        if name in INTRINSIC_NAMES:
            intr[INTRINSIC_NAMES.index(name)] += d
        elif name.startswith("hand_r"):
            rot["xyz".index(name[-1])] += d
        elif name.startswith("hand_t"):
            hfc[:3, 3]["xyz".index(name[-1])] += d
        elif name in ("plane_n1", "plane_n2"):
            nt[int(name[-1]) - 1] += d
        elif name == "plane_d":
            plane[3] += d
    if rot.any():
        hfc[:3, :3] = rotation_from_vector(rot) @ hfc[:3, :3]
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


def of_joint(result: Any) -> PointModel:
    """The point model of a general-model calibration (``calibrate_joint``'s result): the
    intrinsics, distortion, laser plane and (chain mode) hand-eye unknowns of its solve."""
    from .checks import stripe_noise_px

    chain = result.mode == "chain"
    names = list(result.names)
    keep = [k for k, n in enumerate(names) if n in INTRINSIC_NAMES or n.startswith("plane_")
            or (chain and n.startswith("hand_"))]
    sub = [names[k] for k in keep]
    sensor = result.sensor

    def points(delta: np.ndarray, px: np.ndarray) -> np.ndarray:
        moved = _perturbed(sensor, sub, delta) if np.any(delta) else sensor
        return _points(moved, px, chain)

    sets = [r["laser_pixels"] for r in result.residuals.values() if len(r["laser_pixels"])]
    sig = stripe_noise_px(sets, robust=False)
    return PointModel(points, sub, np.asarray(result.covariance, float)[np.ix_(keep, keep)],
                      sets, sig if math.isfinite(sig) else 0.0, chain)


_EULER = ("omega", "phi", "varphi")


def _euler_torotation_to_vector(q: np.ndarray, which: Sequence[str]) -> np.ndarray:
    """(3, len(which)) d(rotation vector)/d(Euler angles ``which``) of hand_from_camera's
    rotation at the parameters ``q``, the rotation vector applied on the left (hand frame):
    R(q + d) = exp([B d]x) R(q). Central differences of 1e-6 rad."""
    from ..models.paper import hand_from_camera
    from ..models.params import NAMES

    r0 = hand_from_camera(q)[:3, :3]
    out = np.zeros((3, len(which)))
    for col, n in enumerate(which):
        d = np.zeros(len(q))
        d[NAMES.index(n)] = 1e-6
        plus = rotation_to_vector(hand_from_camera(q + d)[:3, :3] @ r0.T)
        minus = rotation_to_vector(hand_from_camera(q - d)[:3, :3] @ r0.T)
        out[:, col] = (plus - minus) / 2e-6
    return out


def of_paper(result: Any, dataset: Any) -> PointModel | None:
    """The point model of a paper-model calibration (:class:`CalibrationResult` and the
    data set it was fitted to): its free parameters' covariance
    (:attr:`CalibrationResult.uncertainty`) with the Euler angles turned into a rotation
    vector of hand_from_camera (well defined at the ZYZ gimbal lock, where omega and varphi
    are not one by one); the stripe noise from the points' pixels per pose, else the
    uncertainty analysis' pixel noise. Points in the flange frame. None without an
    uncertainty analysis."""
    from ..models.paper import hand_from_camera, points_in_camera
    from ..models.params import NAMES
    from .checks import stripe_noise_px

    unc = getattr(result, "uncertainty", None)
    if unc is None:
        return None
    q = result.params.to_array().astype(float)
    free = list(unc.free)
    euler = [n for n in free if n in _EULER]
    plain = [n for n in free if n not in _EULER]
    t = np.zeros((len(plain) + (3 if euler else 0), len(free)))
    for row, n in enumerate(plain):
        t[row, free.index(n)] = 1.0
    if euler:
        t[len(plain):, [free.index(n) for n in euler]] = _euler_torotation_to_vector(q, euler)
    cov = t @ np.asarray(unc.covariance, float) @ t.T
    names = plain + (["hand_rx", "hand_ry", "hand_rz"] if euler else [])
    idx = [NAMES.index(n) for n in plain]
    hfc = hand_from_camera(q)

    def points(delta: np.ndarray, px: np.ndarray) -> np.ndarray:
        qq = q.copy()
        qq[idx] += delta[:len(plain)]
        try:
            pts, ok = points_in_camera(qq, px, on_invalid="mask")
        except ValueError:  # a step out of the model's domain (f, Su or Sv <= 0): no points
            return np.full((len(px), 3), np.nan)
        h = hand_from_camera(qq)
        rot = h[:3, :3] if not euler else rotation_from_vector(delta[len(plain):]) @ hfc[:3, :3]
        return np.where(ok[:, None], pts @ rot.T + h[:3, 3], np.nan)

    sets = _pixels_per_pose(dataset)
    sig = stripe_noise_px(sets, robust=False)
    if not math.isfinite(sig):
        sig = float(unc.pixel_noise or 0.0)
    return PointModel(points, names, (cov + cov.T) / 2, sets, sig, True)


def _pixels_per_pose(dataset: Any) -> list[np.ndarray]:
    """The data set's stripe pixels, one array per robot pose (in the order of their
    columns along the stripe)."""
    px = np.asarray(dataset.pixels, float)
    groups = pose_groups(dataset)
    out = []
    for g in np.unique(groups):
        sel = px[groups == g]
        out.append(sel[np.argsort(sel[:, 0], kind="stable")])
    return out


def pose_groups(dataset: Any) -> np.ndarray:
    """(m,) a label per point of ``dataset``: its pose (``pose_index``, else equal poses)."""
    if getattr(dataset, "pose_index", None) is not None:
        return np.asarray(dataset.pose_index)
    flat = np.round(np.asarray(dataset.poses, float).reshape(len(dataset), -1), 9)
    return np.unique(flat, axis=0, return_inverse=True)[1].ravel()


def footprint(model: PointModel, samples: int = SAMPLES, seed: int = 0) -> np.ndarray:
    """Stripe pixels of the calibration's views (those its solve used), at most ``samples``
    of them drawn evenly: the laser line's image footprint over the session's working
    range."""
    sets = [s for s in model.pixel_sets if len(s)]
    px = np.concatenate(sets) if sets else np.empty((0, 2))
    if len(px) > samples:
        px = px[np.random.default_rng(seed).choice(len(px), samples, replace=False)]
    return np.ascontiguousarray(px, float)


def point_sigmas(model: PointModel, pixels: np.ndarray, stripe_sigma_px: float) -> np.ndarray:
    """Predicted 3D standard deviation (mm, sqrt of the covariance's trace) of the points of
    ``pixels`` measured with the calibration ``model``, with ``stripe_sigma_px`` of noise
    across the stripe (0: the parameters' uncertainty alone)."""
    cov = model.covariance
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    jac = np.zeros((len(pixels), 3, len(model.names)))
    for k in range(len(model.names)):
        h = max(std[k], 1e-9) * 1e-2
        d = np.zeros(len(model.names))
        d[k] = h
        jac[:, :, k] = (model.points(d, pixels) - model.points(-d, pixels)) / (2 * h)
    var = np.einsum("nij,jk,nik->n", jac, cov, jac)
    if stripe_sigma_px > 0:
        dv = np.array([0.0, 0.5])
        jv = model.at(pixels + dv) - model.at(pixels - dv)
        var = var + stripe_sigma_px**2 * np.sum(jv**2, axis=1)
    return np.sqrt(np.clip(var, 0, None))


def predicted_map(model: PointModel) -> tuple[np.ndarray, np.ndarray] | None:
    """The footprint's pixels (k, 2) and their predicted 3D standard deviations (k, mm), with
    the stripe noise measured from the stripes themselves and the robot's pose error
    (``model.pose_sigma_mm``); None without stripe pixels."""
    px = footprint(model)
    if len(px) == 0:
        return None
    s = np.sqrt(point_sigmas(model, px, model.stripe_sigma_px) ** 2 + model.pose_sigma_mm**2)
    ok = np.isfinite(s)
    return (px[ok], s[ok]) if ok.any() else None


def summary(sigmas: np.ndarray) -> dict[str, float]:
    """{"rms", "p95"} of predicted standard deviations (mm)."""
    return {"rms": float(np.sqrt(np.mean(sigmas**2))), "p95": float(np.percentile(sigmas, 95))}


def map_sigma_mm(result: Any, dataset: Any = None) -> dict[str, float] | None:
    """{"rms", "p95"}: the predicted 3D uncertainty (mm) over the laser line's image
    footprint (:func:`predicted_map`) of a general-model calibration, or of a paper-model
    one with the ``dataset`` it was fitted to; None without stripe pixels."""
    model = of_joint(result) if dataset is None else of_paper(result, dataset)
    m = None if model is None else predicted_map(model)
    return None if m is None else summary(m[1])
