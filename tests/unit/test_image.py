"""The image pipeline on rendered sessions with known truth: difference image and stripe
centres (against the truth and against the NumPy reference). Corners, calibration points and
whole sessions: test_image_board.py."""


import cv2
import hmlvs
from hmlvs.image.stripe import StripeStatus
from hmlvs.sim.render import RenderOptions
import numpy as np
import pytest
import reference_stripe as ref
from scene_checks import stripe_errors

pytestmark = pytest.mark.scene  # simulated sessions or rendered images

METHODS = ["centroid", "gaussian", "steger"]


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


@pytest.fixture(scope="module")
def uniform_noisy():
    """A board of uniform albedo (no square edges to bias the stripe) with sensor noise, to
    compare the reported uncertainty with the actual error."""
    s = hmlvs.simulate.session(num_poses=4, seed=3)
    return hmlvs.simulate.render_session(s, options=RenderOptions(noise=2.0, black=0.85), seed=3)


@pytest.fixture(scope="module")
def troubled():
    """Sensor noise, a saturating glare spot on the stripe and a laser reflection."""
    s = hmlvs.simulate.session(num_poses=2, seed=0)
    return hmlvs.simulate.render_session(
        s, options=RenderOptions(noise=2.0, glare=True, spurious=0.6), seed=1)


# ------------------------------------------------------------------------------ difference


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_difference_image_is_eq23(rng, dtype):
    top = np.iinfo(dtype).max
    on = rng.integers(0, top, (37, 53), endpoint=True).astype(dtype)
    off = rng.integers(0, top, (37, 53), endpoint=True).astype(dtype)
    d = hmlvs.difference_image(on, off)
    expect = np.where(on > off, on.astype(np.int64) - off, 0)
    assert d.dtype == dtype
    np.testing.assert_array_equal(d, expect)
    # a strided (non-contiguous) view is read in place and gives the same result
    big_on = np.zeros((37, 106), dtype)
    big_on[:, ::2] = on
    np.testing.assert_array_equal(hmlvs.difference_image(big_on[:, ::2], off), expect)
    # normalised: (on - off) * mean(off) / max(off, 0.1 mean(off)), rounded. 8-bit images
    # are computed in single precision, which may round a value within ~1e-4 of a
    # half-integer the other way: allow that on a few pixels.
    dn = hmlvs.difference_image(on, off, normalize=True).astype(np.int64)
    dr = ref.difference(on, off, normalize=True).astype(np.int64)
    assert np.abs(dn - dr).max() <= 1 and np.count_nonzero(dn != dr) <= 2


def _normalised_numpy(on, off, offset, scale=None, floor=None):
    """The albedo-offset normalisation as a NumPy expression: the independent reference."""
    fb = off.astype(np.float64)
    mean = float(fb.mean())
    s = mean + offset if scale is None else scale
    fl = max(1.0, 0.1 * mean) if floor is None else floor
    d = np.maximum(on.astype(np.float64) - fb, 0.0) * s / np.maximum(fb + offset, fl)
    return np.clip(np.rint(d), 0, np.iinfo(on.dtype).max).astype(on.dtype)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_difference_image_offset_is_the_numpy_formula(rng, dtype):
    """With an albedo offset the normalisation runs in C++, in double precision, rounded
    half to even: the NumPy expression's value to the bit, whatever the offset's sign, with
    scale and floor automatic or given, on strided views too."""
    top = np.iinfo(dtype).max
    for shape in ((37, 53), (240, 320)):
        on = rng.integers(0, top, shape, endpoint=True).astype(dtype)
        off = rng.integers(0, top, shape, endpoint=True).astype(dtype)
        off[:, : shape[1] // 3] //= 50  # dark pixels: the floor acts
        for offset in (-40.5, -3.7, 0.3, 2.5, 37.25, 1e4):
            for scale, floor in ((None, None), (123.4, None), (None, 7.5), (3e3, 2.0)):
                got = hmlvs.difference_image(on, off, normalize=True, scale=scale,
                                             floor=floor, offset=offset)
                assert got.dtype == dtype
                np.testing.assert_array_equal(
                    got, _normalised_numpy(on, off, offset, scale, floor))
        np.testing.assert_array_equal(
            hmlvs.difference_image(on.T, off.T, normalize=True, offset=5.5),
            _normalised_numpy(on.T, off.T, 5.5))
    # exact half-integers round to even: (on - off) x 1 / (1 + 1) = 0.5, 1.5, 2.5, 3.5, 4.5
    off = np.ones((1, 5), dtype)
    on = (off + np.array([1, 3, 5, 7, 9])).astype(dtype)
    np.testing.assert_array_equal(
        hmlvs.difference_image(on, off, normalize=True, scale=1.0, offset=1.0), [[0, 2, 2, 4, 4]])


def test_albedo_offset_local_filters_are_the_whole_image_ones(rng):
    """albedo_offset reads, per column, the peak of the 5-px box-filtered difference and the
    Gaussian-smoothed laser-off level and its 7 x 7 min / max at that peak: computed on a
    window around the peak, they equal OpenCV's filters of the whole image to the bit
    (image borders, widths that are not a multiple of 8, 8- and 16-bit, small images)."""
    from hmlvs import _core
    from reference_frames import _level_at

    box = np.ones((7, 7), np.uint8)
    for h, w, dtype in ((480, 640, np.uint8), (97, 203, np.uint16), (150, 1001, np.uint8),
                        (16, 130, np.uint16), (40, 77, np.uint8), (9, 12, np.uint8),
                        (3, 2, np.uint16), (300, 129, np.uint8)):
        top = np.iinfo(dtype).max
        diff = rng.integers(0, top // 5, (h, w), endpoint=True).astype(dtype)
        diff[rng.integers(0, h, 3)] = 0  # ties: the first row wins
        # squares of 11 x 13 px at random levels with noise: flat windows and edges
        sq = rng.uniform(0.02, 0.9, (h // 11 + 1, w // 13 + 1)) * top
        off = np.kron(sq, np.ones((11, 13)))[:h, :w] + rng.normal(0, 0.01 * top, (h, w))
        off = np.clip(np.rint(off), 0, top).astype(dtype)
        sm = cv2.blur(diff.astype(np.float32), (5, 1))
        cols = np.arange(w)
        m, total = _core._column_peaks(diff, 2)
        np.testing.assert_array_equal(m, np.argmax(sm, axis=0))
        np.testing.assert_array_equal((np.asarray(total) * 0.2).astype(np.float32),
                                      sm[m, cols])
        m = rng.integers(0, h, w)
        m[:3], m[-3:] = 0, h - 1  # corners
        if w >= 8:
            m[w // 2:w // 2 + 3] = (1, 2, h - 2) if h >= 3 else 1
        offs = cv2.GaussianBlur(off.astype(np.float32), (0, 0), 1.0)
        flat = cv2.dilate(offs, box) <= 1.2 * np.maximum(cv2.erode(offs, box), 1.0)
        level, ok = _level_at(off, m)
        assert level.dtype == np.float32
        np.testing.assert_array_equal(level, offs[m, cols])
        np.testing.assert_array_equal(ok, flat[m, cols])
        assert h < 15 or 0 < np.count_nonzero(ok) < w  # both cases tested


def test_difference_image_colour(rng):
    on = rng.integers(0, 256, (20, 30, 3)).astype(np.uint8)
    off = rng.integers(0, 256, (20, 30, 3)).astype(np.uint8)
    gray = hmlvs.difference_image(on, off)
    g_on, g_off = (cv2.cvtColor(x, cv2.COLOR_BGR2GRAY).astype(int) for x in (on, off))
    np.testing.assert_array_equal(gray, np.clip(g_on - g_off, 0, None))
    red = hmlvs.difference_image(on, off, channel=2)
    np.testing.assert_array_equal(red, np.clip(on[..., 2].astype(int) - off[..., 2], 0, None))


@pytest.mark.parametrize("on, off, match", [
    (np.zeros((4, 5), np.uint8), np.zeros((4, 6), np.uint8), "5 x 4 pixels but the laser-off"),
    (np.zeros((4, 5), np.uint8), np.zeros((4, 5), np.uint16), "different bit depths"),
    (np.zeros((4, 5), np.float32), np.zeros((4, 5), np.float32), "8- or 16-bit"),
    (np.zeros((4, 5, 2), np.uint8), np.zeros((4, 5, 2), np.uint8), "has 2 channels"),
    (np.zeros((0, 5), np.uint8), np.zeros((0, 5), np.uint8), "empty"),
    ([[1, 2]], [[1, 2]], "numpy array"),
])
def test_difference_image_bad_input(on, off, match):
    with pytest.raises(ValueError, match=match):
        hmlvs.difference_image(on, off)


# ------------------------------------------------------------------------------ stripe


@pytest.mark.parametrize("method, options", [(m, {}) for m in METHODS] + [
    ("steger", {"steger_sigma_along": 4.0})])
@pytest.mark.parametrize("direction", ["columns", "rows"])
def test_stripe_matches_numpy_reference(troubled, method, options, direction):
    """C++ and the independent NumPy version agree on every status and every number, on
    images with noise, glare and a reflection (so every status and code path occurs);
    Steger's also with more smoothing along the stripe than across it (its kernel cut short
    at the image's edges)."""
    seen = set()
    for i in range(2):
        d = hmlvs.difference_image(troubled.on[i], troubled.off[i], normalize=True)
        img = d if direction == "columns" else np.ascontiguousarray(d.T)
        a = hmlvs.extract_stripe(img, direction=direction, method=method, **options)
        b = ref.extract(img, direction=direction, method=method, **options)
        np.testing.assert_array_equal(a.status, b["status"])
        np.testing.assert_array_equal(a.num_peaks, b["num_peaks"])
        assert a.threshold == pytest.approx(b["threshold"], rel=1e-12)
        assert a.noise == pytest.approx(b["noise"], rel=1e-12)
        f = a.found
        np.testing.assert_allclose(a.centre[f], b["centre"][f], rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.sigma[f], b["sigma"][f], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a.width, b["width"], rtol=1e-12, equal_nan=True)
        np.testing.assert_allclose(a.intensity, b["intensity"], rtol=0, equal_nan=True)
        seen |= set(np.unique(a.status).tolist())
    assert {StripeStatus.FOUND, StripeStatus.NONE, StripeStatus.MULTIPLE} <= seen


@pytest.mark.parametrize("method", METHODS)
def test_stripe_accuracy_without_noise(clean, method):
    e, _ = stripe_errors(clean, method, normalize=True)
    assert e.size > 0.95 * 8 * 640  # the stripe crosses every column of every image
    assert rms(e) < 0.05
    assert np.abs(e).max() < 0.2
    # Without normalisation the stripe's albedo steps (black/white squares) pull the centre
    # towards the white side: the paper's plain difference image is much worse wherever the
    # stripe runs along a row of corners, i.e. exactly in the paper's procedure.
    e_raw, _ = stripe_errors(clean, method, normalize=False)
    assert rms(e_raw) > 3 * rms(e)


@pytest.mark.parametrize("method, zmax", [("centroid", 1.3), ("gaussian", 1.3), ("steger", 1.5)])
def test_stripe_error_reported_honestly(uniform_noisy, method, zmax):
    """With noise the reported sigma matches the actual error: the normalised errors
    (error / sigma) have an RMS near 1. Steger's sigma neglects the noise of the Hessian and
    runs ~25 % optimistic, hence its wider bound."""
    e, z = stripe_errors(uniform_noisy, method, normalize=False, noise=None)
    assert rms(e) < 0.1
    assert 0.75 < rms(z) < zmax


def test_stripe_rows_equal_columns_of_the_transposed_image(clean):
    d = hmlvs.difference_image(clean.on[0], clean.off[0], normalize=True)
    # threshold and noise given: automatic ones are taken from every 4th image row, which
    # are other pixels in the transposed image
    kw = {"noise": 1.0, "threshold": 20.0}
    for method in METHODS:
        a = hmlvs.extract_stripe(d, method=method, **kw)
        b = hmlvs.extract_stripe(np.ascontiguousarray(d.T), direction="rows", method=method,
                                 **kw)
        np.testing.assert_array_equal(a.status, b.status)
        np.testing.assert_allclose(a.centre, b.centre, rtol=0, atol=1e-12, equal_nan=True)
        np.testing.assert_allclose(a.pixels, b.pixels[:, ::-1], rtol=0, atol=1e-12)
        # a transposed view (strided, no copy) gives the same numbers
        c = hmlvs.extract_stripe(d.T, direction="rows", method=method, **kw)
        np.testing.assert_allclose(c.centre, a.centre, rtol=0, atol=1e-12, equal_nan=True)


def gaussian_column(n, centre, sigma, peak):
    v = np.arange(n)
    return peak * np.exp(-0.5 * ((v - centre) / sigma) ** 2)


def test_stripe_statuses_on_synthetic_columns():
    n = 60
    cols = [
        gaussian_column(n, 20.3, 1.5, 200),                                 # one stripe
        np.zeros(n),                                                        # nothing
        gaussian_column(n, 15.0, 1.5, 200) + gaussian_column(n, 40.0, 1.5, 150),  # two peaks
        np.where(np.arange(n) == 30, 200.0, 0.0),                           # a hot pixel
        # a wide blob: FWHM 47 px, beyond the default max_width of 40 px (a FWHM of 28 px
        # was "too wide" while the default was 20 px; defocused stripes are that wide)
        gaussian_column(n, 30.0, 20.0, 200),
        np.minimum(gaussian_column(n, 25.0, 2.0, 600), 255),                # saturated top
        gaussian_column(n, 10.0, 1.5, 200) + gaussian_column(n, 45.0, 1.5, 60),  # weak echo
    ]
    img = np.clip(np.rint(np.stack(cols, axis=1)), 0, 255).astype(np.uint8)
    s = hmlvs.extract_stripe(img, method="gaussian", threshold=30, noise=1.0)
    S = StripeStatus
    assert s.status.tolist() == [S.FOUND, S.NONE, S.MULTIPLE, S.TOO_NARROW, S.TOO_WIDE,
                                 S.FIT_FAILED, S.MULTIPLE]
    assert s.num_peaks.tolist() == [1, 0, 2, 0, 1, 1, 2]
    assert s.centre[0] == pytest.approx(20.3, abs=0.02)
    assert s.width[0] == pytest.approx(2.3548 * 1.5, abs=0.1)
    assert s.intensity[0] == img[:, 0].max()
    assert np.isnan(s.centre[1:]).all()
    # with a dominance ratio the strong stripe over a weak echo is accepted, the two equal
    # peaks still are not
    s2 = hmlvs.extract_stripe(img, method="centroid", threshold=30, noise=1.0, dominance=2.0)
    assert s2.status[6] == S.FOUND and s2.centre[6] == pytest.approx(10.0, abs=0.02)
    assert s2.status[2] == S.MULTIPLE
    assert s2.pixels.tolist() == [[0.0, s2.centre[0]], [5.0, s2.centre[5]], [6.0, s2.centre[6]]]
    # 16-bit images work the same (same numbers scaled by 256)
    s16 = hmlvs.extract_stripe(img.astype(np.uint16) * 256, method="gaussian",
                               threshold=30 * 256, noise=256.0)
    # Column 5 is not saturated in 16 bits (255 * 256 < 65535): its flat top is fitted as
    # if it were a peak. Saturation is recognised only at the pixel type's maximum.
    np.testing.assert_array_equal(np.delete(s16.status, 5), np.delete(s.status, 5))
    assert s16.status[5] == S.FOUND
    assert s16.centre[0] == pytest.approx(s.centre[0], abs=1e-2)


def test_stripe_reflection_and_glare_are_reported_not_guessed():
    """Over 5 scenes (2 views each) with sensor noise, a saturating glare spot on the stripe
    and a laser reflection 0.6 as bright: reflections are flagged, glare hides the stripe,
    and what is reported is the stripe's. Measured over these 10 views: the plain difference
    takes the reflection in 1 of 4482 columns (p99 error 0.69 px, the rest pulled by its
    albedo bias up to 2.4 px at square edges); the normalised one with a dominance ratio in
    3 of 1182 columns (RMS of the others 0.11 px). The bounds below hold those rates with
    room; columns that take a reflection are the stripe-quality work's to remove."""
    plain, dominant = [], []
    for seed in range(5):
        s = hmlvs.simulate.session(num_poses=2, seed=seed)
        r = hmlvs.simulate.render_session(
            s, options=RenderOptions(noise=2.0, glare=True, spurious=0.6), seed=1)
        w = r.on[0].shape[1]
        lo, hi = (np.array(r.options.spurious_columns) * w).astype(int)
        band = np.arange(lo + 3, hi - 3)
        for i in range(2):
            truth = r.stripe_v[i]
            # The plain difference has the same noise everywhere, so the automatic threshold
            # (5 sigma) keeps noise out. (The normalised one amplifies noise on black squares;
            # dataset_from_images raises its threshold accordingly, tested below.)
            st = hmlvs.extract_stripe(hmlvs.difference_image(r.on[i], r.off[i]))
            plain.append(np.abs(st.centre[st.found] - truth[st.found]))
            # the reflection's columns are flagged as multiple peaks
            assert np.mean(st.status[band] == StripeStatus.MULTIPLE) > 0.8
            # the saturated glare spot hides the stripe there: no stripe, not a wrong one
            g = int(round(r.options.glare_at * (w - 1)))
            assert np.all(st.status[g - 5:g + 6] != StripeStatus.FOUND)
            # with a dominance ratio the stripe (1 / 0.6 brighter) is taken over its
            # reflection; only on the albedo-normalised image, as in the plain one a
            # reflection off a white square can outshine the stripe on a black one
            dn = hmlvs.difference_image(r.on[i], r.off[i], normalize=True)
            thr = hmlvs.image.stripe.normalized_threshold(r.on[i], r.off[i], dn)
            s2 = hmlvs.extract_stripe(dn, dominance=1.3, threshold=thr)
            ok = s2.found[band]
            assert ok.mean() > 0.8
            dominant.append(np.abs(s2.centre[band][ok] - truth[band][ok]))
    plain, dominant = np.concatenate(plain), np.concatenate(dominant)
    # a wrong peak (the reflection) is >= 15 px off; the stripe's own centre within ~2.4 px
    assert np.mean(plain > 3.0) < 0.002 and np.percentile(plain, 99) < 1.0
    assert np.mean(dominant > 3.0) < 0.01
    assert rms(dominant[dominant <= 3.0]) < 0.3


def _slanted_stripe(seed, slope=0.11, speckle=0.1, width=6.0, shape=(120, 400)):
    """A straight stripe v = 50 + slope * u (Gaussian profile of FWHM ``width``, peak 200)
    under multiplicative speckle of ``speckle`` (white noise blurred over ~2 px), and its
    true centres."""
    h, w = shape
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    centre = 50.0 + slope * np.arange(w)
    sd = width / 2.355 * np.sqrt(1 + slope ** 2)  # the profile across a column
    img = 200.0 * np.exp(-0.5 * ((v - centre[None, :]) / sd) ** 2)
    if speckle:
        grain = cv2.GaussianBlur(np.random.default_rng(seed).standard_normal(shape), (0, 0), 1.0)
        img *= 1.0 + speckle * grain / grain.std()
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), centre


def test_steger_smoothing_along_the_stripe():
    """More smoothing along a straight stripe than across it averages more speckle without a
    bias; near the image's first and last columns its kernel is cut short symmetrically (a
    replicated border bends a slanted stripe), and the columns too close to fit are
    FIT_FAILED."""
    iso, along = [], []
    for seed in range(4):
        img, truth = _slanted_stripe(seed)
        a = hmlvs.extract_stripe(img, method="steger", steger_sigma=3.0)
        b = hmlvs.extract_stripe(img, method="steger", steger_sigma=3.0, steger_sigma_along=6.0)
        assert a.found.sum() == b.found.sum() == 400 - 2 * 3  # ceil(3) columns at either edge
        iso.append(a.centre[a.found] - truth[a.found])
        along.append(b.centre[b.found] - truth[b.found])
    iso, along = np.concatenate(iso), np.concatenate(along)
    assert rms(along) < 0.85 * rms(iso)  # measured 0.059 against 0.079 px
    assert abs(np.mean(along) - np.mean(iso)) < 0.003  # no bias of its own (measured 0.0002)
    # without speckle: exact up to the image's edges (a replicated border put the first
    # columns 0.13, 0.26, 0.50 px off on this slope at the three scales; now 0.0033 px)
    img, truth = _slanted_stripe(0, speckle=0.0)
    for sa in (3.0, 6.0, 12.0):
        r = hmlvs.extract_stripe(img, method="steger", steger_sigma=3.0, steger_sigma_along=sa)
        assert np.array_equal(np.nonzero(~r.found)[0], [0, 1, 2, 397, 398, 399])
        assert np.abs(r.centre[r.found] - truth[r.found]).max() < 0.01


def test_peaks_found_on_the_image_smoothed_along_the_stripe():
    """``detect_sigma_along``: a faint stripe (peak 12 grey levels) on noise of 3 clears a
    threshold of 5 smoothed sigmas, where the image's own 5 sigmas cut it; the centres are
    the image's, unchanged on a clean stripe, and the smoothing's noise gain is that of white
    noise (an independent check with OpenCV's filter)."""
    from hmlvs.image.stripe import smoothing_noise_gain

    h, w = 120, 400
    v = np.arange(h)[:, None]
    truth = 50.0 + 0.05 * np.arange(w)
    found, plain = [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        img = 60.0 + 12.0 * np.exp(-0.5 * ((v - truth[None, :]) / 2.0) ** 2) \
            + rng.normal(0.0, 3.0, (h, w))
        base = 60.0 + rng.normal(0.0, 3.0, (h, w))
        on, off = (np.clip(np.rint(x), 0, 255).astype(np.uint8) for x in (img, base))
        d = hmlvs.difference_image(on, off)
        a = hmlvs.extract_stripe(d, method="steger", steger_sigma=3.0)
        b = hmlvs.extract_stripe(d, method="steger", steger_sigma=3.0, detect_sigma_along=2.0)
        plain.append(a.found.mean())
        found.append(b.found.mean())
        assert b.threshold < 0.5 * a.threshold
        e = b.centre[b.found] - truth[b.found]
        assert rms(e) < 0.3  # noise 3 on a 12-level peak (measured 0.17-0.20 px)
    # measured: none found, and 0.970-0.973 of the columns (6 of the 400 are too close to
    # the image's edges for Steger's kernel)
    assert max(plain) < 0.2 and min(found) > 0.93
    img, truth = _slanted_stripe(0, speckle=0.0)
    a = hmlvs.extract_stripe(img, method="steger", steger_sigma=3.0)
    b = hmlvs.extract_stripe(img, method="steger", steger_sigma=3.0, detect_sigma_along=2.0)
    np.testing.assert_array_equal(a.found, b.found)
    np.testing.assert_allclose(b.centre[b.found], a.centre[a.found], atol=1e-9)
    white = np.random.default_rng(9).standard_normal((400, 4000))
    for sigma in (0.5, 2.0, 6.0):
        r = int(np.ceil(3.5 * sigma))
        smooth = cv2.GaussianBlur(white, (2 * r + 1, 1), sigma)[:, r:-r]
        assert smoothing_noise_gain(sigma) == pytest.approx(smooth.std(), rel=0.02)


@pytest.mark.parametrize("kwargs, match", [
    ({"direction": "diagonal"}, "direction must be"),
    ({"method": "moments"}, "method must be"),
    ({"min_width": 5, "max_width": 4}, "min_width < max_width"),
    ({"threshold": -3}, "threshold must be"),
    ({"noise": float("nan")}, "noise must be"),
    ({"steger_sigma": 0.1}, "steger_sigma must"),
    ({"steger_sigma_along": 50.0}, "steger_sigma_along must"),
    ({"steger_sigma_along": float("inf")}, "steger_sigma_along"),
    ({"dominance": 0.5}, "dominance must be"),
    ({"detect_sigma_along": 0.2}, "detect_sigma_along must"),
    ({"detect_sigma_along": float("nan")}, "detect_sigma_along"),
])
def test_extract_stripe_bad_options(kwargs, match):
    with pytest.raises(ValueError, match=match):
        hmlvs.extract_stripe(np.zeros((10, 10), np.uint8), **kwargs)


def test_extract_stripe_bad_images():
    with pytest.raises(ValueError, match="uint8 or uint16"):
        hmlvs.extract_stripe(np.zeros((10, 10)))
    with pytest.raises(ValueError, match="grayscale"):
        hmlvs.extract_stripe(np.zeros((10, 10), np.uint8), channel=1)
    with pytest.raises(ValueError, match="2D grayscale or 3D colour"):
        hmlvs.extract_stripe(np.zeros((2, 10, 10, 3), np.uint8))
