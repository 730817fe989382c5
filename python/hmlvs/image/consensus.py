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

from dataclasses import dataclass
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
    c = _Candidates.of(views, board, camera_matrix, dist_coeffs)
    cap = c.cap
    # The right hand-eye is among every view's candidates: those of the few views with the
    # fewest placements (the most corners) are tried as centres.
    counts = np.bincount(c.owner, minlength=c.n_views)
    sources = [v for v in np.argsort(counts, kind="stable") if counts[v] > 0][:CENTRE_VIEWS]
    centres = np.nonzero(np.isin(c.owner, sources))[0]
    scores = np.array([np.minimum(c.per_view(c.cand[i])[0], cap).mean() for i in centres])
    best, which = c.per_view(c.cand[centres[int(np.argmin(scores))]])
    agree = which[best < 0.5 * cap]
    which = which[which >= 0]
    x = np.asarray(_core._mean_transform(list(c.cand[agree])), float)
    s1 = float(np.minimum(c.per_view(x)[0], cap).mean())
    # the best rival: a candidate that moves the boards by half a square or more
    m1 = c.bfh[which] @ x[None] @ c.cfb[which]
    rival = np.inf
    for i, score in zip(centres, scores):
        shift = np.median(c.spread(c.bfh[which] @ c.cand[i][None] @ c.cfb[which], m1))
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


@dataclass
class _Candidates:
    """Every placement of every view as a candidate hand-eye (:func:`consensus_hand_eye`)."""

    owner: np.ndarray  # (n,) the view of each candidate
    bfh: np.ndarray  # (n, 4, 4) its view's base_from_hand
    cfb: np.ndarray  # (n, 4, 4) camera_from_board of its placement
    cand: np.ndarray  # (n, 4, 4) its hand_from_camera
    bfb: np.ndarray  # the board's base_from_board
    mu: np.ndarray  # the mean of the board's corners (board frame, mm)
    cov: np.ndarray  # and their covariance
    cap: float  # a square (mm): the most one view's distance counts

    @property
    def n_views(self) -> int:
        return int(self.owner.max()) + 1

    @classmethod
    def of(cls, views: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], board: Any,
           camera_matrix: np.ndarray, dist_coeffs: np.ndarray) -> "_Candidates":
        from ..geometry.board import board_pose_from_corners

        bfb = board.base_from_board()
        bxy = board.board_coordinates()
        pts = np.c_[bxy, np.zeros(len(bxy))]
        mu = pts.mean(axis=0)
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
                                 f"{MIN_VIEWS} are needed to number partly visible boards "
                                 "by their agreement")
        bfh_a, cfb_a = np.array(bfh_all), np.array(cfb_all)
        # each candidate's hand-eye: base_from_hand^-1 base_from_board board_from_camera
        cand = np.linalg.inv(bfh_a) @ bfb[None] @ np.linalg.inv(cfb_a)
        return cls(np.array(owner), bfh_a, cfb_a, cand, bfb, mu,
                   (pts - mu).T @ (pts - mu) / len(pts), float(board.square))

    def spread(self, m1: np.ndarray, m2: np.ndarray) -> np.ndarray:
        """RMS distance (mm) over the board's corners between their places under board
        poses m1 and m2 ((n, 4, 4), broadcast): |A mu + b|^2 + tr(A cov A^T) with A, b the
        difference of the rotations and the translations."""
        a = m1[:, :3, :3] - m2[:, :3, :3]
        off = a @ self.mu + (m1[:, :3, 3] - m2[:, :3, 3])
        return np.sqrt(np.sum(off**2, axis=1) + np.einsum("nij,jk,nik->n", a, self.cov, a))

    def per_view(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per view: its best placement's distance (mm) under hand-eye x, and which."""
        cost = self.spread(self.bfh @ x[None] @ self.cfb, self.bfb[None])
        order = np.lexsort((cost, self.owner))  # by view, then by distance
        first = order[np.r_[True, np.diff(self.owner[order]) != 0]]
        best = np.full(self.n_views, np.inf)
        which = np.full(self.n_views, -1)
        best[self.owner[first]], which[self.owner[first]] = cost[first], first
        return best, which
