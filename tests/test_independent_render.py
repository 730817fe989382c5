"""The image pipeline on images it did not render (issue 14, first "Done when" bullet).

``independent_render.py`` renders the paper's Table 2 sensor from MODEL.md alone (no code of
``hmlvs.sim``): k = 4.8e-4, laser reflectance lower on dark squares and not proportional to
the ambient albedo (dark 0.25 / light 0.9 for the laser, 0.07 / 0.85 under ambient light),
area-integrated pixels, 0.5 px blur, 10 % laser speckle, 1 grey level of noise, random yaw
/ tilt / height 230-400 mm, 16 views + 4 held out. ``independent_check.py`` measures the
session pipeline (``hmlvs calibrate DIR --mode homography``: the paper model with the
manifest's board pose) on them; the baseline is the fit of the exact stripe pixels plus
0.05 px of noise (RMS over 5 draws).

Measured (seeds 0, 1, 2; LM from the nominal parameters):

- before (the laser-off frame divided out as if the laser's return were proportional to it,
  ``albedo_offset=0``): the stripe is lost on the light squares (its normalised peak falls
  below the automatic threshold: ~5000 of ~10000 columns found); FOUND columns 0.20-0.24 px
  RMS, up to 1.3-1.6 px, nearly all within 4 px of a square's edge; map error on held-out
  true stripes 0.013, 0.030, 0.041 mm: 7.7, 12.5, 11.6 x the baseline.
- after (the return fitted as proportional to ``off + a``, ``albedo_offset``): all columns
  found (within 3 px of an edge 0.077 px RMS, elsewhere 0.061); FOUND 0.059, 0.069, 0.061
  px RMS, at most 0.30, 0.31, 0.28 px; map error 0.0034, 0.0078, 0.015 mm: 1.95, 3.2, 4.3 x
  the baseline (1.3, 4.6, 3.9 x a baseline on the same views the pipeline used). The CLI
  (pso+lm) gives the same 0.0034 mm on seed 0.
- and with the stripe points mapped to the board by the homography of all corners where it
  fits them (``hmlvs.image.points.GLOBAL_RESIDUAL``; the reference points' error 0.008-0.0096
  -> 0.004-0.005 mm): map error 0.0023, 0.0069, 0.0139 mm: 1.32, 2.8, 4.0 x the baseline;
  with it also in squares where some of the four corners were not found (747 -> 888, 627 ->
  739, 691 -> 838 points): 0.0025, 0.0047, 0.0098 mm, 1.44, 1.96, 2.80 x the baseline
  (0.99, 2.8, 2.5 x a baseline on the same views).

Not reached, and why:

- 0.06 px RMS on every seed and 0.3 px at most: what is left is the laser speckle (10 %,
  ~2 px grains), which Steger's smoothing at 3 px averages over a few columns only.
- map error within 1.5 x (reached on seed 0 only, 1.44): views are missing (below), and the centre
  errors, though close to the baseline's 0.05 px per column, are correlated along the
  stripe over ~12 columns (Steger's smoothing at 3 px of the sensor noise and speckle;
  lag 8: 0.22), so their per-view means reach 0.01-0.02 px (0.003 px without noise and
  speckle); removing those means alone took seed 2's map error from 0.015 to 0.0056 mm.
- all 16 views: ``findChessboardCornersSB`` finds no 3 x 3 grid in 1-4 of 16 views, close
  views (230-250 mm, squares of ~130 px) near the board's border, some of which show only
  two rows of inner corners. Their corners are now found as X-junctions where the robot
  pose predicts them (``find_corners``; ``test_predicted_numbering.py``): every view's
  corners are found and numbered right (within 0.16 px of the truth on the 48 views of
  seeds 0-2). All 16 views are used on seeds 1 and 2; on seed 0 one view shows only 8
  corners, too few for the one-homography mapping (9, with the distortion fit), and its
  stripe crosses no square with all four corners: it gives no point. Letting it give
  points through a homography of its 8 corners without the distortion fit made seed 0's
  map error 2.4 x worse (0.0025 -> 0.0061 mm), so it stays out. With the close views in,
  the map error is 0.0025, 0.0055, 0.0092 mm (1.44, 2.28, 2.63 x the baseline): more
  views, but close views' stripes are the noisiest (0.08-0.09 px RMS against 0.06).
"""

from __future__ import annotations

from pathlib import Path
import sys

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

import independent_check as C  # noqa: E402

pytestmark = pytest.mark.scene


@pytest.fixture(scope="module", params=[0, 1])
def measured(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp(f"independent{request.param}")
    m = C.measure(request.param, "lm", folder)
    truth = dict(np.load(folder / "truth.npz"))
    before = C.stripe_errors(folder, truth, albedo_offset=0.0)
    return m, before


def test_stripe_centres_on_accepted_columns(measured):
    m, before = measured
    s = m["stripe"]
    columns = sum(v["n"] for k, v in s.items() if k != "per_view_found_rms")
    assert s["FOUND"]["n"] > 9000 and s["FOUND"]["n"] > 0.95 * columns  # of 16 x 640
    assert s["FOUND"]["rms"] < 0.08 and s["FOUND"]["max"] < 0.4
    # before: the stripe lost on the light squares, and the rest 3 x worse, over 1 px at worst
    assert before["FOUND"]["n"] < 0.7 * s["FOUND"]["n"]
    assert before["FOUND"]["rms"] > 2.5 * s["FOUND"]["rms"]
    assert before["FOUND"]["max"] > 1.0


def test_views_and_map_error(measured):
    m, _ = measured
    # every board is found (measured: 16 of 16 views used on seed 1, 15 on seed 0)
    assert len(m["used"]) >= 15
    # a dropped view: its stripe crosses no square the homography mapping can use (seed 0,
    # p000: 8 corners), never a board not found
    assert all(r.startswith("no calibration points") for r in m["dropped"].values())
    assert m["map"]["rms"] < 3.0 * m["baseline"]["rms"]  # measured 1.44 and 2.28
    assert m["map"]["rms"] < 0.008  # mm on held-out true stripes (measured 0.0025, 0.0055)


def test_albedo_offset_recovers_an_affine_laser_return():
    """A stripe over squares whose laser return is 0.2 + 0.8 x (ambient albedo): the offset
    a with return proportional to off + a is 0.25 x the ambient scale; a return proportional
    to the ambient albedo gives 0; one that does not follow it gives inf."""
    from hmlvs.image.stripe import albedo_offset, difference_image

    rng = np.random.default_rng(3)
    h, w = 120, 400
    alb = np.where((np.arange(w) // 50) % 2 == 0, 0.1, 0.9)[None, :].repeat(h, axis=0)
    v = np.arange(h)[:, None]
    line = np.exp(-0.5 * ((v - 60.3) / 1.8) ** 2)

    def pair(ret):
        off = 150.0 * alb + rng.normal(0, 1, (h, w))
        on = 150.0 * alb + 80.0 * ret * line + rng.normal(0, 1, (h, w))
        return [np.clip(np.rint(x), 0, 255).astype(np.uint8) for x in (on, off)]

    on, off = pair(0.2 + 0.8 * alb)
    assert albedo_offset(on, off) == pytest.approx(0.25 * 150, rel=0.15)
    on, off = pair(alb)
    assert abs(albedo_offset(on, off)) < 3.0
    on, off = pair(np.ones_like(alb) - 0.5 * alb)
    assert np.isinf(albedo_offset(on, off))
    np.testing.assert_array_equal(difference_image(on, off, normalize=True, offset=np.inf),
                                  difference_image(on, off))
