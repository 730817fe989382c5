"""cv2.calibrateCamera on OpenCV's thread pool sums in a schedule-dependent order: on a loaded
machine the same corners gave focal lengths 2e-12 apart (relative), and the CLI and the library
calibrations of one session then differed in the last bits. hmlvs runs it on one thread."""

from __future__ import annotations

import cv2
from hmlvs import _opencv
from hmlvs.calibration.joint_setup import initial_intrinsics
from hmlvs.data.views import ViewData
from hmlvs.geometry.board import BoardSpec
import numpy as np


def _views() -> tuple[list[ViewData], BoardSpec]:
    board = BoardSpec(rows=5, cols=7, square=20.0)
    k = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    rng = np.random.default_rng(0)
    views = []
    for i in range(5):
        rv = rng.normal(0, 0.3, 3)
        t = np.array([-60.0, -40.0, 600.0]) + rng.normal(0, 20, 3)
        px = cv2.projectPoints(board.points(), rv, t, k, np.zeros(5))[0].reshape(-1, 2)
        views.append(ViewData(id=f"v{i}", corner_pixels=px, corner_index=np.arange(35),
                              laser_pixels=np.empty((0, 2))))
    return views, board


def test_calibrate_camera_runs_on_one_opencv_thread_and_restores_the_pool(monkeypatch):
    seen = []
    real = cv2.calibrateCamera

    def spy(*args, **kwargs):
        seen.append(cv2.getNumThreads())
        return real(*args, **kwargs)

    monkeypatch.setattr(cv2, "calibrateCamera", spy)
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    try:
        views, board = _views()
        intr, _, rms = initial_intrinsics(views, board, (640, 480), ("k1", "k2"))
        assert seen == [1] and cv2.getNumThreads() == 2
        assert abs(intr[0] - 800.0) < 1e-3 and rms < 1e-3  # exact corners: the true camera
        # and when it raises, the pool is put back too
        with np.testing.assert_raises(cv2.error):
            _opencv.calibrate_camera([], [], (640, 480), None, None)
        assert cv2.getNumThreads() == 2
    finally:
        cv2.setNumThreads(before)
