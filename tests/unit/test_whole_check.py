"""Whole-board views numbered whole squares off (a false row detected where the stripe meets
the board's edge) are numbered again from the robot chain (hmlvs.image.whole_check); views
numbered right, and views that show every row and column, are left as they are."""

from __future__ import annotations

from dataclasses import replace

from hmlvs.geometry.board import Checkerboard
from hmlvs.image.whole_check import renumbered_by_pose
from hmlvs.sim.features import synthetic_views
import numpy as np
import pytest

SIZE = (1024, 768)  # the synthetic views' camera


def _board(spec) -> Checkerboard:
    """The synthetic views' board, its directions such that the camera sees the side its
    corners turn as the views show them (the board's handedness)."""
    return Checkerboard(rows=spec.rows, cols=spec.cols, square=spec.square,
                        row_direction=(1.0, 0.0, 0.0), col_direction=(0.0, -1.0, 0.0))


def _row_off(view, cols: int, rows_kept: slice, shift: int):
    """The view with only the corners of rows ``rows_kept`` (as the stripe's clearing leaves
    them), their indices moved by ``shift`` rows (the detection one row off)."""
    idx = np.asarray(view.corner_index)
    keep = np.isin(idx // cols, np.arange(6)[rows_kept])
    return replace(view, corner_pixels=np.asarray(view.corner_pixels)[keep],
                   corner_index=idx[keep] + shift * cols)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_view_numbered_a_row_off_is_numbered_again(seed):
    views, spec, _, _ = synthetic_views(seed, n_views=8, corner_noise=0.1)
    board = _board(spec)
    wrong = _row_off(views[3], board.cols, slice(1, 6), -1)  # rows 1-5 numbered as 0-4
    short = _row_off(views[5], board.cols, slice(0, 5), 0)  # rows 0-4, numbered right
    given = [*views[:3], wrong, views[4], short, *views[6:]]
    got, moved = renumbered_by_pose(given, board, SIZE)
    assert list(moved) == [wrong.id]
    assert moved[wrong.id].startswith("numbered again from its robot pose as rows 1-5")
    np.testing.assert_array_equal(got[3].corner_index, wrong.corner_index + board.cols)
    for a, b in zip(got, given):
        if a.id != wrong.id:
            assert a is b


def test_too_few_views_of_the_whole_board_leave_every_view_as_it_is():
    views, spec, _, _ = synthetic_views(4, n_views=4, corner_noise=0.1)
    board = _board(spec)
    given = [views[0], views[1], *(_row_off(v, board.cols, slice(1, 6), -1) for v in views[2:])]
    got, moved = renumbered_by_pose(given, board, SIZE)
    assert moved == {} and got == given


def test_a_renumbered_view_says_so_in_its_account_and_its_inspection_line():
    from hmlvs.image.accounts import ImageReport
    from hmlvs.report.inspect import ViewInspection

    note = "numbered again from its robot pose as rows 1-5, columns 0-8, first corner r1c0"
    rep = ImageReport("im6", 6, "im6.png", "none", True, corners=37, note=note)
    assert rep.to_dict()["note"] == note
    assert "note" not in replace(rep, note="").to_dict()
    line = ViewInspection("im6", True, corners=37, note=note).line()
    assert line.startswith(f"im6: used, 37 corners ({note}), stripe")
