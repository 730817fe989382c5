"""Rotations and rigid transforms, written once: rotation vectors (Rodrigues), quaternions,
4x4 transforms, their inverse and the angle between rotations. Every module that needs one of
these uses this one."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def rotation_from_vector(rv: Any) -> np.ndarray:
    """Rotation vector (axis times angle, rad) -> 3x3 rotation matrix (Rodrigues' formula)."""
    r = np.asarray(rv, dtype=float).reshape(3)
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.eye(3)
    k = r / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


def rotation_to_vector(rot: Any) -> np.ndarray:
    """3x3 rotation matrix -> rotation vector (axis times angle, rad, angle in [0, pi])."""
    q = rotation_to_quaternion(rot)  # (x, y, z, w) with w >= 0
    s = float(np.linalg.norm(q[:3]))
    if s < 1e-15:
        return np.zeros(3)
    angle = 2.0 * math.atan2(s, q[3])
    return q[:3] / s * angle


def rotation_to_quaternion(rot: Any, order: str = "xyzw") -> np.ndarray:
    """3x3 rotation matrix -> unit quaternion in ``order``, with w >= 0 (Shepperd's method)."""
    r = np.asarray(rot, dtype=float).reshape(3, 3)
    tr = float(np.trace(r))
    if tr > max(r[0, 0], r[1, 1], r[2, 2]):
        s = 2.0 * math.sqrt(1.0 + tr)
        q = np.array([(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s,
                      (r[1, 0] - r[0, 1]) / s, 0.25 * s])
    elif r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + r[0, 0] - r[1, 1] - r[2, 2], 0.0))
        q = np.array([0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s,
                      (r[2, 1] - r[1, 2]) / s])
    elif r[1, 1] >= r[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + r[1, 1] - r[0, 0] - r[2, 2], 0.0))
        q = np.array([(r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s,
                      (r[0, 2] - r[2, 0]) / s])
    else:
        s = 2.0 * math.sqrt(max(1.0 + r[2, 2] - r[0, 0] - r[1, 1], 0.0))
        q = np.array([(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s,
                      (r[1, 0] - r[0, 1]) / s])
    q = q / np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    if order == "xyzw":
        return q
    if order == "wxyz":
        return np.array([q[3], q[0], q[1], q[2]])
    raise ValueError(f"the quaternion order must be 'xyzw' or 'wxyz', got {order!r}")


def rotation_angle(r: Any) -> float:
    """The angle (rad, in [0, pi]) of a 3x3 rotation matrix, e.g. of ``a @ b.T`` between two."""
    r = np.asarray(r, dtype=float)
    return math.acos(max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0)))


def make_transform(rotation: Any, translation: Any) -> np.ndarray:
    """A 4x4 rigid transform from a 3x3 rotation matrix (or a rotation vector) and a
    translation."""
    r = np.asarray(rotation, dtype=float)
    out = np.eye(4)
    out[:3, :3] = rotation_from_vector(r) if r.size == 3 else r.reshape(3, 3)
    out[:3, 3] = np.asarray(translation, dtype=float).reshape(3)
    return out


def invert_transform(m: Any) -> np.ndarray:
    """The inverse of a 4x4 rigid transform (transposed rotation), exact to rounding."""
    m = np.asarray(m, dtype=float)
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out
