"""Whole-board views checked against the robot chain for a shifted numbering.

A whole board's detection is numbered by the top-left rule and its half-turn twins are made
consistent in the joint solve. A detection can also be off by whole squares: a row of false
corners where a bright stripe meets the board's edge taken for the board's first row, the
true first row missed (the Blaser frames seen in grey: one view in 14, numbered a row off).
Once the corners the stripe can have pulled are left out, such a view no longer shows all
the board's rows (or columns), and under a shifted placement its corners put the board
exactly where the other views do: as a partly visible board's are placed
(:func:`hmlvs.image.grid_place.place_by_pose`), the view is renumbered when one placement
puts the board clearly nearer (:data:`RATIO` times) the first calibration's board, within
half a square; otherwise it is left as detected."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ..data.views import ViewData
from .grid_place import board_apart, grid_placements

#: how much nearer the chosen placement must put the board than the detected numbering
#: (the partly visible boards' rule, :func:`hmlvs.image.grid_place.place_by_pose`)
RATIO = 3.0


def _short(index: np.ndarray, board: Any) -> bool:
    """Whether corners with board indices ``index`` miss a whole row or column of the board
    (so that a shift of the numbering keeps them on it)."""
    r, c = np.divmod(np.asarray(index, int), board.cols)
    return bool(r.size) and (np.ptp(r) < board.rows - 1 or np.ptp(c) < board.cols - 1)


def renumbered_by_pose(views: list[ViewData], board: Any, image_size: tuple[int, int],
                       base_from_board: np.ndarray | None = None
                       ) -> tuple[list[ViewData], dict[str, str]]:
    """``views`` (whole-board views, with robot poses) with those whose numbering the robot
    chain clearly places whole squares away renumbered, and per renumbered view what moved
    (see the module's documentation). Needs 3 views that show every row and column."""
    from ..calibration.joint import calibrate_joint

    posed = [v for v in views if v.base_from_hand is not None]
    suspects = [v.id for v in posed if len(v.corner_index) and _short(v.corner_index, board)]
    full = [v for v in posed if v.id not in suspects and len(v.corner_index)]
    if not suspects or len(full) < 3:
        return views, {}
    try:
        first = calibrate_joint(full, board, image_size, base_from_board=base_from_board)
    except ValueError:
        return views, {}
    sensor = first.sensor
    out, moved = [], {}
    for v in views:
        if v.id not in suspects:
            out.append(v)
            continue
        idx = np.asarray(v.corner_index, int)
        px = np.asarray(v.corner_pixels, float)
        apart = board_apart(px, board, sensor.camera_matrix, sensor.dist_coeffs,
                            v.base_from_hand @ sensor.hand_from_camera, sensor.base_from_board)
        now = apart(idx)
        scored = [(apart(new), desc, new)
                  for new, desc in grid_placements(*np.divmod(idx, board.cols), board, px)]
        best, desc, new = min(scored, key=lambda x: x[0], default=(np.inf, "", idx))
        if np.array_equal(new, idx) or best > 0.5 * board.square or now < RATIO * best:
            out.append(v)
            continue
        out.append(replace(v, corner_index=new))
        moved[v.id] = (f"numbered again from its robot pose as {desc}: as detected, its "
                       f"board lay {now:.1f} mm from where the other views put it; now "
                       f"{best:.2f} mm")
    return out, moved
