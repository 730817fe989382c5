"""The views of an image session, the observations both sensor models calibrate from: per
image, the board corners found and numbered, the stripe (its pixels, and every scan line with
its status) and the robot pose."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np


@dataclass
class ViewData:
    """What one view contributes: its corners, its stripe pixels and (optionally) its pose.

    corner_pixels : (k, 2) detected corners; corner_index : (k,) their board indices
    laser_pixels : (m, 2) stripe pixels (any that miss the board are dropped by the solve's
        set-up); base_from_hand : the robot's 4x4 pose, None without a robot
    stripe : the stripe of a view read from images, every scan line with its centre, noise
        and status (a :class:`hmlvs.image.stripe.StripeResult`, corrected as its
        ``laser_pixels`` were), from which the paper model's calibration points are derived
        (:func:`hmlvs.image.points.view_points`); None for views made otherwise
    joints : the joint readings (rad) the pose was computed from, when the view's record
        gave them
    """

    id: str
    corner_pixels: np.ndarray
    corner_index: np.ndarray
    laser_pixels: np.ndarray
    base_from_hand: np.ndarray | None = None
    stripe: Any = None
    joints: np.ndarray | None = None


def split_views(views: Sequence[ViewData], holdout: float, seed: int = 0
                ) -> tuple[list[ViewData], list[ViewData]]:
    """The views to calibrate on and a held-out fraction ``holdout`` of them (at least one
    when > 0), drawn with ``seed``; ``holdout`` 0 holds none out."""
    views = list(views)
    if holdout == 0:
        return views, []
    if not 0 < holdout < 1:
        raise ValueError(f"--holdout must be a fraction in (0, 1), got {holdout}")
    rng = np.random.default_rng(seed)
    n_test = max(1, int(round(holdout * len(views))))
    pick = set(rng.choice(len(views), n_test, replace=False).tolist())
    return ([v for i, v in enumerate(views) if i not in pick],
            [v for i, v in enumerate(views) if i in pick])
