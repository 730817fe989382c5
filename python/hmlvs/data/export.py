"""Export a calibration for other software: OpenCV FileStorage YAML, ROS camera_info YAML, JSON.

Every export starts from an :class:`~hmlvs.models.opencv.OpenCvSensor`. A paper-model
calibration is converted by :func:`sensor_of`: the pinhole intrinsics follow directly, the
laser plane and the hand-eye transform too, and the paper's one-term division model is fitted
by OpenCV's radial terms k1, k2, k3 (p1 = p2 = 0) over the image.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any
import warnings

import numpy as np
import yaml

from .._io import atomic_write
from ..geometry.transforms import rotation_to_quaternion
from ..models.opencv import OpenCvSensor
from ..models.params import Parameters
from .calibration_file import Calibration

FORMATS: tuple[str, ...] = ("opencv", "ros", "json")
#: a paper calibration whose distortion the k1, k2, k3 fit misses by more than this warns
MAX_FIT_ERROR_PX = 0.05


def _pixel_grid(image_size: tuple[int, int], n: int = 41) -> np.ndarray:
    w, h = image_size
    uu, vv = np.meshgrid(np.linspace(0.0, w - 1.0, n), np.linspace(0.0, h - 1.0, n))
    return np.column_stack([uu.ravel(), vv.ravel()])


def division_to_brown(params: Parameters, image_size: tuple[int, int]
                      ) -> tuple[np.ndarray, float]:
    """The division model's k as OpenCV's (k1, k2, p1, p2, k3), by linear least squares.

    Over a 41 x 41 grid of pixels covering the image, the paper's undistorted point
    ``x_u = x_d / (1 + k f^2 |x_d|^2)`` (normalised coordinates ``x_d = Su (u - Cu) / f``) is
    computed exactly; k1, k2, k3 then minimise the pixel distance between the distorted pixels
    and OpenCV's distortion of ``x_u``, ``x_u (1 + k1 r^2 + k2 r^4 + k3 r^6)``.

    Returns (dist_coeffs (5,), the largest remaining error over the grid in px).
    """
    fx, fy = params.f / params.Su, params.f / params.Sv
    if params.k == 0.0:
        return np.zeros(5), 0.0
    px = _pixel_grid(image_size)
    xd = (px[:, 0] - params.Cu) / fx
    yd = (px[:, 1] - params.Cv) / fy
    s = 1.0 + params.k * params.f ** 2 * (xd ** 2 + yd ** 2)
    ok = s > 1e-6
    xd, yd, s = xd[ok], yd[ok], s[ok]
    xu, yu = xd / s, yd / s
    r2 = xu ** 2 + yu ** 2
    basis = np.column_stack([r2, r2 ** 2, r2 ** 3])
    # rows: fx xu (k1 r^2 + k2 r^4 + k3 r^6) = fx (xd - xu), the same for y (pixel units)
    a = np.vstack([fx * xu[:, None] * basis, fy * yu[:, None] * basis])
    b = np.concatenate([fx * (xd - xu), fy * (yd - yu)])
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    err = np.hypot(*(a @ sol - b).reshape(2, -1))
    return np.array([sol[0], sol[1], 0.0, 0.0, sol[2]]), float(err.max())


def sensor_of(calibration: Any, image_size: tuple[int, int] | None = None) -> OpenCvSensor:
    """The :class:`OpenCvSensor` of a calibration (a :class:`Calibration`, its file's path,
    :class:`Parameters` or an OpenCvSensor).

    For the paper model: fx = f / Su, fy = f / Sv, cx = Cu, cy = Cv; distortion by
    :func:`division_to_brown` over ``image_size`` (width, height; default 2 Cu x 2 Cv
    rounded); laser plane (0, 1, tan(theta), -H) normalised; hand_from_camera of the paper
    (:func:`hmlvs.models.paper.hand_from_camera`). A distortion fit worse than 0.05 px warns.
    """
    from ..models.paper import hand_from_camera

    if isinstance(calibration, (str, os.PathLike)):
        calibration = Calibration.load(calibration)
    if isinstance(calibration, OpenCvSensor):
        return calibration
    if isinstance(calibration, Calibration):
        if calibration.model == "opencv" or calibration.params is None:
            assert calibration.sensor is not None
            return calibration.sensor
        params = calibration.params
    elif isinstance(calibration, Parameters):
        params = calibration
    else:
        raise ValueError("sensor_of takes a Calibration, its file, Parameters or an "
                         f"OpenCvSensor, got {type(calibration).__name__}")
    if image_size is None:
        image_size = (int(round(2 * params.Cu)), int(round(2 * params.Cv)))
    w, h = (int(v) for v in image_size)
    if w <= 0 or h <= 0:
        raise ValueError(f"image_size must be positive (width, height), got {image_size}")
    dist, err = division_to_brown(params, (w, h))
    if err > MAX_FIT_ERROR_PX:
        warnings.warn(f"the division model (k = {params.k:g} 1/mm^2) is matched by OpenCV's "
                      f"k1, k2, k3 only within {err:.3g} px over the {w} x {h} image",
                      stacklevel=2)
    fx, fy = params.f / params.Su, params.f / params.Sv
    k = np.array([[fx, 0.0, params.Cu], [0.0, fy, params.Cv], [0.0, 0.0, 1.0]])
    plane = np.array([0.0, 1.0, math.tan(params.theta), -params.H])
    return OpenCvSensor(camera_matrix=k, dist_coeffs=dist, image_size=(w, h),
                        laser_plane=plane, hand_from_camera=hand_from_camera(params))


# ------------------------------------------------------------------------------------------
# formats


def _opencv_matrix(name: str, m: np.ndarray) -> str:
    m = np.atleast_2d(np.asarray(m, dtype=np.float64))
    data = ", ".join(repr(float(v)) for v in m.ravel())
    return (f"{name}: !!opencv-matrix\n   rows: {m.shape[0]}\n   cols: {m.shape[1]}\n"
            f"   dt: d\n   data: [ {data} ]\n")


def _opencv_text(s: OpenCvSensor) -> str:
    """OpenCV FileStorage YAML (what ``cv2.FileStorage`` reads; ``%YAML:1.0`` header)."""
    text = ("%YAML:1.0\n---\n"
            "# hmlvs sensor calibration: lengths in mm, pixel centres at integers;\n"
            "# laser_plane: a x + b y + c z + d = 0 in the camera frame (unit normal, d in mm)\n"
            f"image_width: {int(s.image_size[0])}\n"
            f"image_height: {int(s.image_size[1])}\n")
    text += _opencv_matrix("camera_matrix", s.camera_matrix)
    text += _opencv_matrix("distortion_coefficients", s.dist_coeffs.reshape(1, -1))
    text += _opencv_matrix("laser_plane", s.laser_plane.reshape(1, 4))
    text += _opencv_matrix("hand_from_camera", s.hand_from_camera)
    if s.base_from_board is not None:
        text += _opencv_matrix("base_from_board", s.base_from_board)
    return text


#: ROS camera_info's distortion models by number of coefficients (image_geometry's)
_ROS_MODELS = {5: "plumb_bob", 8: "rational_polynomial"}


def _ros_text(s: OpenCvSensor, camera_name: str) -> str:
    n = s.dist_coeffs.size
    if n not in _ROS_MODELS:
        raise ValueError("ROS camera_info has no distortion model for the thin prism or the "
                         "tilted sensor (s1 to tauy are not all 0): export as opencv or json "
                         "instead")
    k = s.camera_matrix
    proj = np.hstack([k, np.zeros((3, 1))])
    doc = {
        "image_width": int(s.image_size[0]),
        "image_height": int(s.image_size[1]),
        "camera_name": camera_name,
        "camera_matrix": {"rows": 3, "cols": 3, "data": k.ravel().tolist()},
        "distortion_model": _ROS_MODELS[n],
        "distortion_coefficients": {"rows": 1, "cols": n, "data": s.dist_coeffs.tolist()},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": np.eye(3).ravel().tolist()},
        "projection_matrix": {"rows": 3, "cols": 4, "data": proj.ravel().tolist()},
    }
    q = rotation_to_quaternion(s.hand_from_camera[:3, :3], "xyzw")
    t = s.hand_from_camera[:3, 3] / 1000.0
    head = ("# camera_info written by hmlvs export (camera_calibration_parsers layout).\n"
            "# Not part of camera_info, for reference:\n"
            f"# laser_plane (a, b, c, d; camera optical frame, d in m): "
            f"[{', '.join(f'{v:.9g}' for v in s.laser_plane[:3])}, "
            f"{s.laser_plane[3] / 1000.0:.9g}]\n"
            f"# hand_from_camera (flange -> camera optical frame) translation m: "
            f"[{', '.join(f'{v:.9g}' for v in t)}], quaternion xyzw: "
            f"[{', '.join(f'{v:.9g}' for v in q)}]\n")
    return head + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)


def _json_doc(s: OpenCvSensor) -> dict[str, Any]:
    hfc = s.hand_from_camera
    return {
        "units": {"length": "mm", "angle": "rad", "pixel": "px"},
        "camera_matrix": s.camera_matrix.tolist(),
        "dist_coeffs": s.dist_coeffs.tolist(),
        "image_size": list(s.image_size),
        "laser_plane": s.laser_plane.tolist(),
        "hand_from_camera": hfc.tolist(),
        "hand_from_camera_pose": {
            "xyz_mm": hfc[:3, 3].tolist(),
            "quaternion_xyzw": rotation_to_quaternion(hfc[:3, :3], "xyzw").tolist()},
        "base_from_board": None if s.base_from_board is None else s.base_from_board.tolist(),
    }


def export_text(calibration: Any, fmt: str, *, image_size: tuple[int, int] | None = None,
                camera_name: str = "hmlvs_camera") -> str:
    """The calibration in format ``fmt`` ("opencv", "ros" or "json") as text."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown export format {fmt!r}; choose {', '.join(FORMATS)}")
    s = sensor_of(calibration, image_size)
    if fmt == "opencv":
        return _opencv_text(s)
    if fmt == "ros":
        return _ros_text(s, camera_name)
    return json.dumps(_json_doc(s), indent=2) + "\n"


def export(calibration: Any, fmt: str, path: str | os.PathLike, *,
           image_size: tuple[int, int] | None = None,
           camera_name: str = "hmlvs_camera") -> Path:
    """Write :func:`export_text` atomically to ``path``; returns the path."""
    text = export_text(calibration, fmt, image_size=image_size, camera_name=camera_name)
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write(text)
    return path
