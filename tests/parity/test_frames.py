"""The per-frame stripe pipeline in C++ (stripe_from_pair, hmlvs.Measurer: one call per frame,
cpp/hmlvs/image/frames.h) against its NumPy reference, the whole-image composition it replaces
(tests/oracles/reference_frames.py): the same statuses, widths, thresholds and noise, centres within
1e-3 px (measured: 3e-7 px at most: the denoised laser-off frame's weights are exact here and
interpolated from a table by OpenCV, and single-precision sums run in another order) and
sigmas within 1e-5 relative, on
rendered frames with every option the pipeline takes, laser-on frames alone, 16-bit and colour
frames, stripes along image rows and a real photograph; the building blocks it replaces
(OpenCV's opening, scipy's median filter, the albedo offset's fit); the same values from
several threads and without AVX2."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import os
from pathlib import Path
import subprocess
import sys

import cv2
from hmlvs.image.colour import drop_jumps
from hmlvs.image.session import estimate_background, stripe_from_pair
from hmlvs.image.stripe import StripeStatus, albedo_offset
from hmlvs.sim.general import example_sensor, general_session, render_general_view
import numpy as np
import pytest
import reference_frames as ref

DATA = Path(__file__).parents[1] / "data"


@pytest.fixture(scope="module")
def frames():
    """Two rendered 640 x 480 laser on/off pairs of the general sensor (a 7 x 5 board,
    speckle, blur, noise, a saturating laser), and a 1280 x 1024 pair made from the first
    (enlarged, with fresh noise: rendering at full size takes seconds)."""
    import hmlvs

    s = general_session(example_sensor((640, 480)),
                        hmlvs.Checkerboard(rows=5, cols=7, square=15.0), views=2, seed=5,
                        distance=(330.0, 480.0))
    small = [render_general_view(s, i) for i in range(2)]
    rng = np.random.default_rng(7)
    big = tuple(np.clip(np.rint(cv2.resize(x.astype(np.float32), (1280, 1024),
                                           interpolation=cv2.INTER_CUBIC)
                                + rng.normal(0, 1.0, (1024, 1280))), 0, 255).astype(np.uint8)
                for x in small[0])
    return small, big


def assert_same(a, b, tol=1e-3):
    """The C++ stripe a is the reference's b: statuses, peaks, widths, thresholds, noise and
    method alike, centres within tol px and sigmas within 1e-5 relative."""
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.num_peaks, b.num_peaks)
    np.testing.assert_array_equal(a.width, b.width)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    assert (a.threshold, a.noise, a.method, a.direction) == \
        (b.threshold, b.noise, b.method, b.direction)
    np.testing.assert_array_equal(np.isnan(a.centre), np.isnan(b.centre))
    np.testing.assert_allclose(a.centre, b.centre, rtol=0, atol=tol)
    np.testing.assert_allclose(a.sigma, b.sigma, rtol=1e-5)
    np.testing.assert_allclose(a.residual, b.residual, rtol=0, atol=1e-9)


@pytest.mark.parametrize("options", [
    {}, {"normalize": False}, {"albedo_offset": 0.0}, {"albedo_offset": 12.5},
    {"albedo_offset": np.inf}, {"threshold": 12.0}, {"method": "centroid"},
    {"method": "gaussian", "threshold": 20.0}, {"steger_sigma": 2.0, "noise": 1.5},
    {"smooth_along": 2.0, "blur_var": 0.4}, {"detect_sigma_along": 0.0},
    {"detect_sigma_along": 3.0, "steger_sigma_along": 5.0}, {"assess": False},
    {"albedo_step": 1.5}, {"dominance": 2.0, "min_width": 1.5, "max_width": 12.0},
    {"normalize": False, "detect_sigma_along": 2.0},
])
def test_pairs_are_the_references(frames, options):
    small, _ = frames
    for on, off in small:
        assert_same(stripe_from_pair(on, off, **options), ref.stripe_from_pair(on, off, **options))


@pytest.mark.parametrize("options", [{}, {"smooth_along": 2.0, "blur_var": 0.4},
                                     {"dominance": 3.0}, {"normalize": False}])
def test_laser_on_frames_alone_are_the_references(frames, options):
    small, _ = frames
    for on, _off in small:
        a = stripe_from_pair(on, None, **options)
        assert_same(a, ref.stripe_from_pair(on, None, **options))
        assert a.found.sum() > 300


def test_full_size_frames_are_the_references(frames):
    _, (on, off) = frames
    for o in (off, None):
        a = stripe_from_pair(on, o)
        assert_same(a, ref.stripe_from_pair(on, o))
        assert a.found.sum() > 850  # of 1280 columns


def test_16_bit_colour_and_transposed_frames_are_the_references(frames):
    small, _ = frames
    on, off = small[0]
    # 16 bits: the rules in double precision, every grey level of the 8-bit frame x 257
    on16, off16 = (x.astype(np.uint16) * 257 for x in (on, off))
    for o in (off16, None):
        assert_same(stripe_from_pair(on16, o), ref.stripe_from_pair(on16, o))
    # a colour pair with the laser's channel named: that channel, read in place
    on_c, off_c = (np.dstack([x // 3, x // 2, x]) for x in (on, off))
    assert_same(stripe_from_pair(on_c, off_c, channel=2), ref.stripe_from_pair(on, off))
    # a stripe along the image's rows: the same pipeline on the transposed frames, the
    # statistics taken over the caller's rows as the reference takes them
    for options in ({}, {"normalize": False}):
        a = stripe_from_pair(on.T, off.T, direction="rows", **options)
        assert_same(a, ref.stripe_from_pair(on.T, off.T, direction="rows", **options))
        assert a.found.sum() > 300


def test_a_real_photograph_is_the_references():
    """OpenCV's left01.jpg (a real camera's noise, JPEG blocks and a board under room light:
    tests/data holds no real laser frames) as the laser-off frame, a slanted speckled laser
    line whose return follows the print (as off + 40) added for the laser-on one. (Not alone:
    the photograph's squares are as short as the opening's line, which takes them for
    stripes.)"""
    off = cv2.imread(str(DATA / "opencv_left" / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    rng = np.random.default_rng(3)
    h, w = off.shape
    u = np.arange(w)
    centre = 200.0 + 0.12 * u + 6.0 * np.sin(u / 90.0)
    v = np.arange(h)[:, None]
    laser = 90.0 * np.exp(-0.5 * ((v - centre) / 1.6) ** 2) * rng.gamma(20.0, 1 / 20.0, (h, w))
    on = off + laser * (off + 40.0) / 100.0 + rng.normal(0, 1.5, (h, w))
    on = np.clip(np.rint(on), 0, 255).astype(np.uint8)
    for options in ({}, {"blur_var": 0.3}):
        a = stripe_from_pair(on, off, **options)
        assert_same(a, ref.stripe_from_pair(on, off, **options))
        assert a.found.sum() > 250
        assert np.sqrt(np.mean((a.centre[a.found] - centre[a.found]) ** 2)) < 0.15


def test_a_frame_without_stripe_is_refused_as_before(frames):
    small, _ = frames
    off = small[0][1]
    for on, o in ((off, off), (np.full_like(off, 40), None)):
        for extract in (ref.stripe_from_pair, stripe_from_pair):
            with pytest.raises(ValueError, match="leaves no pixel of the difference image"):
                extract(on, o)


def test_background_and_jumps_are_opencvs_and_scipys():
    rng = np.random.default_rng(0)
    for h, w, dtype in ((480, 640, np.uint8), (97, 203, np.uint16), (5, 30, np.uint8),
                        (60, 1, np.uint16)):
        top = np.iinfo(dtype).max
        on = rng.integers(0, top, (h, w), endpoint=True).astype(dtype)
        for width in (0.0, 0.5, 3.3, 16.0, 40.0):
            np.testing.assert_array_equal(estimate_background(on, width),
                                          ref.estimate_background(on, width))
    colour = rng.integers(0, 256, (50, 70, 3), dtype=np.uint8)
    np.testing.assert_array_equal(estimate_background(colour, 4.0),
                                  ref.estimate_background(colour, 4.0))
    stripe = stripe_from_pair(*_pair(rng))
    centre = stripe.centre.copy()
    centre[100:104] += 3.0  # a jump
    for s in (replace_centre(stripe, centre), stripe):
        np.testing.assert_array_equal(drop_jumps(s).status, ref._drop_jumps(s).status)
    assert (drop_jumps(replace_centre(stripe, centre)).status[100:104] ==
            StripeStatus.MULTIPLE).all()


def replace_centre(stripe, centre):
    from dataclasses import replace

    return replace(stripe, centre=centre)


def _pair(rng, h=120, w=300):
    """A flat pair with a horizontal Gaussian stripe."""
    off = np.full((h, w), 60.0) + rng.normal(0, 1, (h, w))
    on = off + 120 * np.exp(-0.5 * ((np.arange(h)[:, None] - 60.3) / 1.4) ** 2)
    return (np.clip(np.rint(on), 0, 255).astype(np.uint8),
            np.clip(np.rint(off), 0, 255).astype(np.uint8))


def test_albedo_offset_is_the_references(frames):
    """The fit's levels are the laser-off frame blurred at sigma 1 in single precision: OpenCV
    sums the taps with its SIMD (fused multiply-adds where the CPU has them: a third of the
    values a few ulps from the plain sums, measured), the C++ core in OpenCV's scalar order,
    and the fit's difference of products cancels most of the level (here an offset of -0.31
    from levels of 50): within 1e-4."""
    small, (on_big, off_big) = frames
    for on, off in [*small, (on_big, off_big)]:
        for direction in ("columns", "rows"):
            a, b = (on, off) if direction == "columns" else (on.T, off.T)
            want = ref._albedo_offset(a, b, direction)[0]
            got = albedo_offset(a, b, direction)
            assert got == pytest.approx(0.0 if np.isnan(want) else want, rel=1e-4, abs=1e-4)
    on, off = _pair(np.random.default_rng(1))
    assert albedo_offset(on, off) == 0.0  # one level: nothing to fit


def test_threads_give_the_serial_values(frames):
    small, (on_big, off_big) = frames
    jobs = [(on, o) for on, off in [*small, (on_big, off_big)] for o in (off, None)] * 2
    serial = [stripe_from_pair(*j) for j in jobs]
    with ThreadPoolExecutor(max_workers=3) as pool:
        threaded = list(pool.map(lambda j: stripe_from_pair(*j), jobs))
    for a, b in zip(serial, threaded):
        np.testing.assert_array_equal(a.status, b.status)
        np.testing.assert_array_equal(a.centre, b.centre)


def _avx2_case() -> np.ndarray:
    on, off = _pair(np.random.default_rng(2), 200, 640)
    out = [stripe_from_pair(on, o, blur_var=0.3) for o in (off, None)]
    parts = [np.r_[s.centre, s.sigma, s.status] for s in out]
    # the opening (EstimateBackground) of a noisy frame whose rows are no whole number of
    # vectors, 8 and 16 bits, with a short and a long line
    noisy = np.random.default_rng(4).integers(0, 256, (150, 637), dtype=np.uint8)
    for image in (noisy, noisy.astype(np.uint16) * 257):
        for width in (2.0, 16.0):
            parts.append(estimate_background(image, width).ravel().astype(float))
    return np.concatenate(parts)


def test_the_same_values_without_avx2(tmp_path):
    """The AVX2 loops (taken on CPUs that have them) give the SSE2 loops' values to the bit:
    the stripe of a pair and of a laser-on frame alone, and the opening alone."""
    path = tmp_path / "sse2.npy"
    code = ("import sys, numpy as np; sys.path[:0] = sys.argv[1].split(','); "
            "from test_frames import _avx2_case; np.save(sys.argv[2], _avx2_case())")
    here = Path(__file__).parent  # this module, beside the shared helpers and the oracles
    paths = ",".join(str(d) for d in (here, here.parent, here.parent / "oracles"))
    subprocess.run([sys.executable, "-c", code, paths, str(path)],
                   check=True, env={**os.environ, "HMLVS_NO_AVX2": "1"})
    np.testing.assert_array_equal(_avx2_case(), np.load(path))
