"""The result of the general model's joint calibration (:class:`JointCalibration`)."""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any

import numpy as np

from ..geometry.transforms import rotation_to_vector
from ..models.opencv import DISTORTION_NAMES, OpenCvSensor


@dataclass
class JointCalibration:
    """The outcome of :func:`calibrate_joint`.

    sensor : the calibrated :class:`OpenCvSensor`
    std : standard deviation of each estimated quantity (px, mm, rad; rotations as rotation
        vectors perturbed in the base/hand frame, the plane normal as 2 tangent angles)
    names : the estimated quantities, in the order of ``covariance``
    covariance : their covariance
    corner_rms_px, laser_rms_mm : RMS of the residuals of the final solve
    corner_sigma_px, laser_sigma_mm : the noise levels used as weights (estimated)
    per_view : per view id: corners used, stripe pixels used, corner RMS (px), laser RMS (mm)
    dropped : counts of corners and stripe pixels dropped as outliers
    mode : "chain" (robot poses) or "camera" (free board poses)
    rank, num_unknowns, condition : the Jacobian's numerical rank, size and condition number
        (column-scaled); every quantity is determined when rank == num_unknowns
    termination, iterations, seconds : of the final Levenberg-Marquardt solve
    flipped : ids of views whose corner numbering was turned by 180 degrees
    rejected : ids of views left out, with the reason (a numbering that cannot be decided)
    residuals : per view id: ``corner_pixels`` (k, 2) and ``corner_residuals`` (k, 2, px,
        projected - detected), ``laser_pixels`` (m, 2) and ``laser_residuals`` (m, mm from
        the laser plane), of the points used
    """

    sensor: OpenCvSensor
    std: dict[str, float]
    names: list[str]
    covariance: np.ndarray
    corner_rms_px: float
    laser_rms_mm: float
    corner_sigma_px: float
    laser_sigma_mm: float
    per_view: dict[str, dict[str, float]]
    dropped: dict[str, int]
    mode: str
    rank: int
    num_unknowns: int
    condition: float
    termination: str
    iterations: int
    seconds: float
    flipped: list[str] = field(default_factory=list)
    camera_from_board: dict[str, np.ndarray] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    test_rms_mm: float | None = None
    test_views: int = 0
    residuals: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    rejected: dict[str, str] = field(default_factory=dict)
    #: chain mode with uncertain robot poses: the estimated spread of the robot pose errors,
    #: (translation mm, rotation deg) per axis; None with exact poses
    robot_pose_sigma: tuple[float, float] | None = None
    #: chain mode with exact robot poses: the spread of the robot pose errors the residuals
    #: show (translation mm, rotation deg, per axis), counted in the covariance
    #: (:mod:`hmlvs.calibration.joint_covariance`); None when they show none
    pose_errors_counted: tuple[float, float] | None = None
    #: camera mode: how much the views' own cameras differ (px RMS from view to view, per
    #: intrinsic: fx, fy, cx, cy), counted in the covariance
    #: (:func:`hmlvs.calibration.joint_covariance.camera_mode_covariance`); None when the
    #: residuals show no such differences
    view_cameras_counted: dict[str, float] | None = None
    #: RMS corner reprojection (px) of the camera calibration with every view's board pose
    #: free (Zhang's, or the held camera's solvePnP): what the detector's noise leaves
    free_rms_px: float | None = None
    #: the stripe residuals' correlation length along the stripe (neighbouring stripe pixels
    #: that count as one independent one, :func:`stripe_correlation`); the covariance takes
    #: the stripe pixels as that many times fewer
    stripe_correlation: float = 1.0
    #: a calibration evaluated on a session (:func:`evaluate_sensor`): its camera, laser plane
    #: and hand-eye held, so the solve is of the board's pose alone
    evaluated: bool = False

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values (the command line's --json): the sensor,
        the fit, what the data determine, the termination."""
        s = self.sensor
        return {"model": "opencv", "mode": self.mode, "evaluated": self.evaluated,
                "camera_matrix": s.camera_matrix.tolist(),
                "dist_coeffs": s.dist_coeffs.tolist(), "image_size": list(s.image_size),
                "laser_plane": s.laser_plane.tolist(),
                "hand_from_camera": s.hand_from_camera.tolist(),
                "base_from_board": None if s.base_from_board is None
                else s.base_from_board.tolist(),
                "std": self.std, "corner_rms_px": self.corner_rms_px,
                "laser_rms_mm": self.laser_rms_mm, "test_rms_mm": self.test_rms_mm,
                "views": len(self.per_view), "determined": self.determined,
                "rank": self.rank, "unknowns": self.num_unknowns, "dropped": self.dropped,
                "flipped": self.flipped, "termination": self.termination,
                "iterations": self.iterations, "seconds": self.seconds}

    def solve_figures(self) -> dict[str, Any]:
        """The solve's figures in the form both models share (``hmlvs calibrate --json``'s
        ``solve``, docs/file-formats.md); ``determined``/``not_determined`` name the unknowns
        only when the data determine them all (a rank-deficient solve does not name its flat
        directions: both null then). Then this model's own: the mode, the corner residuals,
        the views used, the outliers dropped, the views whose numbering was turned."""
        from .result import Termination

        all_named = self.determined
        return {"termination": str(Termination.from_ceres(self.termination)),
                "iterations": int(self.iterations), "seconds": float(self.seconds),
                "unknowns": int(self.num_unknowns), "rank": int(self.rank),
                "determined": list(self.names) if all_named else None,
                "not_determined": [] if all_named else None,
                "rotation_vector_rad": [float(x) for x in rotation_to_vector(
                    self.sensor.hand_from_camera[:3, :3])],
                "mode": self.mode, "corner_rms_px": float(self.corner_rms_px),
                "views": len(self.per_view), "dropped": dict(self.dropped),
                "flipped": list(self.flipped),
                "robot_pose_sigma": None if self.robot_pose_sigma is None
                else [float(x) for x in self.robot_pose_sigma],
                "pose_errors_counted": None if self.pose_errors_counted is None
                else [float(x) for x in self.pose_errors_counted],
                "view_cameras_counted": None if self.view_cameras_counted is None
                else {k: float(v) for k, v in self.view_cameras_counted.items()}}

    @property
    def determined(self) -> bool:
        return self.rank == self.num_unknowns

    def summary(self) -> str:
        """A few lines a user reads: what was estimated, how well, how sure."""
        s = self.sensor
        d = s.dist_coeffs
        std = self.std
        how = ("robot poses" if self.mode == "chain"
               else "no robot poses: intrinsics and laser plane only")
        nan = float("nan")
        lines = [
            f"model opencv, {self.mode} mode ({how}), {len(self.per_view)} views, "
            f"{self.termination.lower()} after {self.iterations} LM iterations, "
            f"{self.seconds:.2f} s",
            f"camera: fx {s.fx:.2f} +- {std.get('fx', nan):.2g}, fy {s.fy:.2f} +- "
            f"{std.get('fy', nan):.2g}, cx {s.cx:.2f} +- {std.get('cx', nan):.2g}, "
            f"cy {s.cy:.2f} +- {std.get('cy', nan):.2g} px; distortion k1 {d[0]:.5f}, "
            f"k2 {d[1]:.5f}, p1 {d[2]:.6f}, p2 {d[3]:.6f}, k3 {d[4]:.5f}"
            + "".join(f", {n} {v:.5g}" for n, v in zip(DISTORTION_NAMES[5:], d[5:])),
            f"laser plane: normal ({s.laser_plane[0]:.5f}, {s.laser_plane[1]:.5f}, "
            f"{s.laser_plane[2]:.5f}), {-s.laser_plane[3]:.3f} +- "
            f"{std.get('plane_d', nan):.2g} mm from the camera centre",
        ]
        if self.robot_pose_sigma is not None:
            lines.append(f"robot poses: uncertain, their errors estimated at "
                         f"{self.robot_pose_sigma[0]:.3f} mm and "
                         f"{self.robot_pose_sigma[1]:.4f} deg RMS per axis")
        if self.pose_errors_counted is not None:
            lines.append(f"robot poses: exact in the solve; the residuals show pose errors of "
                         f"about {self.pose_errors_counted[0]:.3f} mm and "
                         f"{self.pose_errors_counted[1]:.4f} deg RMS per axis, counted in "
                         "the uncertainties")
        if self.view_cameras_counted is not None:
            each = ", ".join(f"{k} {v:.2f}" for k, v in self.view_cameras_counted.items())
            lines.append(f"the views fit cameras of their own, differing by about {each} px "
                         "RMS from view to view (focus, heat, a loose lens, a lens model that "
                         "does not fit?), counted in the uncertainties")
        if self.mode == "chain":
            t = s.hand_from_camera[:3, 3]
            rv = rotation_to_vector(s.hand_from_camera[:3, :3])
            lines.append(f"hand_from_camera: t ({t[0]:.3f}, {t[1]:.3f}, {t[2]:.3f}) mm, rotation "
                         f"vector ({rv[0]:.5f}, {rv[1]:.5f}, {rv[2]:.5f}) rad "
                         f"({math.degrees(float(np.linalg.norm(rv))):.2f} deg)")
        lines.append(f"residuals: corners {self.corner_rms_px:.3f} px RMS, laser "
                     f"{self.laser_rms_mm:.4f} mm RMS; dropped as outliers: "
                     f"{self.dropped['corners']} corners, {self.dropped['laser_pixels']} stripe "
                     "pixels")
        if self.test_rms_mm is not None:
            lines.append(f"held-out views ({self.test_views}): stripe points lie "
                         f"{self.test_rms_mm:.4f} mm RMS from the board plane")
        lines.append("every unknown is determined by the data" if self.determined else
                     f"only {self.rank} of {self.num_unknowns} unknowns are determined")
        return "\n".join(lines)
