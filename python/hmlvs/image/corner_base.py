"""Numbered checkerboard corners (:class:`Corners`), the options of their detection and the
small geometry shared by the detectors."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from numbers import Real
from typing import Any

import numpy as np


@dataclass(frozen=True)
class CornerOptions:
    """Options of :func:`find_corners` and :func:`detect_board`, checked on construction: a
    wrong type or value gives a ``ValueError`` naming the option.

    Attributes
    ----------
    extend : follow the board's homography to corners outside the detected grid
    max_error : a detected corner matches a predicted one within this fraction of the corner
        spacing (``find_corners`` with ``expected`` only)
    fallback : when ``findChessboardCornersSB`` finds no whole board, try the classic
        ``findChessboardCorners`` (+ ``cornerSubPix``) before giving up (whole board only)
    refine : "saddle" (default): ``cornerSubPix``, then the saddle point of the smoothed
        image (:func:`saddle_refine`); "cornersubpix": ``cornerSubPix`` alone, as OpenCV's
        classic pipeline
    """

    extend: bool = True
    max_error: float = 0.35
    fallback: bool = True
    refine: str = "saddle"

    def __post_init__(self) -> None:
        for name in ("extend", "fallback"):
            v = getattr(self, name)
            if not isinstance(v, (bool, np.bool_)):
                raise ValueError(f"corners.{name} must be true or false, got {v!r}")
            object.__setattr__(self, name, bool(v))
        v = self.max_error
        if isinstance(v, bool) or not isinstance(v, Real) or not (np.isfinite(v) and v > 0):
            raise ValueError(f"corners.max_error must be a positive number, got {v!r}")
        object.__setattr__(self, "max_error", float(v))
        if self.refine not in REFINE_METHODS:
            raise ValueError(f"corners.refine must be one of {', '.join(REFINE_METHODS)}, "
                             f"got {self.refine!r}")

    @classmethod
    def from_dict(cls, values: Any) -> "CornerOptions":
        """Options from a mapping (a configuration file's ``corners:`` block); an unknown
        name raises ``ValueError`` listing the valid ones."""
        if not isinstance(values, dict):
            raise ValueError(f"corner options must be a mapping, got {type(values).__name__}")
        valid = [f.name for f in fields(cls)]
        unknown = sorted(str(k) for k in values if k not in valid)
        if unknown:
            raise ValueError(f"unknown corner option(s) {', '.join(unknown)}; valid: "
                             f"{', '.join(valid)}")
        return cls(**values)


#: corner refinements (:class:`CornerOptions` ``refine``)
REFINE_METHODS = ("saddle", "cornersubpix")


@dataclass(frozen=True)
class Corners:
    """Checkerboard corners found in an image, each numbered on the board.

    Attributes
    ----------
    pixels : (k, 2) sub-pixel corner positions (u, v)
    index : (k,) row-major board corner index ``r * board.cols + c`` (0-based inner corners)
    anchor : (k,) True for corners found by ``findChessboardCornersSB``, False for corners
        added by following the board's homography into the rest of the image
    board : the :class:`~hmlvs.Checkerboard` the indices refer to
    rule : how the ordering was fixed: "expected" (nearest to predicted pixels),
        "top-left" (the marker-free rule for a fully visible board, :func:`detect_board`) or
        "top-left flipped" (that numbering turned by 180 degrees, :func:`flip_board_numbering`)
    """

    pixels: np.ndarray
    index: np.ndarray
    anchor: np.ndarray
    board: Any
    rule: str = "expected"
    image_size: tuple[int, int] | None = None  # (width, height) of the image
    #: (rows * cols, 2) findChessboardCornersSB's own sub-pixel positions by board index
    #: (NaN where it gave none), for a whole board it found; None otherwise
    detected: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.index.shape[0])

    def as_detected(self) -> "Corners":
        """The same board with ``findChessboardCornersSB``'s own positions (no refinement,
        no corners added by the homography); ``self`` when there are none."""
        if self.detected is None:
            return self
        idx = np.nonzero(np.isfinite(self.detected).all(axis=1))[0]
        return replace(self, pixels=self.detected[idx].copy(), index=idx,
                       anchor=np.ones(len(idx), bool))

    @property
    def rc(self) -> np.ndarray:
        """(k, 2) board (row, column) of each corner."""
        return np.stack([self.index // self.board.cols, self.index % self.board.cols], axis=1)

    @property
    def ids(self) -> list[str]:
        """Corner ids as :meth:`Checkerboard.corner_ids` spells them (``"r2c4"``)."""
        return [f"r{r}c{c}" for r, c in self.rc]

    @property
    def board_xy(self) -> np.ndarray:
        """(k, 2) board coordinates (mm) along the board's row and column directions."""
        return self.rc.astype(float) * self.board.square

    @property
    def points(self) -> np.ndarray:
        """(k, 3) corner positions in the robot base frame (mm)."""
        return self.board.corners()[self.index]


def to_8bit(gray: np.ndarray) -> np.ndarray:
    """An 8-bit copy for OpenCV's board detectors. A 16-bit image is scaled by its actual
    range (its 99.9th percentile), not by 1/256: 10- and 12-bit cameras store values up to
    1023 or 4095 in 16-bit files, which ``>> 8`` would squeeze into 0-3 or 0-15."""
    if gray.dtype == np.uint8:
        return np.ascontiguousarray(gray)
    top = float(np.percentile(gray, 99.9)) if gray.size else 0.0
    top = top if top > 0 else float(gray.max()) or 1.0
    return np.clip(gray.astype(np.float32) * (255.0 / top), 0, 255).astype(np.uint8)


def handedness(board: Any) -> float:
    """Sign of the image cross product (row step x column step) of a board seen from the
    side its ``normal`` points to: the camera's z axis looks into the scene, so a board frame
    whose row x col points towards the camera appears clockwise (negative) in (u, v)."""
    n = np.cross(board.row_direction, board.col_direction)
    return -1.0 if float(n @ board.normal) > 0 else 1.0


def orientation(px: np.ndarray, idx: np.ndarray, board: Any) -> float:
    """Image cross product sign of the board's row and column steps under a numbering."""
    return orientation_rc(px, np.stack([idx // board.cols, idx % board.cols], axis=-1))


def orientation_rc(px: np.ndarray, rc: np.ndarray) -> float:
    """Image cross product sign of the row and column steps of corners at board (row,
    column) positions ``rc``."""
    rc = np.asarray(rc).reshape(-1, 2).astype(float)
    # affine fit px = [r, c, 1] A: its 2x2 part holds the row and column steps
    a, *_ = np.linalg.lstsq(np.hstack([rc, np.ones((len(rc), 1))]), px.reshape(-1, 2),
                            rcond=None)
    return float(np.sign(a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]))


def corner_spacing(px: np.ndarray) -> float:
    """Median distance from each point to its nearest neighbour (px)."""
    d = np.linalg.norm(px[:, None, :] - px[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def refine_subpix(gray: np.ndarray, pts: np.ndarray, win: int) -> np.ndarray:
    import cv2
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    p = np.ascontiguousarray(pts, dtype=np.float32).reshape(-1, 1, 2)
    return cv2.cornerSubPix(gray, p, (win, win), (-1, -1), crit).reshape(-1, 2).astype(float)


def match_nearest(px: np.ndarray, pred: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest neighbours between detected px and predicted board corners within
    radius: (indices into px, board indices)."""
    d = np.linalg.norm(px[:, None, :] - pred[None, :, :], axis=2)
    d[:, ~np.isfinite(pred).all(axis=1)] = np.inf
    j = np.argmin(d, axis=1)
    i_back = np.argmin(d, axis=0)
    ok = (d[np.arange(len(px)), j] < radius) & (i_back[j] == np.arange(len(px)))
    return np.nonzero(ok)[0], j[ok]


def subpix_window(spacing: float) -> int:
    """``cornerSubPix``'s half-window (px) for corners ``spacing`` px apart: a fifth of the
    spacing, 2 to 9 px."""
    return int(np.clip(round(0.2 * spacing), 2, 9))


def away_from_light(corners: Corners, light: np.ndarray, width: np.ndarray) -> Corners:
    """The corners of a laser-on frame that its stripe cannot have pulled: those farther
    than the stripe's local width (FWHM) plus 1.5 x the refinement's half-window
    (:func:`subpix_window`) from every stripe centre ``light`` (m, 2), ``width`` (m,) the
    FWHM at each (NaN: the median's). A corner under or beside the stripe's light is found
    where that light's edge crosses the squares' edges: on renders of laser-on frames alone,
    the corners within 3 px of the stripe err 3.7 px RMS (up to 13 px), those 6-10 px away
    0.5 px (up to 1.8 px), those farther 0.016 px, as on the laser-off frames."""
    light = np.asarray(light, float).reshape(-1, 2)
    if len(corners) == 0 or len(light) == 0:
        return corners
    w = np.asarray(width, float).reshape(-1)
    w = np.where(np.isfinite(w), w, np.nanmedian(w) if np.isfinite(w).any() else 0.0)
    reach = w + 1.5 * subpix_window(corner_spacing(corners.pixels) if len(corners) > 1
                                    else 0.0)
    d = np.linalg.norm(corners.pixels[:, None, :] - light[None, :, :], axis=2)
    keep = ~(d < reach[None, :]).any(axis=1)
    if keep.all():
        return corners
    detected = None
    if corners.detected is not None:
        detected = corners.detected.copy()
        detected[corners.index[~keep]] = np.nan
    return replace(corners, pixels=corners.pixels[keep], index=corners.index[keep],
                   anchor=corners.anchor[keep], detected=detected)
