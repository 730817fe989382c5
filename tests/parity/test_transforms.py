"""geometry.transforms, the one home of rotations and rigid transforms, against OpenCV's
Rodrigues (an independent implementation)."""

from __future__ import annotations

import cv2
from hmlvs.geometry.transforms import (
    invert_transform,
    make_transform,
    rotation_angle,
    rotation_from_vector,
    rotation_to_vector,
)
import numpy as np
import pytest


@pytest.mark.parametrize("seed", range(3))
def test_rotation_vectors_agree_with_opencv_at_every_angle(seed):
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    # angles up to pi, including within 1e-7 of it, where the axis' sign is easy to lose
    angles = np.r_[rng.uniform(0, np.pi, 44), np.pi - 1e-7, np.pi - 1e-4, 1e-9, 0.0, np.pi / 2,
                   np.pi - 1e-10]
    for axis, angle in zip(axes, angles):
        rv = axis * angle
        r = rotation_from_vector(rv)
        np.testing.assert_allclose(r, cv2.Rodrigues(rv)[0], atol=1e-12)
        back = rotation_to_vector(r)
        # the same rotation (a vector of length pi and its negative are one rotation)
        np.testing.assert_allclose(rotation_from_vector(back), r, atol=1e-9)
        assert np.linalg.norm(back) <= np.pi + 1e-12
        if angle < np.pi - 1e-3:
            np.testing.assert_allclose(back, rv, atol=1e-9)
        assert rotation_angle(r) == pytest.approx(angle, abs=1e-6)


def test_transforms_compose_and_invert():
    rng = np.random.default_rng(4)
    for _ in range(20):
        t = make_transform(rng.normal(size=3), rng.normal(0, 100, 3))
        np.testing.assert_allclose(invert_transform(t) @ t, np.eye(4), atol=1e-12)
        np.testing.assert_allclose(invert_transform(t), np.linalg.inv(t), atol=1e-12)
        assert make_transform(t[:3, :3], t[:3, 3]).tolist() == t.tolist()
