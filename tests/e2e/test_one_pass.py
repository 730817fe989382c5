"""One observation model for both sensor models (issue 37): an image session is read once
into views (numbered corners, the stripe with every scan line's status, the robot pose, the
pair's account), and the paper model's calibration points, in either mode, are derived from
those views (hmlvs.image.paper_session.paper_views -> points_of_views)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import hmlvs
from hmlvs.image.paper_session import dataset_from_images, paper_views, points_of_views
from hmlvs.image.points import view_points
from hmlvs.image.stripe import StripeResult
from hmlvs.image.views import views_from_images
import numpy as np
import pytest

pytestmark = pytest.mark.scene


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """4 pairs (seed 0, the board placed in the manifest): p001's board corner is found as
    X-junctions, p003's stripe takes the session's albedo offset."""
    out = tmp_path_factory.mktemp("one_pass") / "s"
    hmlvs.simulate.render_session(num_poses=4, seed=0, out_dir=out)
    return out


def _same_dataset(a, b):
    for name in ("pixels", "points", "poses", "joints", "pose_index"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert list(a.ids) == list(b.ids) and a.meta == b.meta
    assert a.quality.keys() == b.quality.keys()
    for k in a.quality:
        np.testing.assert_array_equal(a.quality[k], b.quality[k], err_msg=k)


def test_each_image_is_read_once_and_both_modes_derive_from_the_views(rendered, monkeypatch):
    from hmlvs import _io

    read = Counter()
    real = _io.read_image

    def counted(path, *args, **kwargs):
        read[Path(path).name] += 1
        return real(path, *args, **kwargs)

    monkeypatch.setattr(_io, "read_image", counted)
    views = paper_views(rendered)
    # every laser-on and laser-off image once, whatever is derived from the views after
    assert len(read) == 8 and set(read.values()) == {1}
    derived = {mode: points_of_views(views, mode=mode) for mode in ("corners", "homography")}
    assert len(read) == 8 and set(read.values()) == {1}
    monkeypatch.undo()
    for mode, (ds, reports) in derived.items():
        direct, direct_reports = dataset_from_images(rendered, mode=mode)
        _same_dataset(ds, direct)
        assert [r.to_dict() for r in reports] == [r.to_dict() for r in direct_reports]
    # the accounts and the data set of each mode: p003 took the session's albedo offset
    ds, reports = derived["corners"]
    assert ds.meta["albedo_offset_taken_by"] == ["p003"]
    assert {r.id: r.points for r in reports if r.ok} == {"p000": 1, "p001": 1, "p002": 1,
                                                         "p003": 6}


def test_a_views_calibration_points_are_a_function_of_its_observations(rendered):
    views = paper_views(rendered)
    ds, reports = points_of_views(views, mode="corners")
    assert [v.id for v in views.views] == [r.id for r in reports if r.view is not None]
    for r in reports:
        if not r.ok:
            continue
        v = r.view
        # the view's observations: numbered corners, every scan line with its status, the
        # pose and the joints it was computed from
        assert isinstance(v.stripe, StripeResult) and len(v.stripe.status) == 640
        np.testing.assert_array_equal(v.laser_pixels, v.stripe.pixels)
        assert len(v.corner_index) == r.corners and v.joints is not None
        np.testing.assert_array_equal(hmlvs.Robot.scorbot_er7().poses(v.joints[None])[0],
                                      v.base_from_hand)
        cp = view_points(v, views.board, image_size=views.image_size)
        mine = ds.pose_index == r.index
        np.testing.assert_array_equal(cp.pixels, ds.pixels[mine])
        np.testing.assert_array_equal(cp.points, ds.points[mine])
        assert [f"{v.id}:{k}" for k in cp.ids] == list(ds.ids[mine])
    # a view made without images has no stripe to derive points from
    bare = hmlvs.data.views.ViewData("x", views.views[0].corner_pixels,
                                     views.views[0].corner_index, views.views[0].laser_pixels)
    with pytest.raises(ValueError, match="the view's stripe"):
        view_points(bare, views.board)


def test_both_models_read_a_pair_alike(rendered):
    # The general model's views come from the same pass: read with the same stripe options
    # and camera blur, a view both models keep has the same stripe, scan line for scan line.
    # (Their own defaults differ: the paper model smooths along the stripe on the board
    # twice as much, BOARD_SMOOTH_ALONG, and gives a stripe that cannot fit its albedo
    # offset the session's; its boards are numbered from the pose, the general model's
    # without a model.)
    options = {"smooth_along": 2.0, "blur_var": 0.3}
    paper = {v.id: v for v in paper_views(rendered, **options).views}
    general, *_ = views_from_images(rendered, **options)
    both = [v for v in general if v.id in paper]
    assert [v.id for v in both] == ["p001"]  # the other boards are only partly visible
    for v in both:
        for name in ("centre", "sigma", "width", "intensity", "status"):
            np.testing.assert_array_equal(getattr(v.stripe, name),
                                          getattr(paper[v.id].stripe, name), err_msg=name)
        np.testing.assert_array_equal(v.base_from_hand, paper[v.id].base_from_hand)


@pytest.mark.parametrize("mode", ["corners", "homography"])
def test_the_paper_pass_gives_the_same_points_on_any_number_of_threads(rendered, mode):
    # the pairs are read on all cores by default, each from its own images alone
    one, rep1 = dataset_from_images(rendered, mode=mode, threads=1)
    for n in (2, 3):
        many, rep = dataset_from_images(rendered, mode=mode, threads=n)
        _same_dataset(one, many)
        assert [r.to_dict() for r in rep] == [r.to_dict() for r in rep1]
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        dataset_from_images(rendered, threads=0)
