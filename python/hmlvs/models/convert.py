"""Conversions between the two sensor models.

:func:`paper_params_of` starts the paper's 14-parameter model from a general (opencv) one:
a calibration from the board's corners and the stripe gives the paper model a start near its
solution, with no guess needed. (The other direction is :func:`hmlvs.data.export.sensor_of`.)
"""

from __future__ import annotations

import math

import numpy as np

from .opencv import OpenCvSensor
from .params import NAMES, NOMINAL, Parameters


def euler_zyz(r: np.ndarray) -> tuple[float, float, float]:
    """(omega, phi, varphi) with r = Rz(omega) Ry(phi) Rz(varphi) (phi in [0, pi])."""
    phi = math.atan2(math.hypot(r[0, 2], r[1, 2]), r[2, 2])
    if math.sin(phi) < 1e-12:  # gimbal lock: only omega + varphi is defined
        return math.atan2(r[1, 0], r[0, 0]), phi, 0.0
    return math.atan2(r[1, 2], r[0, 2]), phi, math.atan2(r[2, 1], -r[2, 0])


def paper_params_of(sensor: OpenCvSensor, su: float = float(NOMINAL[NAMES.index("Su")])
                    ) -> Parameters:
    """The paper's parameters closest to a general sensor, with the pixel pitch ``su`` (mm/px,
    the scale gauge, e.g. from the camera's datasheet).

    f = fx su, Sv = f / fy, Cu = cx, Cv = cy; k is the least-squares division-model term
    matching the sensor's undistortion over its image; the laser plane a x + b y + c z + d = 0
    becomes y + z tan(theta) = H with tan(theta) = c / b and H = -d / b (its tilt about the
    camera's y axis, a / b, has no place in the paper's model and is dropped); the hand-eye
    rotation becomes ZYZ Euler angles.
    """
    if not su > 0:
        raise ValueError(f"the pixel pitch Su must be > 0 mm/px, got {su}")
    a, b, c, d = sensor.laser_plane
    if not b > 1e-6:
        raise ValueError("the laser plane is parallel to the camera's y axis, which the paper's "
                         f"model y + z tan(theta) = H cannot describe (normal {a:.3g}, {b:.3g}, "
                         f"{c:.3g})")
    f = sensor.fx * su
    sv = f / sensor.fy
    w, h = sensor.image_size
    uu, vv = np.meshgrid(np.linspace(0, w - 1, 25), np.linspace(0, h - 1, 19))
    px = np.c_[uu.ravel(), vv.ravel()]
    und, ok = sensor.undistort(px)
    xd = su * (px[ok, 0] - sensor.cx)
    yd = sv * (px[ok, 1] - sensor.cy)
    xu, yu = f * und[ok, 0], f * und[ok, 1]
    r2 = xd**2 + yd**2
    # Xd = Xu (1 + k r2) on both coordinates: linear least squares in k
    g = np.r_[r2 * xu, r2 * yu]
    e = np.r_[xd - xu, yd - yu]
    k = float(g @ e / (g @ g)) if g @ g > 0 else 0.0
    omega, phi, varphi = euler_zyz(sensor.hand_from_camera[:3, :3])
    t = sensor.hand_from_camera[:3, 3]
    return Parameters(f=f, Su=su, Sv=sv, Cu=sensor.cx, Cv=sensor.cy, k=k, H=float(-d / b),
                      theta=math.atan(c / b), omega=omega, phi=phi, varphi=varphi,
                      tx=float(t[0]), ty=float(t[1]), tz=float(t[2]))
