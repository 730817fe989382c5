"""The image pipeline on images it did not render (issue 14, first "Done when" bullet).

``independent_render.py`` renders the paper's Table 2 sensor from docs/model.md alone (no code of
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
- the lens distortion fitted to the corners of all 16 views at once (one lens), so that a
  view with 6-8 corners is mapped by one homography too: all 16 views used on every seed
  (0-8); and a view whose stripe runs along the light squares only (seed 7, p013: no
  albedo offset of its own, 70 of 640 columns found, 0.52 px RMS) takes the session's
  offset (640 columns, 0.06 px). Map error, seeds 0-8: 0.0028, 0.0050, 0.0093, 0.0029,
  0.0031, 0.0035, 0.0074, 0.0050, 0.0034 mm; 1.63, 2.06, 2.64, 1.06, 1.52, 1.38, 1.41,
  1.72, 1.15 x the baseline (median 1.52; RMS over the seeds 1.70 x the baseline's RMS).
  What the rest is (seed 2, by swapping in exact data): the extracted stripe with exact
  reference points 0.0093 mm, the exact stripe with the pipeline's reference points 0.0023
  mm; on a render without speckle or noise the pipeline's error is 0.0028 mm (0.80 x), with
  sensor noise alone 0.0035 mm (0.99 x). The speckle is what is left: its error is
  correlated along the stripe, so each view's mean centre error is 0.007-0.011 px whatever
  the centre estimator (Steger, centroid, Gaussian or log-parabola fits over the profile:
  0.0071-0.0101 px on the same views), against 0.0065 px for the baseline's independent
  0.05 px per point.
- Steger's smoothing along the stripe twice its scale across it in calibration sessions
  (``hmlvs.image.session.BOARD_SMOOTH_ALONG``: the stripe lies on the board's plane), and
  its kernel cut short symmetrically at the image's first and last columns instead of a
  replicated border (which bent slanted stripes there): FOUND 0.044, 0.052, 0.046, 0.047,
  0.048, 0.044, 0.046, 0.046, 0.045 px RMS on seeds 0-8 (0.059-0.069 before), at most
  0.16-0.25 px (0.26-0.36 before); the 0.06 px / 0.3 px targets hold on every seed. The
  per-view mean errors, and so the map error, do not change: 0.0026, 0.0053, 0.0083,
  0.0027, 0.0031, 0.0036, 0.0071, 0.0053, 0.0040 mm; 1.52, 2.20, 2.35, 0.99, 1.54, 1.43,
  1.37, 1.82, 1.33 x the baseline (median 1.53; RMS over the seeds 1.66 x).
- the noise-weighted stripe centre (``refine_centres``) and corners that
  ``findChessboardCornersSB`` puts off the grid dropped rather than the view: all 16 views
  on seeds 0-17; map error 1.51, 1.93, 1.97, 0.89, 1.12, 1.38, 1.21, 1.39, 1.12, 1.67, 0.85,
  1.38, 1.24, 1.75, 1.38, 2.78, 2.21, 0.98 x the baseline (median 1.38).
- the corners moved to the saddle point of the smoothed image after ``cornerSubPix``
  (``saddle_refine``; 0.027 -> 0.014 px RMS per axis against the true corners): the
  reference points' error 0.0044 -> 0.0021-0.0031 mm; map error 0.64, 1.43, 1.80, 0.87,
  0.98, 1.14, 1.09, 0.98, 1.20, 1.72, 0.86, 1.02, 1.31, 2.01, 1.04, 2.50, 1.38, 0.75 x the
  baseline on seeds 0-17 (median 1.13; RMS over the seeds 1.18 x; 14 of 18 within 1.5 x).
  The four above 1.5 x are the stripe's: with the exact reference points in place of the
  homography's, seeds 2 and 15 stay at 1.73 and 2.52 x. Each seed is one draw of the
  image noise against a baseline averaged over 5 draws of its own; one draw of the
  baseline's noise alone varies 0.67-3.3 x from seed to seed.
- the correction at albedo steps for the camera blur fitted to the session (``blur_var``,
  ``session_blur_var``): FOUND 0.038-0.045 px RMS, at most 0.15-0.25 px; map error 0.76,
  1.38, 1.66, 0.89, 0.80, 1.28, 1.13, 0.90, 1.13, 1.68, 0.83, 0.80, 1.11, 2.00, 0.97, 2.00,
  1.38, 0.87 x (median 1.12; RMS 1.14 x; 14 of 18 within 1.5 x). On those seeds the
  speckle decides: re-rendered without it (noise only), seeds 2 and 15 gave 0.56 and
  1.52 x with the exact reference points, with it 1.67 and 2.53 x (before this correction).
- peaks found on the image smoothed 2 px along the stripe (``DETECT_ALONG``; for noisy
  cameras, ``test_a_noisy_camera_keeps_the_stripe``): on these renders FOUND 0.037-0.044 px
  RMS, at most 0.25 px; map error 0.74, 1.37, 1.67, 0.89, 0.79, 1.29, 1.18, 0.88, 1.12,
  1.63, 0.83, 0.76, 1.14, 1.97, 0.96, 2.07, 1.45, 0.82 x (median 1.13; RMS 1.14 x; 14 of 18
  within 1.5 x): unchanged. Rendered as the issue describes its scene, without speckle
  (``independent_check.py --speckle 0``): FOUND 0.017-0.024 px RMS, at most 0.17 px; map
  error 0.69, 0.93, 0.61, 1.66, 0.90, 1.21, 0.40, 1.14, 0.49, 0.97, 0.33, 0.97, 0.73, 1.09,
  0.76, 1.18, 0.62, 0.55 x (median 0.83; 17 of 18 within 1.5 x), better than 59 % of an
  ideal pipeline's fits (the exact stripe plus one 0.05 px draw, 20 per seed, of which 34
  of 360 exceed 1.5 x; ``--ideal 20``).
- what the speckle alone costs: the same 18 sessions (the same poses, speckle and noise
  draws) with one albedo at the laser's wavelength everywhere (``--flat-laser 0.6``: no
  albedo step under the stripe; the camera sees the same board): FOUND 0.032-0.038 px RMS,
  at most 0.27 px; map error 0.72, 1.14, 1.34, 0.75, 0.75, 1.14, 0.97, 0.76, 1.13, 1.46,
  0.64, 1.15, 1.08, 1.61, 0.89, 1.83, 0.94, 0.61 x (median 1.02; 2 of 18 above 1.5 x:
  seeds 13 and 15, at 1.97 and 2.07 x with the steps). The steps cost about 11 % (median
  1.13 / 1.02); the rest is the speckle's error, correlated within each view. No centre
  estimator tried does better there (on a uniform board with exact reference points,
  seeds 15, 2, 9, 13: the pipeline 1.65, 1.37, 1.28, 1.63 x; a Gaussian fit 2.12, 1.86,
  1.59, 1.99; a log-parabola fit weighted for speckle and noise 1.54, 1.82, 1.33, 2.05).
- the renderer's own error taken out: each of a pixel's 4 x 4 samples now takes the print
  averaged over its share of the pixel (``albedos(..., footprint=)``), where it took the
  print at one point, which put every edge of the squares up to 1/8 px off in each pixel
  row (``test_pixels_integrate_their_area``). The detected corners against the true ones
  (seed 3, 16 views): 0.0127 -> 0.0075 px RMS per axis without noise, 0.0140 -> 0.0099 px
  with it (12 x 12 point samples gave 0.0077 / 0.0100: what remains is the pipeline's);
  seed 3's reference points 0.0025 -> 0.0020 mm RMS. The stripe's error does not change
  (FOUND 0.037-0.044 px RMS, at most 0.25 px; 0.017-0.024 / 0.17 px without speckle). Map
  error: 0.80, 1.37, 1.60, 0.90, 0.70, 1.22, 1.20, 0.83, 1.08, 1.56, 0.80, 0.73, 1.04, 1.87,
  0.89, 1.91, 1.42, 0.81 x the baseline (median 1.06; 4 of 18 above 1.5 x, each 5-8 %
  lower than before); without speckle 0.76, 1.01, 0.60, 1.68, 0.84, 1.19, 0.38, 0.95,
  0.49, 0.87, 0.31, 0.89, 0.63, 1.01, 0.72, 1.08, 0.60, 0.53 x (median 0.80; 17 of 18
  within 1.5 x; better than 62 % of the ideal pipeline's fits). Seed 3 (1.68 x) is one
  view's: with view p005's points exact, the stripe alone (exact reference points) goes
  from 1.49 to 0.80 x. On that view's calibration columns the pipeline's mean centre error
  is -0.0042 px over 16 other noise draws (sd 0.0031), -0.0100 px in this one; the
  baseline's 0.05 px per point gives that view's mean an sd of 0.0063 px.
- the corners' saddles with the tilt of the renderer's 30 % vignette taken out
  (``saddle_refine``'s ``illumination``: the light fitted to the corners' grey values):
  corners 0.0097 -> 0.0076 px RMS per axis (seed 3; 0.0075 -> 0.0047 without noise, 0.0040
  with no vignette). Map error 0.63, 1.39, 1.55, 0.80, 0.56, 1.28, 1.20, 0.77, 1.00, 1.56,
  0.79, 0.74, 0.93, 1.70, 0.90, 1.90, 1.43, 0.84 x the baseline (median 0.97; 4 of 18
  above 1.5 x); without speckle 0.61, 0.96, 0.51, 1.54, 0.72, 1.07, 0.38, 0.84, 0.38, 0.85,
  0.24, 0.84, 0.49, 0.87, 0.70, 0.93, 0.53, 0.43 x (median 0.71; 17 of 18 within 1.5 x,
  seed 3 at 1.54 x).
- each scene without speckle taken 4 times more (``--redraw 4``: the same poses, the images'
  noise drawn again): 0 of the 72 takes above 1.5 x (at most 1.49 x, seed 1; median 0.74
  and 0.71 x over seeds 0-8 and 9-17, RMS 0.81 x). Seed 3's scene: 0.74-1.31 x (median
  1.03; over 12 takes 0.60-1.31 x, median 0.88), against 1.54 x in its first take. The
  ideal pipeline exceeds 1.5 x on 34 of its 360 fits (9 %), on seed 3's scene on 15 % of
  them: that scene's 1.54 x is its first take's noise. With speckle, the four scenes above
  1.5 x taken 4 times more: seeds 2 and 13 0.88-1.38 and 0.89-1.46 x (their 1.55 and 1.70 x
  were their first takes' noise); seeds 9 and 15 0.68-1.81 and 0.85-3.02 x (1 and 2 of 4
  takes above 1.5 x): those two scenes stay hard under speckle.
"""

from __future__ import annotations

import cv2
import independent_check as C  # noqa: E402
import independent_render as R  # noqa: E402
import numpy as np
import pytest

pytestmark = [pytest.mark.scene, pytest.mark.slow]


@pytest.fixture(scope="module", params=[0, pytest.param(1, marks=pytest.mark.one_kernel)])
def measured(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp(f"independent{request.param}")
    m = C.measure(request.param, "lm", folder)
    truth = dict(np.load(folder / "truth.npz"))
    # before: the laser-off frame divided out as it is, the peaks found on the image itself
    before = C.stripe_errors(folder, truth, albedo_offset=0.0, detect_sigma_along=0.0)
    return m, before


def test_stripe_centres_on_accepted_columns(measured):
    m, before = measured
    s = m["stripe"]
    columns = sum(v["n"] for k, v in s.items() if k != "per_view_found_rms")
    assert s["FOUND"]["n"] > 9000 and s["FOUND"]["n"] > 0.95 * columns  # of 16 x 640
    # the issue's targets (measured 0.039 / 0.179 and 0.044 / 0.246 px on seeds 0 and 1)
    assert s["FOUND"]["rms"] < 0.06 and s["FOUND"]["max"] < 0.3
    # before: the stripe lost on the light squares, and the rest 3 x worse, over 1 px at worst
    assert before["FOUND"]["n"] < 0.7 * s["FOUND"]["n"]
    assert before["FOUND"]["rms"] > 2.5 * s["FOUND"]["rms"]
    assert before["FOUND"]["max"] > 1.0


def test_views_and_map_error(measured):
    m, _ = measured
    # every view is used (seed 0's p000, 8 corners, through the session's lens distortion)
    assert len(m["used"]) == 16 and not m["dropped"]
    assert m["map"]["rms"] < 2.0 * m["baseline"]["rms"]  # measured 0.63 and 1.39
    assert m["map"]["rms"] < 0.005  # mm on held-out true stripes (measured 0.0011, 0.0034)


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


def test_a_stripe_on_one_level_takes_the_sessions_albedo_offset(tmp_path):
    """A view whose stripe runs along the light squares, touching the dark ones only at
    their corners (seed 7's pose 13), cannot fit the albedo offset: with 0 instead (the
    laser-off frame divided out as it is) its stripe was found in 70 of 640 columns, 0.50 px
    RMS off (pulled towards the dark squares); found on the image smoothed along the stripe
    (``detect_sigma_along``) in 634, still 0.22 px RMS off. The session takes the median
    offset of its other views for it: 634 columns, 0.052 px RMS, at most 0.16 px
    (measured)."""
    import json

    from hmlvs.image.paper_session import dataset_from_images
    from hmlvs.image.session import stripe_from_pair

    rng = np.random.default_rng(7)
    poses = [R.random_pose(rng) for _ in range(20)]
    pick = [0, 1, 2, 13]
    draw = np.random.default_rng(70)
    entries = []
    for k, i in enumerate(pick):
        on, off = R.render_view(R.TRUE, poses[i], draw)
        cv2.imwrite(str(tmp_path / f"p{k:03d}_on.png"), on)
        cv2.imwrite(str(tmp_path / f"p{k:03d}_off.png"), off)
        entries.append({"id": f"p{k:03d}", "on": f"p{k:03d}_on.png",
                        "off": f"p{k:03d}_off.png", "pose": poses[i].tolist()})
    (tmp_path / "manifest.json").write_text(json.dumps({
        "format": "hmlvs-images", "version": 1, "image_size": list(R.SIZE),
        "board": R.BOARD, "poses": entries}))
    ds, reports = dataset_from_images(tmp_path, mode="homography")
    assert ds.meta["albedo_offset_taken_by"] == ["p003"]
    # the laser's return is 0.9 / 0.25 on light / dark squares against 0.85 / 0.07 of the
    # ambient light (150 grey levels, vignetted by up to 30 %): a = 0.23 x 105..150 = 24..35
    # grey levels; fitted on noisy views (measured: 33.5)
    a = ds.meta["albedo_offset_session"]
    assert 20 < a < 45
    assert all(r.ok for r in reports) and reports[3].stripe["FOUND"] > 600
    on = cv2.imread(str(tmp_path / "p003_on.png"), cv2.IMREAD_UNCHANGED)
    off = cv2.imread(str(tmp_path / "p003_off.png"), cv2.IMREAD_UNCHANGED)
    truth = R.true_centres(R.TRUE, poses[13])
    alone = stripe_from_pair(on, off)
    unsmoothed = stripe_from_pair(on, off, detect_sigma_along=0.0)
    shared = stripe_from_pair(on, off, albedo_offset=a)
    e_alone = (alone.centre - truth)[alone.found]
    e_unsmoothed = (unsmoothed.centre - truth)[unsmoothed.found]
    e_shared = (shared.centre - truth)[shared.found]
    assert unsmoothed.found.sum() < 200 and np.sqrt(np.mean(e_unsmoothed ** 2)) > 0.3
    assert np.sqrt(np.mean(e_alone ** 2)) > 2.5 * np.sqrt(np.mean(e_shared ** 2))
    assert shared.found.sum() > 600 and np.sqrt(np.mean(e_shared ** 2)) < 0.1
    np.testing.assert_array_equal(reports[3].stripe["FOUND"], shared.found.sum())


@pytest.mark.parametrize("seed", [3, 11])
def test_a_noisy_camera_keeps_the_stripe(tmp_path, seed):
    """3 grey levels of sensor noise (a camera at high gain): normalising by the laser-off
    frame multiplies the noise on the dark squares, and the threshold that keeps it out cut
    the stripe where it is faint (measured on ``independent_check`` seed 0's 16 views: 3595
    of 10144 columns found). Found on the image smoothed 2 px along the stripe
    (``DETECT_ALONG``), the peaks clear a threshold 2.7 x lower: 10127 columns, 0.060 px
    RMS, at most 0.33 px; the map error 2.00 -> 1.10 x the baseline (seeds 1, 2: 2.52 ->
    1.97, 1.97 -> 1.88). A session of 3 grey levels also fits its albedo offset on fewer
    views: the peaks it takes must clear 5 sigmas of their 5-pixel mean, not of a pixel."""
    import json

    from hmlvs.image.paper_session import dataset_from_images

    rng = np.random.default_rng(seed)
    poses = [R.random_pose(rng) for _ in range(5)]
    draw = np.random.default_rng(100 + seed)
    entries, centres = [], []
    for k, pose in enumerate(poses):
        on, off = R.render_view(R.TRUE, pose, draw, noise=3.0)
        cv2.imwrite(str(tmp_path / f"p{k:03d}_on.png"), on)
        cv2.imwrite(str(tmp_path / f"p{k:03d}_off.png"), off)
        entries.append({"id": f"p{k:03d}", "on": f"p{k:03d}_on.png",
                        "off": f"p{k:03d}_off.png", "pose": pose.tolist()})
        centres.append(R.true_centres(R.TRUE, pose))
    (tmp_path / "manifest.json").write_text(json.dumps({
        "format": "hmlvs-images", "version": 1, "image_size": list(R.SIZE),
        "board": R.BOARD, "poses": entries}))
    ds, reports = dataset_from_images(tmp_path, mode="homography")
    assert all(r.ok for r in reports)
    truth = {"views": len(poses), "centres": centres}
    on_image = int(sum(np.isfinite(c).sum() for c in centres))
    now = C.stripe_errors(tmp_path, truth, ds.meta)["FOUND"]
    before = C.stripe_errors(tmp_path, truth, ds.meta, detect_sigma_along=0.0)["FOUND"]
    assert now["n"] > 0.95 * on_image and before["n"] < 0.75 * on_image
    # three times the noise of the issue's scene (its targets 0.06 px RMS, 0.3 px at most):
    # measured 0.070 / 0.062 px RMS, at most 0.50 / 0.30 px on seeds 3 / 11; the 0.50 px
    # column is also found, as far off, without the smoothing
    assert now["rms"] < 0.09 and now["max"] < 0.75


def test_a_flat_laser_albedo_takes_the_step_out_of_the_stripe_only():
    """``laser_albedo`` (``independent_check.py --flat-laser``): one albedo at the laser's
    wavelength everywhere takes the squares' steps out of the stripe, while the laser-off
    frame still shows the board. The stripe's peak over dark squares against light ones:
    0.25 / 0.9 of the print by default, 1 flat (up to the fan's fall-off and speckle)."""
    rng = np.random.default_rng(4)
    pose = R.random_pose(rng)
    u = np.arange(R.SIZE[0])
    rows = R.true_centres(R.TRUE, pose)
    ok = np.isfinite(rows)
    amb = R.albedos(R.board_coords(R.board_hits(R.TRUE, pose, u[ok].astype(float),
                                                rows[ok])[0]))[0]
    dark = amb == R.ALBEDO["dark"]
    light = amb == R.ALBEDO["light"]
    assert dark.sum() > 50 and light.sum() > 50

    def peak_ratio(**options):
        on, off = R.render_view(R.TRUE, pose, np.random.default_rng(5), **options)
        d = on.astype(float) - off.astype(float)
        r = np.clip(np.rint(rows[ok]).astype(int), 3, R.SIZE[1] - 4)
        peak = np.max([d[r + k, u[ok]] for k in range(-3, 4)], axis=0)
        return np.median(peak[dark]) / np.median(peak[light]), off

    printed, off = peak_ratio()
    flat, off_flat = peak_ratio(laser_albedo=dict.fromkeys(("dark", "light", "table"), 0.6))
    assert printed < 0.45  # the print's 0.28, raised by the blur near edges
    assert 0.8 < flat < 1.25
    np.testing.assert_array_equal(off, off_flat)  # the camera sees the same board


def test_a_sample_takes_the_print_averaged_over_its_footprint():
    """``albedos(..., footprint=)``: the mean of the print over the parallelogram a sample
    stands for (exact at straight edges; near a square's corner only approximately), and
    the print's own levels, exactly, without a footprint."""
    rng = np.random.default_rng(0)
    sq = R.BOARD["square"]
    xy = rng.uniform(-2 * sq, 9 * sq, (2000, 2))
    amb, las = R.albedos(xy)
    assert set(np.unique(amb)) <= set(R.ALBEDO.values())
    assert set(np.unique(las)) <= set(R.LASER_ALBEDO.values())
    # points within a footprint of an edge between squares or of the paper's or the
    # squares' border, along one board axis and away from the other's edges
    edges = np.r_[np.arange(-1, 7), -1.5, 6.5] * sq
    uniform = rng.uniform(-0.5, 0.5, (100_000, 2))
    checked = 0
    for k in range(12):
        a, b = rng.uniform(-0.4, 0.4, 2), rng.uniform(-0.4, 0.4, 2)
        axis = k % 2  # the board axis across the edge
        span = abs(a[axis]) + abs(b[axis])  # the footprint's extent across it
        p = np.array([rng.choice(edges) + rng.uniform(-0.4, 0.4) * span, (k % 7 + 0.5) * sq])
        if axis:
            p = p[::-1]
        exact = R.albedos(p + uniform[:, :1] * a + uniform[:, 1:] * b)
        got = R.albedos(p[None], footprint=(a[None], b[None]))
        for e, g in zip(exact, got):
            # the Monte-Carlo mean's own error: at most 0.78 * 0.5 / sqrt(1e5) = 0.0012 (1 sd)
            assert abs(g[0] - e.mean()) < 0.005
        checked += np.ptp(exact[0]) > 0
    # 9 of 12 (the others straddle the border between a light square and the light margin)
    assert checked >= 8


def test_pixels_integrate_their_area():
    """Each of the ``ss`` x ``ss`` samples of a pixel stands for its share of the pixel
    (the print averaged over its footprint), so 4 x 4 samples give the pixel's area
    integral: without noise or speckle, the same view with 8 x 8 differs by at most the
    rounding, 1 grey level, on 0.03 % of the pixels. Point samples of the sharp print (as
    the renderer took them before) differ by up to 4 grey levels on 2.4 % of the pixels,
    all at the print's edges, and shifted the detected corners by 0.013 px RMS per axis
    without noise (0.0075 px with the footprint; seed 3, 16 views)."""
    pose = R.random_pose(np.random.default_rng(3))
    view = {ss: R.render_view(R.TRUE, pose, np.random.default_rng(0), ss=ss, noise=0.0,
                              speckle=0.0) for ss in (4, 8)}
    for got, fine in zip(view[4], view[8]):
        d = np.abs(got.astype(int) - fine.astype(int))
        assert d.max() <= 1 and np.mean(d > 0) < 0.005
    # the check is sharp enough to see point sampling
    sharp = R.albedos

    def point_samples(xy, board=R.BOARD, laser_albedo=None, footprint=None):
        return sharp(xy, board, laser_albedo)

    try:
        R.albedos = point_samples
        points = R.render_view(R.TRUE, pose, np.random.default_rng(0), ss=4, noise=0.0,
                               speckle=0.0)
    finally:
        R.albedos = sharp
    d = np.abs(points[1].astype(int) - view[8][1].astype(int))
    assert d.max() >= 3 and np.mean(d > 0) > 0.01


def test_another_take_of_a_scene_keeps_its_poses_and_truth(tmp_path):
    """``render_session(noise_seed=...)`` takes the same scene again: the poses and the true
    stripe are the seed's, only the images' noise is drawn anew (``independent_check.py
    --redraw``: the pipeline's own scatter on one scene). Without it the session is the one
    stream of poses then noise that every figure above was measured on."""
    takes = {k: R.render_session(tmp_path / str(k), seed=3, views=2, held_out=1,
                                 noise_seed=k, speckle=0.0) for k in (None, 0, 1)}
    for k in (0, 1):
        np.testing.assert_array_equal(takes[k]["poses"], takes[None]["poses"])
        np.testing.assert_array_equal(takes[k]["centres"], takes[None]["centres"])
    on = {k: cv2.imread(str(tmp_path / str(k) / "p001_on.png"), cv2.IMREAD_UNCHANGED).astype(int)
          for k in (None, 0, 1)}
    d = np.abs(on[0] - on[1])
    # two draws of 1 grey level of noise: mean |difference| 2 / sqrt(pi) = 1.13
    assert 0.9 < d.mean() < 1.4 and d.max() <= 10
    # without a noise seed: one stream, the poses' then the images' (as it always was)
    rng = np.random.default_rng(3)
    poses = [R.random_pose(rng) for _ in range(3)]
    first = R.render_view(R.TRUE, poses[0], rng, speckle=0.0)
    np.testing.assert_array_equal(
        first[0], cv2.imread(str(tmp_path / "None" / "p000_on.png"), cv2.IMREAD_UNCHANGED))


@pytest.fixture(scope="module", params=[0, pytest.param(1, marks=pytest.mark.one_kernel)])
def measured_as_the_issue_says(request, tmp_path_factory):
    """The issue's scene as it describes it: no speckle, 1 grey level of noise."""
    folder = tmp_path_factory.mktemp(f"independent_clean{request.param}")
    return C.measure(request.param, "lm", folder, speckle=0.0)


def test_the_issues_scene_within_the_issues_bounds(measured_as_the_issue_says):
    """Issue 14's "Done when" on its own scene: all 16 views used, stripe centres within
    0.06 px RMS and none off by more than 0.3 px, the map error within 1.5 x the exact-stripe
    fit. Measured on seeds 0 and 1: 0.018 / 0.114 and 0.024 / 0.168 px; 0.61 and 0.96 x. Over
    seeds 0-17 (``independent_check.py --speckle 0 --ideal 20``): median 0.71 x, 17 of 18
    within 1.5 x (seed 3 at 1.54 x, inside the ideal pipeline's own scatter on that scene),
    better than 70 % of the ideal pipeline's fits."""
    m = measured_as_the_issue_says
    assert len(m["used"]) == 16 and not m["dropped"]
    assert m["stripe"]["FOUND"]["rms"] < 0.06 and m["stripe"]["FOUND"]["max"] < 0.3
    assert m["map"]["rms"] < 1.5 * m["baseline"]["rms"]
