"""The planar checkerboard that provides reference points (paper section 5)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard lying in the robot's workspace, described in the base frame (mm).

    ``rows`` x ``cols`` inner corners spaced ``square`` mm. Corner (r, c) sits at
    ``origin + r * square * row_direction + c * square * col_direction``. The default is the
    paper's set-up: first (left-top) corner at (700, 90, 0) mm, 30 mm squares, the board
    extending towards the robot (-x) and to its right (-y) on the plane z = 0.
    """

    rows: int = 6
    cols: int = 8
    square: float = 30.0
    origin: tuple[float, float, float] = (700.0, 90.0, 0.0)
    row_direction: tuple[float, float, float] = (-1.0, 0.0, 0.0)
    col_direction: tuple[float, float, float] = (0.0, -1.0, 0.0)

    def __post_init__(self) -> None:
        if self.rows < 2 or self.cols < 2:
            raise ValueError(f"a checkerboard needs at least 2 x 2 inner corners, got "
                             f"{self.rows} x {self.cols}")
        if not self.square > 0:
            raise ValueError(f"square size must be > 0 mm, got {self.square}")
        r = np.asarray(self.row_direction, float)
        c = np.asarray(self.col_direction, float)
        if r.shape != (3,) or c.shape != (3,) or abs(np.linalg.norm(r) - 1) > 1e-9 or \
                abs(np.linalg.norm(c) - 1) > 1e-9 or abs(r @ c) > 1e-9:
            raise ValueError("row_direction and col_direction must be orthogonal unit 3-vectors")

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the board, pointing to the side the camera looks from."""
        n = np.cross(self.row_direction, self.col_direction)
        return n if n[2] >= 0 else -n

    def board_coordinates(self) -> np.ndarray:
        """(rows*cols, 2) corner coordinates on the board (mm), row-major order."""
        r, c = np.meshgrid(np.arange(self.rows), np.arange(self.cols), indexing="ij")
        return np.stack([r.ravel(), c.ravel()], axis=1) * self.square

    def corners(self) -> np.ndarray:
        """(rows*cols, 3) corner positions in the base frame (mm), row-major order."""
        rc = self.board_coordinates()
        return (np.asarray(self.origin, float)
                + rc[:, :1] * np.asarray(self.row_direction, float)
                + rc[:, 1:] * np.asarray(self.col_direction, float))

    def corner_ids(self) -> list[str]:
        return [f"r{r}c{c}" for r in range(self.rows) for c in range(self.cols)]

    def to_dict(self) -> dict[str, Any]:
        """The board as plain values (for manifests and calibration files)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    def base_from_board(self) -> np.ndarray:
        """4x4 transform from board coordinates (x along rows, y along columns) to base."""
        t = np.eye(4)
        t[:3, 0] = self.row_direction
        t[:3, 1] = self.col_direction
        t[:3, 2] = np.cross(self.row_direction, self.col_direction)
        t[:3, 3] = self.origin
        return t


@dataclass(frozen=True)
class BoardSpec:
    """A checkerboard: ``rows`` x ``cols`` inner corners spaced ``square`` mm. Corner (r, c)
    lies at (r * square, c * square, 0) in the board frame (as :class:`hmlvs.Checkerboard`)."""

    rows: int
    cols: int
    square: float

    def __post_init__(self) -> None:
        if int(self.rows) < 2 or int(self.cols) < 2:
            raise ValueError(f"a board needs at least 2 x 2 inner corners, got {self.rows} x "
                             f"{self.cols}")
        if not float(self.square) > 0:
            raise ValueError(f"the board's square size must be > 0 mm, got {self.square}")

    @classmethod
    def of(cls, board: Any) -> "BoardSpec":
        if isinstance(board, BoardSpec):
            return board
        if isinstance(board, dict):
            return cls(int(board["rows"]), int(board["cols"]), float(board["square"]))
        return cls(int(board.rows), int(board.cols), float(board.square))

    def points(self, index: np.ndarray | None = None) -> np.ndarray:
        """(k, 3) board-frame points of corner indices ``r * cols + c`` (all by default)."""
        idx = np.arange(self.rows * self.cols) if index is None else np.asarray(index, int)
        return np.stack([idx // self.cols * self.square, idx % self.cols * self.square,
                         np.zeros(idx.size)], axis=1)

    def flip(self) -> np.ndarray:
        """The 180-degree turn of the board about its centre (4x4): corner index i and
        rows*cols - 1 - i swap places."""
        f = np.diag([-1.0, -1.0, 1.0, 1.0])
        f[0, 3] = (self.rows - 1) * self.square
        f[1, 3] = (self.cols - 1) * self.square
        return f
