"""``hmlvs inspect``: per view a PNG with the numbered corners and the stripe coloured by
status, and one terminal line saying whether the view is used and why not."""

from __future__ import annotations

import json

import cv2
from hmlvs.cli import main as cli_main
from hmlvs.image.stripe import StripeResult, StripeStatus
from hmlvs.report.inspect import (
    CORNER_COLOUR,
    STATUS_COLOURS,
    TICK,
    draw_view,
    inspect_session,
)
from hmlvs.sim.general import general_session, render_general_session
import numpy as np
import pytest


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """3 rendered views of the general sensor; the laser-off frame of v001 is replaced by a
    blank wall (its stripe kept), so that view has no board: a laser-only view, its stripe on
    the board's plane."""
    d = tmp_path_factory.mktemp("inspect")
    r = render_general_session(general_session(views=3, seed=4), d)
    on = cv2.imread(str(d / "v001_on.png"), cv2.IMREAD_UNCHANGED)
    off = cv2.imread(str(d / "v001_off.png"), cv2.IMREAD_UNCHANGED)
    top = np.iinfo(off.dtype).max
    blank = np.full(off.shape, 0.4 * top)
    stripe = np.clip(on.astype(float) - off, 0, None)
    cv2.imwrite(str(d / "v001_off.png"), blank.astype(off.dtype))
    cv2.imwrite(str(d / "v001_on.png"), np.clip(blank + stripe, 0, top).astype(off.dtype))
    truth = json.loads((d / "truth.json").read_text())
    return d, r, truth


def test_inspect_draws_each_view_and_says_which_are_used(session, tmp_path):
    d, r, truth = session
    views = inspect_session(d, tmp_path / "out")
    assert [v.id for v in views] == ["v000", "v001", "v002"]
    # the view without a board is used for its stripe alone (through its robot pose)
    assert [v.used for v in views] == [True, True, True]
    assert views[1].reason == "" and views[1].corners == 0
    n = truth["board"]["rows"] * truth["board"]["cols"]
    for v in (views[0], views[2]):
        assert v.corners == n and v.reason == ""
        assert v.stripe["FOUND"] > 300
    # the view without a board still shows its stripe
    assert views[1].stripe["FOUND"] > 300
    assert views[1].line().startswith("v001: used (laser only, no board seen), 0 corners")
    assert views[0].line().startswith(f"v000: used, {n} corners, stripe FOUND ")
    for v, view_truth in zip(views, truth["views"]):
        img = cv2.imread(str(v.image))
        assert img is not None and img.shape == (768, 1024, 3)
        # a corner mark (yellow) near every true corner of a used view, none on the blank one
        yellow = np.all(img == CORNER_COLOUR, axis=2)
        near = [yellow[max(int(y) - 6, 0):int(y) + 7, max(int(x) - 6, 0):int(x) + 7].any()
                for x, y in view_truth["corners"]]
        if v.corners:
            assert np.mean(near) > 0.95, v.id
        else:
            assert not yellow[40:].any(), v.id  # (the title is white)
        # the stripe centres in green on the true stripe rows
        green = np.all(img == STATUS_COLOURS[StripeStatus.FOUND], axis=2)
        vs = np.array([np.nan if s is None else s for s in view_truth["stripe_v"]])
        cols = np.nonzero(green.any(axis=0) & np.isfinite(vs))[0]
        assert len(cols) > 300, v.id
        rows = np.array([np.nonzero(green[:, c])[0].mean() for c in cols])
        assert np.median(np.abs(rows - vs[cols])) < 1.5, v.id


def test_inspect_command_prints_one_line_per_view(session, tmp_path, capsys):
    d, _, _ = session
    with pytest.raises(SystemExit) as e:
        cli_main(["inspect", str(d), "--out", str(tmp_path / "pics")])
    out = capsys.readouterr().out
    assert e.value.code in (0, None)
    lines = out.strip().splitlines()
    assert lines[0].startswith("v000: used, ")
    assert lines[1].startswith("v001: used (laser only, no board seen), 0 corners")
    assert lines[2].startswith("v002: used, ")
    assert lines[3] == f"3 of 3 views used; pictures in {tmp_path / 'pics'}"
    assert sorted(p.name for p in (tmp_path / "pics").iterdir()) == \
        ["v000.png", "v001.png", "v002.png"]


def test_inspect_without_a_board_in_the_manifest_says_so(session, tmp_path, capsys):
    d, _, _ = session
    doc = json.loads((d / "manifest.json").read_text())
    del doc["board"]
    for e in doc["poses"]:
        e["on"], e["off"] = str(d / e["on"]), str(d / e["off"])
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(SystemExit) as e:
        cli_main(["inspect", str(tmp_path), "--out", str(tmp_path / "pics")])
    assert e.value.code == 2
    assert "no 'board'" in capsys.readouterr().err


def test_rejected_scan_lines_are_marked_at_the_border_in_their_status_colour():
    n = 200
    status = np.full(n, StripeStatus.NONE, np.uint8)
    status[20:60] = StripeStatus.FOUND
    status[70:75] = StripeStatus.MULTIPLE
    status[90:92] = StripeStatus.TOO_WIDE
    # the stripe at row 150 of 200: the header (title and the marks' legend, wrapped at the
    # image's width) covers the top rows of so narrow an image
    centre = np.where(status == StripeStatus.FOUND, 150.0, np.nan)
    nan = np.full(n, np.nan)
    stripe = StripeResult(np.arange(n), centre, nan, nan, nan, status, np.zeros(n, int),
                          "columns", "centroid", 10.0, 1.0)
    img = draw_view(np.full((200, n), 80, np.uint8), None, stripe, "")
    for s, cols in ((StripeStatus.MULTIPLE, range(70, 75)), (StripeStatus.TOO_WIDE, (90, 91))):
        mark = np.all(img[200 - TICK:, :] == STATUS_COLOURS[s], axis=2)
        assert sorted(set(np.nonzero(mark)[1].tolist())) == list(cols)
    green = np.all(img == STATUS_COLOURS[StripeStatus.FOUND], axis=2)
    assert set(np.nonzero(green)[0].tolist()) <= {149, 150, 151}
    assert set(np.nonzero(green)[1].tolist()) == set(range(19, 61))


def test_centres_the_pipeline_dropped_off_the_line_are_drawn_apart():
    # the pipeline dropped the found centres of columns 20-24 as off the stripe's line
    # (status OFF_LINE, views_from_images): drawn in their own colour, marked at the border
    # and named in the header, not in the found centres' green
    n = 200
    status = np.full(n, StripeStatus.NONE, np.uint8)
    status[20:60] = StripeStatus.FOUND
    status[20:25] = StripeStatus.OFF_LINE
    centre = np.where((np.arange(n) >= 20) & (np.arange(n) < 60), 150.0, np.nan)
    nan = np.full(n, np.nan)
    stripe = StripeResult(np.arange(n), centre, nan, nan, nan, status, np.zeros(n, int),
                          "columns", "centroid", 10.0, 1.0)
    img = draw_view(np.full((200, n), 80, np.uint8), None, stripe, "")
    off = STATUS_COLOURS[StripeStatus.OFF_LINE]
    green = np.all(img == STATUS_COLOURS[StripeStatus.FOUND], axis=2)
    assert set(np.nonzero(green)[1].tolist()) == set(range(25, 61))  # (the dots: radius 1)
    cyan = np.all(img == off, axis=2)
    assert set(np.nonzero(cyan[200 - TICK:])[1].tolist()) == set(range(20, 25))
    assert set(np.nonzero(cyan[140:160])[1].tolist()) <= set(range(19, 26))
    assert cyan[:40].any()  # the header names OFF_LINE in its colour
    status[20:25] = StripeStatus.FOUND
    without = draw_view(np.full((200, n), 80, np.uint8), None, stripe, "")
    assert not np.all(without == off, axis=2).any()


def test_the_pipeline_marks_centres_off_the_stripe_line_in_the_view(tmp_path):
    # a found centre far off the view's stripe line (a glint) is dropped from the view's
    # stripe pixels and marked OFF_LINE in the view's stripe, and the account counts it
    from hmlvs.data.views import ViewData
    from hmlvs.image.accounts import ImageReport
    from hmlvs.image.views import _stripes_on_one_line

    n = 300
    status = np.full(n, StripeStatus.NONE, np.uint8)
    status[20:280] = StripeStatus.FOUND
    centre = np.where(status == StripeStatus.FOUND, 100.0 + 0.1 * np.arange(n), np.nan)
    centre[200:205] = 20.0  # a glint 100 px above the line
    nan = np.full(n, np.nan)
    stripe = StripeResult(np.arange(n), centre, nan, nan, nan, status, np.zeros(n, int),
                          "columns", "centroid", 10.0, 1.0)
    view = ViewData("v", np.zeros((0, 2)), np.zeros(0, int), stripe.pixels, np.eye(4),
                    stripe=stripe)
    report = ImageReport("v", 0, "on.png", "off.png", True, "", stripe.counts(), 0, 260)
    views, reports = _stripes_on_one_line([view], [report], 0.3)
    out = views[0].stripe
    assert np.nonzero(out.status == StripeStatus.OFF_LINE)[0].tolist() == list(range(200, 205))
    assert len(views[0].laser_pixels) == 255 and np.all(views[0].laser_pixels[:, 1] > 50)
    assert reports[0].stripe["OFF_LINE"] == 5 and reports[0].stripe["FOUND"] == 255
