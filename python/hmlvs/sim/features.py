"""Synthetic features of a general sensor (model "opencv"): board corners and stripe pixels of
views looking at a board, projected with OpenCV (``cv2.projectPoints``, independent of the C++
model), plus Gaussian noise. For tests and benchmarks of the joint calibration without images
(:mod:`hmlvs.sim.general` renders images)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ..data.views import ViewData
from ..geometry.board import BoardSpec


def transform(rotvec: Any, t: Any) -> np.ndarray:
    """4x4 transform of a rotation vector (rad) and a translation."""

    m = np.eye(4)
    m[:3, :3] = cv2.Rodrigues(np.asarray(rotvec, float).reshape(3, 1))[0]
    m[:3, 3] = t
    return m


@dataclass
class Truth:
    """The general sensor behind synthetic features (OpenCV camera, laser plane (a, b, c, d),
    hand_from_camera, base_from_board)."""

    camera_matrix: np.ndarray
    dist: np.ndarray
    hand_from_camera: np.ndarray
    base_from_board: np.ndarray
    plane: np.ndarray


def default_truth() -> Truth:
    """A general sensor unlike the paper's: 1024 x 768, k1 -0.165, a laser plane 1.5 degrees
    out of the camera's y-z plane, the camera turned ~90 degrees about the flange axis."""
    n = np.array([0.026, 0.6, 0.8])  # 1.5 degrees out of the camera's y-z plane
    n /= np.linalg.norm(n)
    return Truth(camera_matrix=np.array([[1100.0, 0, 512], [0, 1090, 384], [0, 0, 1]]),
                 dist=np.array([-0.165, 0.05, 0.0005, -0.0003, 0.0]),
                 hand_from_camera=transform([0.02, -0.03, 1.6], [60, 5, -45]),
                 base_from_board=transform([0.05, 0.02, 0.3], [700, 50, 10]),
                 plane=np.r_[n, -n @ np.array([0, 60, 400])])


def project(truth: Truth, camera_points: np.ndarray) -> np.ndarray:
    """Camera-frame points -> pixels with cv2.projectPoints."""

    px, _ = cv2.projectPoints(np.asarray(camera_points, float), np.zeros(3), np.zeros(3),
                              truth.camera_matrix, truth.dist)
    return px[:, 0]


def synthetic_views(seed: int, n_views: int = 20, corner_noise: float = 0.1,
               laser_noise: float = 0.1, truth: Truth | None = None,
               board: BoardSpec | None = None, flip_every: int = 0,
               stripe_samples: int = 400, spread: float = 20.0
               ) -> tuple[list[ViewData], BoardSpec, Truth, list[np.ndarray]]:
    """Views of the board from varied poses; returns views, board, truth, and each view's
    exact stripe points in the base frame (for map-error checks).

    stripe_samples : points sampled along the stripe across the board's width; those on the
        board (all of them in most views, at least 15 %) become the view's stripe pixels, so
        the default 400 gives ~200-400 a view and 800 about twice as many. The stripe noise
        draws from the same generator, so another value also changes the later views.
    spread : the standard deviation (mm) of the board centre's offset across the optical axis;
        a larger one puts boards towards the image's edges and corners (views whose corners
        leave the image are drawn again)."""
    truth = truth or default_truth()
    board = board or BoardSpec(6, 9, 25.0)
    rng = np.random.default_rng(seed)
    pts = board.points()
    size = ((board.rows - 1) * board.square, (board.cols - 1) * board.square)
    views, laser_base = [], []
    while len(views) < n_views:
        # the board's centre near the optical axis, 400-500 mm away
        cb = transform(rng.uniform(-0.4, 0.4, 3), [0, 0, 0])
        cb[:3, 3] = cb[:3, :3] @ np.array([-size[0] / 2, -size[1] / 2, 0]) + \
            np.array([rng.normal(0, spread), rng.normal(0, spread), 450 + rng.uniform(-50, 50)])
        bfh = truth.base_from_board @ np.linalg.inv(cb) @ np.linalg.inv(truth.hand_from_camera)
        corners = project(truth, pts @ cb[:3, :3].T + cb[:3, 3])
        # The stripe: board points (x, y, 0) on the laser plane, x across the board.
        n, d = truth.plane[:3], truth.plane[3]
        xs = np.linspace(-0.4 * board.square, size[0] + 0.4 * board.square,
                         stripe_samples)
        a = n @ cb[:3, 1]
        ys = -(n @ (np.outer(cb[:3, 0], xs) + cb[:3, 3:4]) + d) / a
        ok = (ys > -0.4 * board.square) & (ys < size[1] + 0.4 * board.square)
        if ok.sum() < 0.15 * stripe_samples:  # 60 of the default 400
            continue
        cam = (np.outer(xs[ok], cb[:3, 0]) + np.outer(ys[ok], cb[:3, 1]) + cb[:3, 3])
        stripe = project(truth, cam)
        inside = (corners.min(0) > 5).all() and (corners[:, 0].max() < 1019) and \
            (corners[:, 1].max() < 763)
        if not inside:
            continue
        idx = np.arange(len(pts))
        if flip_every and len(views) % flip_every == 1:
            idx = len(pts) - 1 - idx
        views.append(ViewData(f"v{len(views):02d}", corners + rng.normal(0, corner_noise,
                                                                          corners.shape),
                              idx, stripe + rng.normal(0, laser_noise, stripe.shape), bfh))
        hand = cam @ truth.hand_from_camera[:3, :3].T + truth.hand_from_camera[:3, 3]
        laser_base.append(hand @ bfh[:3, :3].T + bfh[:3, 3])
    return views, board, truth, laser_base
