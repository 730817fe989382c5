"""OpenCV calls whose results must not depend on the machine's load.

``cv2.calibrateCamera`` run on OpenCV's thread pool sums in an order that depends on how the
pool's threads are scheduled: on a loaded machine two calls on the same corners differ in the
last bits (2e-12 relative in the focal length, measured), and so would every calibration
started from them. Here it runs on one thread (it takes milliseconds); the pool's size is put
back afterwards.
"""

from __future__ import annotations

import threading
from typing import Any

_LOCK = threading.Lock()


def calibrate_camera(*args: Any, **kwargs: Any) -> Any:
    """``cv2.calibrateCamera`` on one OpenCV thread: bit-for-bit repeatable."""
    import cv2

    with _LOCK:
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            return cv2.calibrateCamera(*args, **kwargs)
        finally:
            cv2.setNumThreads(threads)
