"""The planar checkerboard that provides reference points (paper section 5)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np


def board_pose_from_corners(board_points: np.ndarray, pixels: np.ndarray,
                            camera_matrix: np.ndarray, dist_coeffs: np.ndarray
                            ) -> np.ndarray | None:
    """camera_from_board (4x4, mm) of board corners at ``board_points`` (k, 3, board frame)
    seen at ``pixels`` (k, 2) by a camera (OpenCV's model): ``cv2.solvePnP``; None when it
    finds no pose."""
    import cv2

    ok, rvec, tvec = cv2.solvePnP(np.asarray(board_points, float), np.asarray(pixels, float),
                                  np.asarray(camera_matrix, float), np.asarray(dist_coeffs, float))
    if not ok:
        return None
    pose = np.eye(4)
    pose[:3, :3] = cv2.Rodrigues(rvec)[0]
    pose[:3, 3] = np.ravel(tvec)
    return pose


#: inner corners per side a board may have (a bound, so that a typo such as rows: 1000000
#: is a sentence rather than an allocation of terabytes)
MAX_CORNERS = 1000

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
        if self.rows > MAX_CORNERS or self.cols > MAX_CORNERS:
            raise ValueError(f"a checkerboard has at most {MAX_CORNERS} inner corners per "
                             f"side, got {self.rows} x {self.cols}")
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
        if int(self.rows) > MAX_CORNERS or int(self.cols) > MAX_CORNERS:
            raise ValueError(f"a board has at most {MAX_CORNERS} inner corners per side, got "
                             f"{self.rows} x {self.cols}")
        if not float(self.square) > 0:
            raise ValueError(f"the board's square size must be > 0 mm, got {self.square}")

    @classmethod
    def of(cls, board: Any) -> "BoardSpec":
        if isinstance(board, BoardSpec):
            return board
        if isinstance(board, dict) and board.get("type") == "charuco":
            return CharucoSpec.from_dict(board)
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

    @property
    def unambiguous(self) -> bool:
        """True when the board's own markings number every corner it shows (a ChArUco board's
        marker ids), so no view's numbering is ever turned; False for a plain checkerboard,
        which looks the same turned by 180 degrees (see :meth:`flip`)."""
        return False


@dataclass(frozen=True, init=False)
class CharucoSpec(BoardSpec):
    """A ChArUco board (OpenCV's ``cv2.aruco.CharucoBoard``): ``squares_x`` x ``squares_y``
    squares of ``square`` mm, ArUco markers of ``marker`` mm from the dictionary named
    ``dictionary`` (``"DICT_4X4_50"``, ... as ``cv2.aruco`` spells it) in the white squares.

    Its chessboard corners are the (squares_y - 1) x (squares_x - 1) inner corners: ``rows =
    squares_y - 1``, ``cols = squares_x - 1``. ChArUco corner id k is board corner index k:
    corner (r, c) = (k // cols, k % cols) lies at (r * square, c * square, 0) as for any
    :class:`BoardSpec`. (OpenCV puts the same corner at ((c + 1) * square, (r + 1) * square,
    0); the two frames differ by a swap of x and y and a shift, and every corner keeps its id.)
    The ids tell every corner from its 180-degree twin, so the board is ``unambiguous``, is
    numbered in any view, also when only part of it is visible, and is never flipped.
    """

    marker: float
    dictionary: str

    def __init__(self, squares_x: int, squares_y: int, square: float, marker: float,
                 dictionary: str = "DICT_4X4_50") -> None:
        for name, v in (("squares_x", squares_x), ("squares_y", squares_y)):
            if isinstance(v, bool) or int(v) != v or int(v) < 3:
                raise ValueError(f"a ChArUco board needs {name} >= 3 squares, got {v!r}")
        object.__setattr__(self, "rows", int(squares_y) - 1)
        object.__setattr__(self, "cols", int(squares_x) - 1)
        object.__setattr__(self, "square", float(square))
        object.__setattr__(self, "marker", float(marker))
        object.__setattr__(self, "dictionary", str(dictionary))
        self.__post_init__()
        if not 0 < self.marker < self.square:
            raise ValueError(f"the ChArUco marker length must be > 0 and smaller than the square "
                             f"({self.square} mm), got {marker}")
        import cv2

        if not self.dictionary.startswith("DICT_") or \
                not hasattr(cv2.aruco, self.dictionary):
            names = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and
                           n == n.upper())
            raise ValueError(f"unknown ArUco dictionary {dictionary!r}; choose one of "
                             f"{', '.join(names)}")
        if self.rows * self.cols // 2 + 1 > self.dictionary_size():
            raise ValueError(f"a {squares_x} x {squares_y} ChArUco board needs more markers "
                             f"than {self.dictionary} holds ({self.dictionary_size()})")

    @property
    def squares_x(self) -> int:
        return self.cols + 1

    @property
    def squares_y(self) -> int:
        return self.rows + 1

    @property
    def unambiguous(self) -> bool:
        return True

    def dictionary_size(self) -> int:
        import cv2

        return int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
                   .bytesList.shape[0])

    def flip(self) -> np.ndarray:
        raise ValueError("a ChArUco board is numbered by its marker ids and is never turned")

    def cv_board(self) -> Any:
        """The ``cv2.aruco.CharucoBoard`` (lengths in mm)."""
        import cv2

        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square,
                                      self.marker, d)

    def to_dict(self) -> dict[str, Any]:
        """The manifest's ``board:`` form."""
        return {"type": "charuco", "squares_x": self.squares_x, "squares_y": self.squares_y,
                "square": self.square, "marker": self.marker, "dictionary": self.dictionary}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "CharucoSpec":
        """From the manifest's ``board: {type: charuco, squares_x, squares_y, square, marker,
        dictionary}`` (``dictionary`` defaults to DICT_4X4_50)."""
        need = ("squares_x", "squares_y", "square", "marker")
        missing = [k for k in need if k not in values]
        if missing:
            raise ValueError(f"the ChArUco board lacks {', '.join(missing)}")
        unknown = sorted(str(k) for k in values if k not in (*need, "dictionary", "type"))
        if unknown:
            raise ValueError(f"unknown ChArUco board field(s) {', '.join(unknown)}; valid: "
                             f"type, {', '.join(need)}, dictionary")
        return cls(values["squares_x"], values["squares_y"], values["square"],
                   values["marker"], values.get("dictionary", "DICT_4X4_50"))
