"""The general sensor model (``model="opencv"``): OpenCV pinhole intrinsics with its
distortion, a laser plane with 3 degrees of freedom, a hand-eye transform with any rotation
and, optionally, the board's pose in the robot base.

Conventions are OpenCV's (``cv2.projectPoints``): pixel centres at integers, distortion
coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, taux, tauy]]]])``:
Brown-Conrady, the rational model's denominator (wide lenses), the thin prism and the tilted
(Scheimpflug) sensor's two angles (radians). Lengths in mm. The laser plane
is ``a x + b y + c z + d = 0`` in the camera frame with ``(a, b, c)`` a unit normal pointing
away from the camera's centre (``d < 0``: the camera centre is on the negative side).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any

import numpy as np

from .. import _core
from .._arrays import as_matrix, as_poses, check_transform, same_rows
from .base import OnInvalid, check_on_invalid

#: OpenCV's distortion coefficients, in its order (the C++ core's, after fx, fy, cx, cy)
DISTORTION_NAMES: tuple[str, ...] = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2",
                                     "s3", "s4", "taux", "tauy")
#: the five-term Brown-Conrady lens: the terms a calibration estimates unless told otherwise
CLASSIC_DISTORTION: tuple[str, ...] = DISTORTION_NAMES[:5]
INTRINSIC_NAMES: tuple[str, ...] = ("fx", "fy", "cx", "cy", *DISTORTION_NAMES)
#: the numbers of distortion coefficients OpenCV takes
_DIST_LENGTHS = (4, 5, 8, 12, 14)


def stored_distortion(coefficients: Any) -> np.ndarray:
    """Distortion coefficients as a sensor holds them: the shortest of OpenCV's lengths 5, 8,
    12 and 14 that keeps every non-zero term (so that a five-term lens stays five numbers in
    files and in every OpenCV call). Raises ``ValueError`` for another count or a value that
    is not finite."""
    given = np.array(coefficients, dtype=float).ravel()
    if given.size not in (0, *_DIST_LENGTHS):
        raise ValueError("dist_coeffs must hold 4, 5, 8, 12 or 14 numbers (OpenCV's k1, k2, "
                         "p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, taux, tauy]]]]), got "
                         f"{given.size}")
    full = np.zeros(len(DISTORTION_NAMES))
    full[: given.size] = given
    full = _array(full, full.shape, "dist_coeffs")
    used = np.flatnonzero(full)
    n = next(k for k in _DIST_LENGTHS[1:] if used.size == 0 or used[-1] < k)
    return full[:n]


def _array(x: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    try:
        a = np.array(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers of shape {shape}, got {x!r}") from None
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a.tolist()}")
    return a


def _image_size(size: Any) -> tuple[int, int]:
    """(width, height): two positive whole numbers (a whole float such as 640.0 is one; a
    fraction, a text or a boolean is not)."""
    def whole(v: Any) -> int | None:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer,
                                                                  np.floating)):
            return None
        if not np.isfinite(v) or v != int(v) or v <= 0:
            return None
        return int(v)

    try:
        pair = list(size)
    except TypeError:
        pair = []
    dims = [whole(v) for v in pair] if len(pair) == 2 else [None]
    if None in dims:
        raise ValueError(f"image_size must be two positive whole numbers of pixels (width, "
                         f"height), got {size!r}")
    return dims[0], dims[1]


@dataclass(frozen=True, eq=False)
class OpenCvSensor:
    """A calibrated general sensor.

    camera_matrix : 3x3 ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (pixels)
    dist_coeffs : OpenCV's ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, taux,
        tauy]]]])``, held as 5, 8, 12 or 14 numbers (:func:`stored_distortion`)
    image_size : ``(width, height)`` in pixels
    laser_plane : ``(a, b, c, d)``, camera frame, unit normal, ``d`` in mm (see module doc)
    hand_from_camera : 4x4 transform (mm)
    base_from_board : 4x4 transform of the calibration board in the robot base, when known
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    laser_plane: np.ndarray
    hand_from_camera: np.ndarray
    base_from_board: np.ndarray | None = field(default=None)
    model: str = field(default="opencv", init=False)

    def __post_init__(self) -> None:
        k = _array(self.camera_matrix, (3, 3), "camera_matrix")
        if not (k[0, 0] > 0 and k[1, 1] > 0 and k[1, 0] == 0 and k[2, 0] == 0 and k[2, 1] == 0
                and k[2, 2] == 1):
            raise ValueError("camera_matrix must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with "
                             f"fx, fy > 0, got {k.tolist()}")
        dist = stored_distortion(self.dist_coeffs)
        w, h = _image_size(self.image_size)
        plane = _array(self.laser_plane, (4,), "laser_plane")
        norm = float(np.linalg.norm(plane[:3]))
        if not norm > 0:
            raise ValueError("laser_plane needs a non-zero normal (a, b, c)")
        if not abs(float(plane[3])) > 1e-9 * norm:
            raise ValueError(f"laser_plane {plane.tolist()} has d = 0: a plane through the "
                             "camera's centre, which every ray meets nowhere or everywhere; "
                             "d is the plane's distance from the camera (mm), never 0")
        plane = plane / norm
        if plane[3] > 0:
            plane = -plane
        hfc = check_transform(self.hand_from_camera, "hand_from_camera")
        bfb = None if self.base_from_board is None else check_transform(
            self.base_from_board, "base_from_board")
        object.__setattr__(self, "camera_matrix", k)
        object.__setattr__(self, "dist_coeffs", dist)
        object.__setattr__(self, "image_size", (w, h))
        object.__setattr__(self, "laser_plane", plane)
        object.__setattr__(self, "hand_from_camera", hfc)
        object.__setattr__(self, "base_from_board", bfb)

    @property
    def fx(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def fy(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def cx(self) -> float:
        return float(self.camera_matrix[0, 2])

    @property
    def cy(self) -> float:
        return float(self.camera_matrix[1, 2])

    def intrinsics_vector(self) -> np.ndarray:
        """[fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, taux, tauy], the
        C++ core's order (the terms the sensor does not hold are 0)."""
        v = np.zeros(4 + len(DISTORTION_NAMES))
        v[:4] = (self.fx, self.fy, self.cx, self.cy)
        v[4: 4 + self.dist_coeffs.size] = self.dist_coeffs
        return v

    def project(self, camera_points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame points -> pixels (``cv2.projectPoints``); ``valid`` is False (NaN
        row) for points not in front of the camera."""
        r = _core._general_project(self.intrinsics_vector(),
                                   as_matrix(camera_points, 3, "camera points"))
        return np.array(r.pixels), np.asarray(r.valid, dtype=bool)

    def undistort(self, pixels: Any) -> tuple[np.ndarray, np.ndarray]:
        """Pixels -> undistorted normalised image points (x, y) (``cv2.undistortPoints``,
        solved to convergence); ``valid`` is False where the distortion cannot be inverted."""
        r = _core._general_undistort(self.intrinsics_vector(), as_matrix(pixels, 2, "pixels"))
        return np.array(r.pixels), np.asarray(r.valid, dtype=bool)

    def _outside(self, px: np.ndarray, throw: bool) -> np.ndarray:
        """Pixels outside the image (they have no measurement): a mask, or a ValueError
        naming the first one."""
        w, h = self.image_size
        out = ~((px[:, 0] >= -0.5) & (px[:, 0] <= w - 0.5) & (px[:, 1] >= -0.5)
                & (px[:, 1] <= h - 0.5))
        if throw and out.any():
            i = int(np.argmax(out))
            raise ValueError(f"pixel {i} (u={px[i, 0]:g}, v={px[i, 1]:g}) lies outside the "
                             f"{w} x {h} image, so it has no measurement")
        return out

    def points_in_camera(self, pixels: Any, on_invalid: OnInvalid = "raise"
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Stripe pixels -> camera-frame points on the laser plane (mm). Pixels outside the
        image, whose ray misses the plane or meets it at a grazing angle (< 0.5 deg) have no
        measurement (see ``on_invalid``)."""
        throw = check_on_invalid(on_invalid)
        px = as_matrix(pixels, 2, "pixels")
        outside = self._outside(px, throw)
        r = _core._general_laser_camera(self.intrinsics_vector(), self.laser_plane, px, throw)
        pts, valid = np.array(r.points), np.asarray(r.valid, dtype=bool) & ~outside
        pts[~valid] = np.nan
        return pts, valid

    def points_in_base(self, pixels: Any, poses: Any, on_invalid: OnInvalid = "raise"
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Stripe pixels seen at base_from_hand poses (one per pixel) -> base-frame points:
        ``base_from_hand @ hand_from_camera @ camera point``."""
        throw = check_on_invalid(on_invalid)
        px = as_matrix(pixels, 2, "pixels")
        ps = as_poses(poses)
        same_rows(pixels=px, poses=ps)
        outside = self._outside(px, throw)
        r = _core._general_laser_base(self.intrinsics_vector(), self.laser_plane,
                                      self.hand_from_camera, px, ps, throw)
        pts, valid = np.array(r.points), np.asarray(r.valid, dtype=bool) & ~outside
        pts[~valid] = np.nan
        return pts, valid

    def hand_from_camera_matrix(self) -> np.ndarray:
        return self.hand_from_camera.copy()

    def intrinsics(self) -> dict[str, float]:
        """fx, fy, cx, cy and the distortion terms the sensor holds (k1, k2, p1, p2, k3, and
        k4 ... tauy when not all 0) by name."""
        values = (self.fx, self.fy, self.cx, self.cy, *self.dist_coeffs.tolist())
        return dict(zip(INTRINSIC_NAMES, (float(v) for v in values)))

    def laser_plane_angle_deg(self) -> float:
        """Angle between the laser plane and the camera's optical axis (degrees)."""
        return math.degrees(math.asin(min(1.0, abs(float(self.laser_plane[2])))))

    def to_dict(self) -> dict[str, Any]:
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.tolist(),
            "image_size": list(self.image_size),
            "laser_plane": self.laser_plane.tolist(),
            "hand_from_camera": self.hand_from_camera.tolist(),
            "base_from_board": None if self.base_from_board is None
            else self.base_from_board.tolist(),
        }

    @classmethod
    def from_dict(cls, d: Any, source: str = "sensor") -> "OpenCvSensor":
        if not isinstance(d, dict):
            raise ValueError(f"{source}: the opencv sensor must be a mapping, "
                             f"got {type(d).__name__}")
        missing = [k for k in ("camera_matrix", "dist_coeffs", "image_size", "laser_plane",
                               "hand_from_camera") if k not in d]
        if missing:
            raise ValueError(f"{source}: the opencv sensor lacks {', '.join(missing)}")
        try:
            return cls(camera_matrix=d["camera_matrix"], dist_coeffs=d["dist_coeffs"],
                       image_size=d["image_size"], laser_plane=d["laser_plane"],
                       hand_from_camera=d["hand_from_camera"],
                       base_from_board=d.get("base_from_board"))
        except ValueError as e:
            raise ValueError(f"{source}: {e}") from None
