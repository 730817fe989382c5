"""A dark frame's board (hmlvs.image.corners: a frame whose median lies below a tenth of the
full scale is searched once more on its contrast equalised). On a public robot capture one
frame of median 18 of 255, its board beside a saturated stripe, was found by neither
detector and used as laser-only; equalised, the classic detector finds its 42 corners."""

from __future__ import annotations

from hmlvs.geometry.board import Checkerboard
from hmlvs.image import corners as C
from hmlvs.sim.general import example_sensor, general_session, render_general_session
import numpy as np
import pytest

pytestmark = pytest.mark.scene  # rendered images

BOARD = Checkerboard(rows=5, cols=7, square=15.0)
SIZE = (640, 480)


@pytest.fixture(scope="module")
def dark():
    """Laser-off renders at a tenth of their light, lit unevenly (half the light from a
    broad spot at the upper left), with one grey level of noise: medians of 4 grey levels."""
    s = general_session(example_sensor(SIZE), BOARD, views=4, seed=2, distance=(330.0, 480.0))
    r = render_general_session(s)
    u = np.linspace(0, 1, SIZE[0])[None, :]
    v = np.linspace(0, 1, SIZE[1])[:, None]
    light = 0.5 + np.exp(-((u - 0.2) ** 2 + (v - 0.3) ** 2) / 0.08)
    frames = []
    for i in range(len(s)):
        img = r.off[i] * 0.1 * light + np.random.default_rng(i).normal(0, 1.0, light.shape)
        frames.append(np.clip(np.round(img), 0, 255).astype(np.uint8))
    return s, frames


def _found(frames, detect):
    out = []
    for img in frames:
        try:
            out.append(detect(img))
        except C.BoardNotFoundError:
            out.append(None)
    return out


def test_dark_frames_boards_are_found_where_the_plain_search_misses_them(dark, monkeypatch):
    s, frames = dark
    assert all(np.median(f) < 0.1 * 255 for f in frames)
    got = _found(frames, lambda f: C.detect_board(f, BOARD))
    with monkeypatch.context() as m:
        m.setattr(C, "_dark", lambda gray: False)
        plain = _found(frames, lambda f: C.detect_board(f, BOARD))
    assert sum(c is not None for c in got) >= 3
    assert sum(c is not None for c in plain) < sum(c is not None for c in got)
    for i, c in enumerate(got):
        if c is None:
            continue
        assert len(c) == BOARD.rows * BOARD.cols
        e = min((np.linalg.norm(c.pixels - t[c.index], axis=1)
                 for t in (s.corners[i], s.corners[i][::-1])), key=np.mean)
        # numbered right (a square is 20-30 px here) and measured as well as the light
        # allows: at a tenth of it the squares differ by 3-10 grey levels under one of
        # noise, and cornerSubPix on these frames measures 0.4-0.6 px RMS (up to 1.3 px),
        # against 0.016 px on the frames at full light
        assert np.sqrt(np.mean(e**2)) < 0.8 and e.max() < 2.0, (i, np.sort(e)[-3:])


def test_a_dark_frame_without_a_board_says_what_was_tried():
    img = np.random.default_rng(0).integers(0, 6, (480, 640)).astype(np.uint8)
    with pytest.raises(C.BoardNotFoundError, match="contrast equalised"):
        C.detect_board(img, BOARD)
