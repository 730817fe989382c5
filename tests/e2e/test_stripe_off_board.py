"""Rendered general-sensor sessions in which the laser line misses the board's pattern in
some views (it lies on the white border or the table around it, in the board's plane) and
clips only a corner of it in others: every view calibrates, the stripe off the pattern is
used on the board's plane, and the sensor is recovered. A view with stripe pixels but none on
the pattern used to crash `calibrate_joint` (its masks and plane points went out of step)."""

from __future__ import annotations

import json

from hmlvs.calibration.joint import calibrate_joint
from hmlvs.cli import main
from hmlvs.data.calibration_file import Calibration
from hmlvs.geometry.board import Checkerboard
from hmlvs.image.views import views_from_images
from hmlvs.sim.general import (
    add_stripe_off_board_views,
    example_sensor,
    general_session,
    render_general_session,
)
import numpy as np
import pytest

# rendered images; seed 0 runs again in the Prescott pass (marker scene), seed 1 once: the map
# error is a third of its limit (0.019-0.026 against 0.06 mm), far from any BLAS kernel's bits

BOARD = Checkerboard(rows=5, cols=7, square=15.0)
SIZE = (640, 480)
FULL, MISS, CLIP = 6, 2, 2
SEEDS = (pytest.param(0, marks=pytest.mark.scene), 1)


def _session(seed: int):
    s = general_session(example_sensor(SIZE), BOARD, views=FULL, seed=seed,
                        distance=(330.0, 480.0))
    s = add_stripe_off_board_views(s, MISS, seed, distance=(330.0, 520.0))
    return add_stripe_off_board_views(s, CLIP, seed + 100, on_board=(0.05, 0.3),
                                      distance=(330.0, 520.0))


@pytest.fixture(scope="module", params=SEEDS)
def rendered(request, tmp_path_factory):
    s = _session(request.param)
    r = render_general_session(s, tmp_path_factory.mktemp(f"offboard{request.param}"))
    return s, r


def test_the_drawn_views_miss_or_clip_the_pattern(rendered):
    s, _ = rendered
    frac = [float(on[np.isfinite(v)].mean()) for v, on in zip(s.stripe_v, s.stripe_on_board)]
    assert all(f == 0.0 for f in frac[FULL:FULL + MISS]), frac
    assert all(0.05 <= f <= 0.3 for f in frac[FULL + MISS:]), frac
    assert all(np.isfinite(v).sum() >= SIZE[0] / 3 for v in s.stripe_v[FULL:])


def test_every_view_is_used_and_the_sensor_recovered(rendered, tmp_path, capsys):
    s, r = rendered
    views, _board, _size, _pose, reports = views_from_images(r.manifest)
    assert [v.id for v in views] == r.ids, [rep for rep in reports if not rep.ok]
    out = tmp_path / "cal.yaml"
    with pytest.raises(SystemExit) as e:
        main(["calibrate", str(r.manifest.parent), "--out", str(out), "--json"])
    assert e.value.code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["model"] == "opencv" and doc["solve"]["mode"] == "chain"
    cal = Calibration.load(out)
    # the views whose stripe misses the pattern give laser points on the board's plane
    result = calibrate_joint(views, BOARD, SIZE)
    assert not result.rejected
    for i in range(FULL, FULL + MISS + CLIP):
        pv = result.per_view[f"v{i:03d}"]
        assert pv["laser_pixels"] >= SIZE[0] / 4, (i, pv)
    # mapped to the base, the true stripe pixels (on and off the pattern) land within a few
    # hundredths of a mm of the truth (the 12-view whole-board render gives < 0.06 mm)
    errs = []
    for i in range(len(s)):
        px = s.stripe_pixels(i, on_board=False)
        poses = np.repeat(s.base_from_hand[i][None], len(px), axis=0)
        got, _ = cal.sensor.points_in_base(px, poses, on_invalid="mask")
        true, _ = s.sensor.points_in_base(px, poses, on_invalid="mask")
        errs.append(np.linalg.norm(got - true, axis=1))
    err = np.concatenate(errs)
    assert np.sqrt(np.mean(err**2)) < 0.06, np.sqrt(np.mean(err**2))
