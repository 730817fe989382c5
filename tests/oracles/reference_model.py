"""An independent NumPy implementation of the model of docs/model.md, used as a parity oracle.

Written from docs/model.md alone, vectorised, without calling hmlvs.
"""

from __future__ import annotations

import numpy as np


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def camera_points(q: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    f, su, sv, cu, cv, k, h, theta = q[:8]
    xd = su * (pixels[:, 0] - cu)
    yd = sv * (pixels[:, 1] - cv)
    r2 = xd**2 + yd**2
    xu = xd / (1 + k * r2)
    yu = yd / (1 + k * r2)
    denom = yu + f * np.tan(theta)
    rho = h / denom
    pts = rho[:, None] * np.stack([xu, yu, np.full_like(xu, f)], axis=1)
    return pts, denom > 0


def base_points(q: np.ndarray, pixels: np.ndarray, poses: np.ndarray) -> np.ndarray:
    cam, _ = camera_points(q, pixels)
    rc = rot_z(q[8]) @ rot_y(q[9]) @ rot_z(q[10])
    hand = cam @ rc.T + q[11:14]
    return np.einsum("mij,mj->mi", poses[:, :3, :3], hand) + poses[:, :3, 3]


def dh_standard(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """Rz(theta) Tz(d) Tx(a) Rx(alpha) as a product of elementary transforms."""
    def rz(t):
        m = np.eye(4)
        m[:3, :3] = rot_z(t)
        return m

    def rx(t):
        c, s = np.cos(t), np.sin(t)
        m = np.eye(4)
        m[1:3, 1:3] = [[c, -s], [s, c]]
        return m

    def tr(x, y, z):
        m = np.eye(4)
        m[:3, 3] = [x, y, z]
        return m

    return rz(theta) @ tr(0, 0, d) @ tr(a, 0, 0) @ rx(alpha)


def dh_modified(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """Rx(alpha) Tx(a) Rz(theta) Tz(d) (Craig)."""
    c, s = np.cos(alpha), np.sin(alpha)
    rx = np.eye(4)
    rx[1:3, 1:3] = [[c, -s], [s, c]]
    tx = np.eye(4)
    tx[0, 3] = a
    rz = np.eye(4)
    rz[:3, :3] = rot_z(theta)
    tz = np.eye(4)
    tz[2, 3] = d
    return rx @ tx @ rz @ tz


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    qv = rng.normal(size=4)
    w, x, y, z = qv / np.linalg.norm(qv)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def random_poses(rng: np.random.Generator, m: int) -> np.ndarray:
    poses = np.tile(np.eye(4), (m, 1, 1))
    for i in range(m):
        poses[i, :3, :3] = random_rotation(rng)
        poses[i, :3, 3] = rng.uniform(-800, 800, 3)
    return poses
