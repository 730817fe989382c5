"""The sensor model of docs/model.md, evaluated in C++ (``hmlvs._core``).

Every function takes parameters as :class:`~hmlvs.Parameters` or a 14-vector, stripe pixels
as (m, 2) arrays of (u = column, v = row), and base_from_hand poses as (m, 4, 4) arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .. import _core
from .._arrays import as_matrix, as_params, as_poses, same_rows
from .base import OnInvalid
from .base import check_on_invalid as _check_on_invalid
from .params import Parameters


def points_in_camera(params: Any, pixels: Any, on_invalid: OnInvalid = "raise",
                     min_angle: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Stripe pixels -> laser points in the camera frame (mm), paper Eq. 1-3.

    Returns ``(points (m, 3), valid (m,) bool)``. A pixel whose ray misses the laser plane
    (``Yu + f tan(theta) <= 0``) raises ``ValueError`` naming it, or with
    ``on_invalid="mask"`` gets ``valid=False`` and a NaN row. With ``min_angle`` (rad), so
    does a ray that meets the plane at a smaller angle (measurement uses 0.5 degrees).
    """
    throw = _check_on_invalid(on_invalid)
    r = _core._camera_points(as_params(params), as_matrix(pixels, 2, "pixels"), throw,
                             _min_sine(min_angle))
    return np.array(r.points), np.asarray(r.valid, dtype=bool)


def points_in_base(params: Any, pixels: Any, poses: Any, on_invalid: OnInvalid = "raise",
                   min_angle: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Stripe pixels seen at base_from_hand poses -> points in the robot base frame (Eq. 9).

    Returns ``(points (m, 3), valid (m,) bool)``; see :func:`points_in_camera` for
    ``on_invalid``.
    """
    throw = _check_on_invalid(on_invalid)
    px = as_matrix(pixels, 2, "pixels")
    ps = as_poses(poses)
    same_rows(pixels=px, poses=ps)
    r = _core._base_points(as_params(params), px, ps, throw, _min_sine(min_angle))
    return np.array(r.points), np.asarray(r.valid, dtype=bool)


def _min_sine(min_angle: float) -> float:
    import math

    if not (math.isfinite(min_angle) and 0 <= min_angle < math.pi / 2):
        raise ValueError(f"min_angle must be an angle in [0, pi/2) rad, got {min_angle}")
    return math.sin(min_angle)


def residuals(params: Any, pixels: Any, poses: Any, references: Any) -> np.ndarray:
    """E_i = P_i - bP_i(q) (m, 3) in mm (paper Eq. 14)."""
    px = as_matrix(pixels, 2, "pixels")
    ps = as_poses(poses)
    ref = as_matrix(references, 3, "reference points")
    same_rows(pixels=px, poses=ps, references=ref)
    return np.asarray(_core._residuals(as_params(params), px, ps, ref))


def objective(params: Any, pixels: Any, poses: Any, references: Any) -> float:
    """F(q) = 1/2 sum ||E_i||^2 (paper Eq. 13); +inf if a pixel's ray misses the plane."""
    px = as_matrix(pixels, 2, "pixels")
    ps = as_poses(poses)
    ref = as_matrix(references, 3, "reference points")
    same_rows(pixels=px, poses=ps, references=ref)
    return float(_core._objective(as_params(params), px, ps, ref))


def pixels_from_points(params: Any, points: Any, poses: Any, plane_tolerance: float = 1e-6,
                       on_invalid: OnInvalid = "raise") -> tuple[np.ndarray, np.ndarray]:
    """Base-frame points on the laser plane + poses -> stripe pixels (inverse of Eq. 9).

    A point farther than ``plane_tolerance`` mm from the laser plane, behind the camera, or
    outside the invertible range of the distortion model is invalid. Pass
    ``plane_tolerance=np.inf`` for a plain camera projection of any point.
    """
    throw = _check_on_invalid(on_invalid)
    pts = as_matrix(points, 3, "points")
    ps = as_poses(poses)
    same_rows(points=pts, poses=ps)
    r = _core._pixels_from_base(as_params(params), pts, ps, float(plane_tolerance))
    valid = np.asarray(r.valid, dtype=bool)
    if throw and not valid.all():
        i = int(np.argmin(valid))
        d = float(laser_plane_distance(params, pts[i:i + 1], ps[i:i + 1].reshape(1, 4, 4))[0])
        raise ValueError(
            f"point {i} {pts[i].tolist()} has no stripe pixel: its distance from the laser "
            f"plane is {d:.3g} mm (tolerance {plane_tolerance:g}), or it is behind the camera "
            f"or outside the distortion model's range")
    return np.array(r.pixels), valid


def project(params: Any, points: Any, poses: Any) -> tuple[np.ndarray, np.ndarray]:
    """Plain camera projection of base-frame points (any point, laser plane not required).

    Returns ``(pixels (m, 2), valid (m,))``; invalid points (behind the camera) are NaN.
    """
    return pixels_from_points(params, points, poses, plane_tolerance=np.inf, on_invalid="mask")


def laser_plane_distance(params: Any, points: Any, poses: Any) -> np.ndarray:
    """Signed distance (mm) of base-frame points from the laser plane at each pose."""
    pts = as_matrix(points, 3, "points")
    ps = as_poses(poses)
    same_rows(points=pts, poses=ps)
    return np.asarray(_core._laser_plane_distance(as_params(params), pts, ps))


def rays_in_camera(params: Any, pixels: Any) -> np.ndarray:
    """Pixels -> viewing rays (m, 3) in the camera frame: undistorted (Xu, Yu, f) in mm.

    A ray is not normalised; the camera-frame points along it are ``t * ray`` for t > 0.
    """
    return np.asarray(_core._camera_rays(as_params(params), as_matrix(pixels, 2, "pixels")))


def hand_from_camera(params: Any) -> np.ndarray:
    """The 4x4 hand_from_camera transform (rotation ZYZ Euler, paper Eq. 5-6)."""
    return np.asarray(_core._hand_from_camera(as_params(params)))


def hand_eye_rotation_vector(params: Any) -> list[float]:
    """hand_from_camera's rotation as a rotation vector (axis times angle, rad)."""
    from ..geometry.transforms import rotation_to_vector

    return [float(x) for x in rotation_to_vector(hand_from_camera(params)[:3, :3])]


def validate_poses(poses: Any) -> None:
    """Raise ``ValueError`` naming the first pose that is not a rigid transform."""
    _core._validate_poses(as_poses(poses))


def residual_jacobian(params: Any, pixels: Any, poses: Any, references: Any
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Residuals E (m, 3) and their Jacobian dE/dq (m, 3, 14), by automatic differentiation."""
    px = as_matrix(pixels, 2, "pixels")
    ps = as_poses(poses)
    ref = as_matrix(references, 3, "reference points")
    same_rows(pixels=px, poses=ps, references=ref)
    r, j = _core._residual_jacobian(as_params(params), px, ps, ref)
    m = px.shape[0]
    return np.asarray(r).reshape(m, 3), np.asarray(j).reshape(m, 3, -1)


def least_squares_functions(data: Any, unmeasured: float = 1e6
                            ) -> tuple[Callable[[Any], np.ndarray], Callable[[Any], np.ndarray]]:
    """The residual components E (flattened, 3 m) of a data set's points and their Jacobian
    (3 m, 14), as functions of the 14 parameters, for a general least-squares solver (e.g.
    SciPy's ``least_squares``, to compare with): where the model has no measurement (a ray
    that misses the laser plane, f < 0) every residual is ``unmeasured`` and the Jacobian 0,
    so that a solver without bounds backs off, as MINPACK expects."""
    px, ps, ref = data.pixels, data.poses, data.points
    m = len(px)

    def fun(q: Any) -> np.ndarray:
        try:
            return residuals(q, px, ps, ref).ravel()
        except ValueError:
            return np.full(3 * m, unmeasured)

    def jac(q: Any) -> np.ndarray:
        try:
            return residual_jacobian(q, px, ps, ref)[1].reshape(3 * m, -1)
        except ValueError:
            return np.zeros((3 * m, len(as_params(q))))

    return fun, jac


MIN_RAY_ANGLE = float(np.arcsin(_core.MIN_RAY_SINE))  # 0.5 deg: see PaperSensor


@dataclass(frozen=True)
class PaperSensor:
    """The paper's model as a :class:`hmlvs.models.base.SensorModel` (for measurement and
    export beside the general model)."""

    params: Parameters
    model: str = "paper"

    def points_in_camera(self, pixels: Any, on_invalid: OnInvalid = "raise"
                         ) -> tuple[np.ndarray, np.ndarray]:
        """As :func:`points_in_camera`, refusing grazing rays (< 0.5 deg) as measurement
        does."""
        return points_in_camera(self.params, pixels, on_invalid, min_angle=MIN_RAY_ANGLE)

    def points_in_base(self, pixels: Any, poses: Any, on_invalid: OnInvalid = "raise"
                       ) -> tuple[np.ndarray, np.ndarray]:
        return points_in_base(self.params, pixels, poses, on_invalid, min_angle=MIN_RAY_ANGLE)

    def hand_from_camera_matrix(self) -> np.ndarray:
        return hand_from_camera(self.params)
