"""The NumPy composition of hmlvs.Measurer's profile (parity oracle of its C++ kernel).

``profile(model, frame, base_from_hand, off, **options)`` is Measurer.points as it was composed
in Python before a frame's measurement moved into one C++ call (cpp/hmlvs/measure/profile.h):
the stripe of :func:`hmlvs.image.session.stripe_from_pair`, its found centres through the sensor
model's ``points_in_camera`` (on_invalid="mask"), and the base transform base_from_hand
hand_from_camera applied to them. The transform is written out element by element, each sum
left to right, rather than with ``@``: NumPy's matrix product goes through BLAS, whose kernels
sum in another order and fuse multiplies with adds on some CPUs (within 1 ulp of these sums),
so only the elementwise form pins the bits. tests/parity/test_profiles.py compares the two.
"""

from __future__ import annotations

from typing import Any

from hmlvs.image.session import stripe_from_pair
from hmlvs.image.stripe import StripeStatus
from hmlvs.measurement.measurer import PointStatus
import numpy as np

FIELDS = ("pixels", "points", "camera_points", "status", "stripe_status")


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b of 4 x 4 transforms, each entry a(i, 0) b(0, j) + ... + a(i, 3) b(3, j) in order."""
    return ((a[:, 0:1] * b[0] + a[:, 1:2] * b[1]) + a[:, 2:3] * b[2]) + a[:, 3:4] * b[3]


def transformed(m: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k, 3) points through the 4 x 4 transform m, each coordinate summed in order."""
    p = points
    return ((p[:, 0:1] * m[:3, 0] + p[:, 1:2] * m[:3, 1]) + p[:, 2:3] * m[:3, 2]) + m[:3, 3]


def profile(model: Any, frame: np.ndarray, base_from_hand: np.ndarray,
            off: np.ndarray | None = None, **options: Any) -> dict[str, np.ndarray]:
    """The profile's arrays (``FIELDS``) of ``frame`` measured with the sensor model ``model``
    (a :class:`hmlvs.models.base.SensorModel`) and the stripe options ``options``."""
    n = frame.shape[1]
    out = {"pixels": np.full((n, 2), np.nan), "points": np.full((n, 3), np.nan),
           "camera_points": np.full((n, 3), np.nan),
           "status": np.full(n, PointStatus.NO_STRIPE, np.uint8),
           "stripe_status": np.full(n, StripeStatus.NONE, np.uint8)}
    try:
        stripe = stripe_from_pair(frame, off, **options)
    except ValueError as e:
        if "leaves no pixel" not in str(e):
            raise
        return out
    assert stripe.direction == "columns"
    lines = np.asarray(stripe.position, np.intp)
    out["stripe_status"][lines] = stripe.status
    found = lines[stripe.status == StripeStatus.FOUND]
    px = np.stack([found.astype(float), stripe.centre[found]], axis=1)
    cam, ok = model.points_in_camera(px, on_invalid="mask")
    base_from_camera = compose(np.asarray(base_from_hand, float),
                               np.asarray(model.hand_from_camera_matrix(), float))
    out["pixels"][found] = px
    out["camera_points"][found[ok]] = cam[ok]
    out["points"][found[ok]] = transformed(base_from_camera, cam[ok])
    out["status"][found] = np.where(ok, PointStatus.MEASURED, PointStatus.NO_POINT)
    return out
