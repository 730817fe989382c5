"""The camera and hand-eye on which views of a partly seen board agree, found before any of
those views is numbered.

A partly visible plain checkerboard is numbered only up to whole-square shifts and turns
(:func:`hmlvs.image.grid_place.grid_placements`). With the board's pose in the base known, each
placement of a view's corners implies a hand-eye (hand_from_camera = base_from_hand^-1
base_from_board camera_from_board^-1); under the right placements every view implies the same
one, under a wrong one the view's board lands a whole square (or a turn) away. So the hand-eye
is the one most views agree on (:func:`consensus_hand_eye`), and each view's numbering then
follows from it (:func:`hmlvs.image.grid_place.place_by_pose`), whatever the approximate
parameters predicted. The camera's intrinsics come from the same corners first
(:func:`grid_intrinsics`): a calibration from corners with an arbitrary numbering per view
is as good as with the true one, since each view has its own board pose."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from .. import _core
from .._opencv import calibrate_camera
from .corners import NumberingError
from .grid_place import grid_placements

#: fewest views with corners for the intrinsics and the consensus
MIN_VIEWS = 3
#: views whose candidate hand-eyes are tried as the consensus
CENTRE_VIEWS = 3


def grid_intrinsics(grids: Sequence[tuple[np.ndarray, np.ndarray]], square: float,
                    image_size: tuple[int, int], camera_matrix: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(camera matrix, distortion (5,)) from corners ``grids``: per view (pixels (k, 2),
    integer grid positions (k, 2)), in any numbering of the view's own.

    ``cv2.calibrateCamera`` from ``camera_matrix`` (the approximate parameters') with k1 and k2
    free (no tangential terms, k3 = 0): enough to place a board within a fraction of a
    square. Raises ``ValueError`` with fewer than :data:`MIN_VIEWS` views."""
    import cv2

    if len(grids) < MIN_VIEWS:
        raise ValueError(f"{len(grids)} views with corners; at least {MIN_VIEWS} are needed")
    obj = [np.c_[np.asarray(ij, float) * square, np.zeros(len(ij))].astype(np.float32)
           for _, ij in grids]
    img = [np.ascontiguousarray(px, np.float32).reshape(-1, 1, 2) for px, _ in grids]
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3)
    _, k, d, _, _ = calibrate_camera(obj, img, tuple(int(x) for x in image_size),
                                        np.array(camera_matrix, float), np.zeros(5), flags=flags)
    return np.asarray(k, float), np.asarray(d, float).ravel()


def consensus_hand_eye(views: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], board: Any,
                       camera_matrix: np.ndarray, dist_coeffs: np.ndarray,
                       ratio: float = 3.0) -> np.ndarray:
    """hand_from_camera (4x4) on which the most ``views`` agree.

    ``views``: per view (corner pixels (k, 2), integer grid positions (k, 2), base_from_hand
    (4, 4)); ``board`` is placed in the base (``base_from_board()``). Every placement of
    every view gives a candidate hand-eye; each is scored by how far, under it, every view's
    best placement puts the board from where it lies (RMS over its corners, mm, capped at a
    square so that one bad view cannot outvote the rest). The best candidate is refined as
    the mean of the views' agreeing hand-eyes (within half a square).

    Raises :class:`NumberingError` when the views cannot decide: a candidate that moves the
    boards by half a square or more scores within ``ratio`` of the best (the views' poses do
    not vary enough, e.g. all with the camera turned the same way).
    """
    from ..geometry.board import board_pose_from_corners

    bfb = board.base_from_board()
    bxy = board.board_coordinates()
    pts = np.c_[bxy, np.zeros(len(bxy))]
    mu = pts.mean(axis=0)
    cov = (pts - mu).T @ (pts - mu) / len(pts)

    def spread(m1: np.ndarray, m2: np.ndarray) -> np.ndarray:
        """RMS distance (mm) over the board's corners between their places under board
        poses m1 and m2 ((n, 4, 4), broadcast): |A mu + b|^2 + tr(A cov A^T) with A, b the
        difference of the rotations and the translations."""
        a = m1[:, :3, :3] - m2[:, :3, :3]
        off = a @ mu + (m1[:, :3, 3] - m2[:, :3, 3])
        return np.sqrt(np.sum(off**2, axis=1) + np.einsum("nij,jk,nik->n", a, cov, a))

    k, d = np.asarray(camera_matrix, float), np.asarray(dist_coeffs, float)
    owner, bfh_all, cfb_all = [], [], []
    for v, (px, ij, bfh) in enumerate(views):
        px = np.asarray(px, float)
        for idx, _ in grid_placements(ij[:, 0], ij[:, 1], board, px):
            cfb = board_pose_from_corners(pts[idx], px, k, d)
            if cfb is not None and cfb[2, 3] > 0:
                owner.append(v)
                bfh_all.append(np.asarray(bfh, float))
                cfb_all.append(cfb)
    if len(set(owner)) < MIN_VIEWS:
        raise NumberingError(f"only {len(set(owner))} views give a board pose; at least "
                             f"{MIN_VIEWS} are needed to number partly visible boards by "
                             "their agreement")
    owner_a = np.array(owner)
    bfh_a, cfb_a = np.array(bfh_all), np.array(cfb_all)
    # each candidate's hand-eye: base_from_hand^-1 base_from_board board_from_camera
    cand = np.linalg.inv(bfh_a) @ bfb[None] @ np.linalg.inv(cfb_a)
    n_views = int(owner_a.max()) + 1
    cap = float(board.square)

    def per_view(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per view: its best placement's distance (mm) under hand-eye x, and which."""
        cost = spread(bfh_a @ x[None] @ cfb_a, bfb[None])
        order = np.lexsort((cost, owner_a))  # by view, then by distance
        first = order[np.r_[True, np.diff(owner_a[order]) != 0]]
        best = np.full(n_views, np.inf)
        which = np.full(n_views, -1)
        best[owner_a[first]], which[owner_a[first]] = cost[first], first
        return best, which

    # The right hand-eye is among every view's candidates: those of the few views with the
    # fewest placements (the most corners) are tried as centres.
    counts = np.bincount(owner_a, minlength=n_views)
    sources = [v for v in np.argsort(counts, kind="stable") if counts[v] > 0][:CENTRE_VIEWS]
    centres = np.nonzero(np.isin(owner_a, sources))[0]
    scores = np.array([np.minimum(per_view(cand[c])[0], cap).mean() for c in centres])
    best, which = per_view(cand[centres[int(np.argmin(scores))]])
    agree = which[best < 0.5 * cap]
    which = which[which >= 0]
    x = np.asarray(_core._mean_transform(list(cand[agree])), float)
    s1 = float(np.minimum(per_view(x)[0], cap).mean())
    # the best rival: a candidate that moves the boards by half a square or more
    m1 = bfh_a[which] @ x[None] @ cfb_a[which]
    rival = np.inf
    for c, score in zip(centres, scores):
        shift = np.median(spread(bfh_a[which] @ cand[c][None] @ cfb_a[which], m1))
        if shift >= 0.5 * cap:
            rival = min(rival, float(score))
    # a floor of 2 % of a square: the corners' and the robot's noise
    if rival < ratio * max(s1, 0.02 * cap):
        raise NumberingError(
            "partly visible boards: the views do not agree on one numbering: the best "
            f"hand-eye puts the boards {s1:.1f} mm (mean) from the board's pose, another one "
            f"that moves them by half a square or more {rival:.1f} mm (vary the camera's "
            "turn about its axis between views)")
    return x
