"""The board's corners on a laser-on frame alone: where the stripe's light runs over or beside
a corner, the corner is found where the light's edge crosses the squares' edges, pixels away.
Such corners are left out (hmlvs.image.partial.clear_of_stripe); a pair with a laser-off
frame keeps all its corners, found on that frame.

Measured on renders of the general sensor (5 sessions of 10 views, seeds 0-4): before, 21-31
of about 345 corners a session erred more than 0.3 px (up to 13 px; 3.7 px RMS within 3 px
of the stripe); now none of the 294-303 kept, at most 0.04 px, as on the laser-off frames;
the calibrations from the laser-on frames alone map the stripe 4-16 % closer to the truth
(0.009-0.041 mm RMS against 0.011-0.043, seed by seed)."""

from __future__ import annotations

from types import SimpleNamespace

from hmlvs.geometry.board import Checkerboard
from hmlvs.image.corners import detect_board
from hmlvs.image.partial import clear_of_stripe
from hmlvs.image.session import ESTIMATED_OFF, stripe_from_pair
from hmlvs.sim.general import example_sensor, general_session, render_general_session
import numpy as np
import pytest

pytestmark = pytest.mark.scene  # rendered images

BOARD = Checkerboard(rows=5, cols=7, square=15.0)
SIZE = (640, 480)


def _errors(s, i, corners) -> np.ndarray:
    """Each corner's distance from the truth (the board's numbering as detected, or turned)."""
    e = [np.linalg.norm(corners.pixels - t[corners.index], axis=1)
         for t in (s.corners[i], s.corners[i][::-1])]
    return min(e, key=np.mean)


@pytest.mark.parametrize("seed", [0, 4])
def test_corners_the_stripe_can_pull_are_left_out(seed):
    s = general_session(example_sensor(SIZE), BOARD, views=8, seed=seed,
                        distance=(330.0, 480.0))
    r = render_general_session(s)
    found = kept = 0
    for i in range(len(s)):
        corners = detect_board(r.on[i], BOARD)  # the laser-on frame: the stripe's light in it
        pair = SimpleNamespace(off_name=ESTIMATED_OFF, stripe=stripe_from_pair(r.on[i], None))
        clear = clear_of_stripe(corners, pair)
        e = _errors(s, i, clear)
        assert e.max() < 0.1, (i, np.sort(e)[-3:])
        # what was left out includes every corner the light pulled
        out = np.setdiff1d(corners.index, clear.index)
        pulled = corners.index[_errors(s, i, corners) > 0.3]
        assert set(pulled) <= set(out), (i, pulled, out)
        found += len(corners)
        kept += len(clear)
        # a pair with a laser-off frame keeps its corners (found on that frame)
        with_off = SimpleNamespace(off_name="v_off.png", stripe=pair.stripe)
        assert clear_of_stripe(corners, with_off) is corners
    assert kept >= 0.75 * found, (kept, found)


def test_a_grey_laser_on_session_numbers_its_corners_on_the_frames_themselves(tmp_path):
    """A session of grey laser-on frames alone: the corners are found on each frame itself
    (those near its stripe left out), not on the background estimated for the stripe, whose
    column opening wears the squares' tips down. Measured on this render: before, 0.26-0.31
    px RMS in some views, up to 1.2 px, far from the stripe; now every corner within 0.1 px
    of the truth. (Seeds 0-4 of 10 views: calibrations from the frames map the stripe
    0.005-0.019 mm RMS from the truth, against 0.011-0.043 mm before.)"""
    import json

    from hmlvs.data.manifest import write_png
    from hmlvs.image.views import views_from_images

    s = general_session(example_sensor(SIZE), BOARD, views=8, seed=3, distance=(330.0, 480.0))
    r = render_general_session(s)
    entries = []
    for i, pid in enumerate(r.ids):
        write_png(tmp_path / f"{pid}_on.png", r.on[i])
        entries.append({"id": pid, "on": f"{pid}_on.png", "pose": s.base_from_hand[i].tolist()})
    (tmp_path / "manifest.json").write_text(json.dumps(
        {"format": "hmlvs-images", "version": 1, "poses": entries,
         "board": {"rows": BOARD.rows, "cols": BOARD.cols, "square": BOARD.square}}))
    views, *_ = views_from_images(tmp_path)
    assert len(views) == len(s)
    for v in views:
        i = int(v.id[1:])
        e = [np.linalg.norm(v.corner_pixels - t[v.corner_index], axis=1)
             for t in (s.corners[i], s.corners[i][::-1])]
        e = min(e, key=np.mean)
        assert len(e) >= 20 and e.max() < 0.1, (v.id, len(e), np.sort(e)[-3:])


def test_a_stray_peak_far_from_the_stripe_sweeps_no_corner_away():
    """The stripe's centre line is drawn through its own light only: a clipped or double
    peak far from the stripe (the image's border, a shelf beside the board: on a real green
    stripe down a hand-held board, clipped peaks at the left border) is not on it. Here a
    few scan lines of a rendered laser-on frame alone are given such peaks at the image's
    top border: the corners left out are the same as without them (before, a line drawn
    through them left out corners up to the border)."""
    from dataclasses import replace

    from hmlvs.image.stripe import StripeStatus

    s = general_session(example_sensor(SIZE), BOARD, views=2, seed=1, distance=(330.0, 480.0))
    r = render_general_session(s)
    corners = detect_board(r.on[0], BOARD)
    stripe = stripe_from_pair(r.on[0], None)
    plain = clear_of_stripe(corners, SimpleNamespace(off_name=ESTIMATED_OFF, stripe=stripe))
    status, centre = stripe.status.copy(), stripe.centre.copy()
    # 40 scan lines mid-stripe without a centre (as where it crosses dark squares), and in
    # their middle four with a peak at the image's top border
    mid = np.flatnonzero(stripe.found)[stripe.found.sum() // 2]
    status[mid:mid + 40] = StripeStatus.MULTIPLE
    for way, code in zip(range(mid + 18, mid + 22), (StripeStatus.CLIPPED,
                                                     StripeStatus.DOUBLE_PEAK) * 2):
        status[way], centre[way] = code, 3.0
    stray = replace(stripe, status=status, centre=centre)
    got = clear_of_stripe(corners, SimpleNamespace(off_name=ESTIMATED_OFF, stripe=stray))
    assert len(plain) < len(corners)  # the stripe crosses the board here
    assert np.array_equal(got.index, plain.index), (np.setdiff1d(plain.index, got.index))
