"""The NumPy reference of the session pipeline's stripe (parity oracle of the C++ kernel).

``stripe_from_pair(on, off, **options)`` here is hmlvs.image.session.stripe_from_pair as it was
composed in NumPy and OpenCV before the per-frame path moved into one C++ call
(cpp/hmlvs/image/frames.h): whole-image steps -- the difference image, the albedo offset's fit
(OpenCV's GaussianBlur around each column's peak), the noise-aware threshold, the library's
whole-image extraction (ExtractStripe, itself checked against
tests/oracles/reference_stripe.py), the denoised laser-off frame (cv2.bilateralFilter) and the
refinement image smoothed along the stripe (cv2.sepFilter2D) -- glued by NumPy, the way the C++
kernel must reproduce them while computing only what scan lines read. The laser-on frame alone:
the stripe's width first measured on a sample of its columns (the library's extraction on
them), its background by cv2.morphologyEx, scipy's median filter for the jumps. Grey frames
only (the caller picks the channel). tests/parity/test_frames.py compares the two.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from hmlvs import _core
from hmlvs.image.frames import checked_blur_var, smooth_along_of
from hmlvs.image.session import DETECT_ALONG
from hmlvs.image.stripe import (
    Direction,
    StripeResult,
    as_gray,
    assess_stripe,
    difference_image,
    extract_stripe,
    normalized_threshold,
    refine_centres,
)
import numpy as np


def estimate_background(on: np.ndarray, width: float = 8.0) -> np.ndarray:
    """The laser-on image without its stripe: a morphological opening of every column (a
    vertical line of 2 * ceil(1.5 * width) + 1 px, at least 9) removes bright structures
    narrower than that along the column, such as a roughly horizontal stripe of FWHM
    ``width``, and keeps the board's squares and edges (larger than the line). Stands in
    for the laser-off frame of a session taken without one; the stripe must run across the
    columns (``direction="columns"``)."""
    import cv2
    k = max(9, 2 * int(np.ceil(1.5 * width)) + 1)
    kernel = np.ones((k, 1), np.uint8)
    return cv2.morphologyEx(np.ascontiguousarray(on), cv2.MORPH_OPEN, kernel,
                            borderType=cv2.BORDER_REPLICATE)


def _stripe_and_background(on_g: np.ndarray, off_g: np.ndarray | None, normalize: bool,
                           stripe_options: dict[str, Any]
                           ) -> tuple[StripeResult, np.ndarray, float | None]:
    """The stripe of a pair, its laser-off frame (estimated when None) and the albedo offset
    fitted to a given laser-off frame (see :func:`_pair_stripe`)."""
    if off_g is not None:
        o = dict(stripe_options)
        assess = o.pop("assess", True)
        step, offset = o.pop("albedo_step", None), o.pop("albedo_offset", None)
        blur_var = checked_blur_var(o.pop("blur_var", None))
        stripe, fitted = _pair_stripe(on_g, off_g, normalize, assess, step, offset, o,
                                      blur_var)
        return stripe, off_g, fitted
    if stripe_options.get("direction", "columns") != "columns":
        raise ValueError("a laser-on image without a laser-off frame needs a roughly "
                         "horizontal stripe (direction='columns')")
    # the stripe's FWHM, first measured on a sample of the columns against an opening at a
    # generous width, sizes the opening that stands for the laser-off frame (a longer line
    # than needed would also open up small squares). What the opening leaves of the board
    # (short white segments of a column near the squares' corners) is fainter than the
    # laser: the stripe is taken when 1.5 x brighter than it.
    if "dominance" not in stripe_options:
        stripe_options = dict(stripe_options, dominance=1.5)
    width = _first_width(on_g, stripe_options)
    bg = estimate_background(on_g, FIRST_WIDTH if np.isnan(width) else width)
    if stripe_options.get("method") is None and stripe_options.get("steger_sigma") is None:
        # Steger's scale from the same width (the pipeline's rule)
        stripe_options = dict(stripe_options, steger_sigma=3.0 if np.isnan(width) else
                              float(np.clip(0.5 * width, 3.0, 20.0)))
    o = dict(stripe_options)
    assess = o.pop("assess", True)
    step, offset = o.pop("albedo_step", None), o.pop("albedo_offset", None)
    blur_var = checked_blur_var(o.pop("blur_var", None))
    stripe, _ = _pair_stripe(on_g, bg, normalize, assess, step, offset, o, blur_var,
                             drop_jumps=True)
    return _drop_jumps(stripe), bg, None


#: a laser-on frame alone: the stripe width of the first opening, and the most columns the
#: stripe's width is first measured on
FIRST_WIDTH = 16.0
FIRST_COLUMNS = 160


def _first_width(on: np.ndarray, stripe_options: dict[str, Any]) -> float:
    """The stripe's width as first measured on a laser-on frame alone: the median FWHM of
    the scan lines extract_stripe finds (centroid centres; the options' dominance, widths,
    threshold and noise) on every k-th column (k = ceil(columns / FIRST_COLUMNS)) of the
    frame minus its opening at FIRST_WIDTH; NaN when none is found."""
    step = -(-on.shape[1] // FIRST_COLUMNS)
    a = on[:, ::step]
    b = estimate_background(on, FIRST_WIDTH)[:, ::step]  # the opening works column by column
    d = np.ascontiguousarray(a - np.minimum(a, b))
    keep = ("dominance", "min_width", "max_width", "threshold", "noise")
    first = extract_stripe(d, method="centroid",
                           **{k: stripe_options[k] for k in keep
                              if stripe_options.get(k) is not None})
    w = first.width[first.found]
    return float(np.median(w)) if w.size else float("nan")


def _drop_jumps(stripe: StripeResult, window: int = 41, jump: float = 1.0) -> StripeResult:
    """Scan lines whose centre lies more than ``jump`` px from the running median of the
    found centres (``window`` of them) become MULTIPLE: without a laser-off frame a leftover
    of the board (near a square's corner) can outshine a faint stripe in a few neighbouring
    columns, and the stripe is continuous where those are not."""
    from scipy.ndimage import median_filter

    f = np.nonzero(stripe.found)[0]
    if f.size < 5:
        return stripe
    c = stripe.centre[f]
    med = median_filter(c, size=min(window, f.size | 1), mode="nearest")
    bad = f[np.abs(c - med) > jump]
    if not bad.size:
        return stripe
    status = stripe.status.copy()
    status[bad] = 2  # StripeStatus.MULTIPLE
    return replace(stripe, status=status)


def stripe_from_pair(on: np.ndarray, off: np.ndarray | None, *, normalize: bool = True,
                     assess: bool = True, **stripe_options: Any) -> StripeResult:
    """hmlvs.image.session.stripe_from_pair of grey frames, in NumPy and OpenCV."""
    on_g = as_gray(on, "the laser-on image", None)
    stripe_options = dict(stripe_options)
    albedo_step = stripe_options.pop("albedo_step", None)
    albedo_offset_ = stripe_options.pop("albedo_offset", None)
    blur_var = checked_blur_var(stripe_options.pop("blur_var", None))
    if off is None:
        return _stripe_and_background(on_g, None, normalize, dict(
            stripe_options, assess=assess, albedo_step=albedo_step,
            albedo_offset=albedo_offset_, blur_var=blur_var))[0]
    off_g = as_gray(off, "the laser-off image", None)
    return _pair_stripe(on_g, off_g, normalize, assess, albedo_step, albedo_offset_,
                        stripe_options, blur_var)[0]


def _pair_stripe(on_g: np.ndarray, off_g: np.ndarray, normalize: bool, assess: bool,
                 albedo_step: float | None, albedo_offset_: float | None,
                 stripe_options: dict[str, Any], blur_var: float = 0.0,
                 drop_jumps: bool = False) -> tuple[StripeResult, float | None]:
    """:func:`stripe_from_pair` of gray frames, and the albedo offset it fitted: NaN when
    the stripe does not lie on two clearly different levels (0 is used), None when none was
    fitted (given, or no normalisation). With ``drop_jumps`` (a laser-on frame alone against
    its estimated background) Steger's centres that jump from their neighbours' are dropped
    (:func:`_drop_jumps`) before the refinement (the caller drops them again after it)."""
    opts = dict(stripe_options)
    along = smooth_along_of(opts.pop("smooth_along", None))
    offset, noise = 0.0, None
    fitted = None
    if normalize:
        if albedo_offset_ is None:
            direction = opts.get("direction", "columns")
            offset, noise = _albedo_offset(on_g, off_g, direction)
            fitted = offset
            offset = 0.0 if np.isnan(offset) else offset
            if direction != "columns":
                noise = None  # estimated on the transposed images: not the threshold's
        else:
            offset = float(albedo_offset_)
        normalize = not np.isinf(offset)
    d = difference_image(on_g, off_g, normalize=normalize, offset=offset if normalize else 0.0)
    automatic = opts.get("threshold") is None
    first_opts: dict[str, Any] = {}
    if normalize and automatic:
        # Normalising raises the noise on dark squares, and the threshold that keeps their
        # noise out would cut a faint stripe on a noisy image (3 grey levels of noise: half
        # the columns lost): peaks are found on the image smoothed along the stripe.
        opts.setdefault("detect_sigma_along", DETECT_ALONG)
        opts["threshold"], plain = normalized_threshold(
            on_g, off_g, d, offset, noise, (opts["detect_sigma_along"], 0.0))
        # the width estimate below needs a sample of the stripe's columns, not all: its pass
        # finds them on the image itself (half the smoothing's cost)
        first_opts = {"detect_sigma_along": 0.0, "threshold": plain}
    weighted = opts.get("method") is None
    if opts.get("method") is None:
        # The pipeline's default centre: Steger's line detector at a scale fitted to the
        # stripe (half its median FWHM, at least 3 px). Its smoothing along the stripe
        # averages the laser speckle of neighbouring columns, which dominates the error of
        # a per-column centroid (measured on the general renders: 0.10 -> 0.05 px RMS).
        first = extract_stripe(d, **dict(opts, method="centroid", **first_opts))
        w = first.width[first.found]
        opts["method"] = "steger"
        if opts.get("steger_sigma") is None:
            opts["steger_sigma"] = float(np.clip(0.5 * np.median(w), 3.0, 20.0)) if w.size \
                else 3.0
        if opts.get("steger_sigma_along") is None and along != 1.0:
            opts["steger_sigma_along"] = min(along * opts["steger_sigma"], 40.0)
    stripe = extract_stripe(d, **opts)
    if automatic and not stripe.found.any() and stripe.threshold >= float(d.max()):
        raise ValueError(f"the automatic threshold {stripe.threshold:.4g} leaves no pixel of "
                         f"the difference image (its maximum is {int(d.max())}): no stripe")
    if drop_jumps:
        stripe = _drop_jumps(stripe)
    if weighted:
        stripe = _weighted_centres(stripe, on_g, off_g, normalize, offset, noise,
                                   opts.get("steger_sigma_along") or opts["steger_sigma"],
                                   blur_var)
    if assess:
        # An albedo step under the profile is corrected by the normalisation (measured on
        # the general renders: 0.09 px RMS at steps, against 0.05 px elsewhere, at most 0.2
        # px), and the paper's corner mode needs the stripe that runs along a row of
        # squares' edges: by default the ALBEDO_EDGE check runs only without the
        # normalisation (``albedo_step`` chooses).
        if albedo_step is None:
            albedo_step = 0.0 if normalize else 1.5
        stripe = assess_stripe(stripe, d, on_g, off_g, albedo_step=albedo_step,
                               albedo_offset=max(offset, 0.0) if normalize else 0.0)
    return stripe, fitted


def _weighted_centres(stripe: StripeResult, on_g: np.ndarray, off_g: np.ndarray,
                      normalize: bool, offset: float, noise: float | None,
                      sigma_along: float, blur_var: float = 0.0) -> StripeResult:
    """The pipeline's default centres: Steger's ``stripe`` refined by
    :func:`~hmlvs.image.stripe.refine_centres` on the unrounded difference image, whose
    laser-off frame is first denoised by an edge-preserving (bilateral) filter: the frame is
    the board's print under steady light, flat but for the squares' edges, and its noise would
    otherwise enter the difference a second time. Measured on 9 sessions of an independent
    renderer (tests/oracles/independent_check.py): each view's mean centre error 0.0113 px RMS with
    Steger's centre, 0.0104 px refined on the plain difference, 0.0095 px with the denoised
    frame. With ``blur_var`` (px^2: the variance of the optics' blur and the pixel's area)
    the normalised difference is corrected at albedo steps (see :func:`stripe_from_pair`)."""
    import cv2

    if noise is None:
        noise = float(_core._estimate_difference_noise(
            _core._difference_image(on_g, off_g, False, -1.0, -1.0)))
    frame = noise / np.sqrt(2.0)  # one frame's noise, of the difference of two
    mean = float(off_g.mean())
    # Only a band around the stripe is read: each scan line's window reaches at most 4.5
    # profile sigmas (plus a pixel) from Steger's centre; the filter's 3 px radius more.
    found = stripe.found & np.isfinite(stripe.centre) & np.isfinite(stripe.width)
    if not found.any():
        return stripe
    reach = 4.5 * np.maximum(0.5, stripe.width[found] / 2.3548) + 2.0
    n_prof = off_g.shape[0] if stripe.direction == "columns" else off_g.shape[1]
    lo = int(max(0, np.floor(np.min(stripe.centre[found] - reach)) - 4))
    hi = int(min(n_prof, np.ceil(np.max(stripe.centre[found] + reach)) + 5))
    band = (slice(lo, hi), slice(None)) if stripe.direction == "columns" else \
        (slice(None), slice(lo, hi))
    full_shape = off_g.shape
    on_g, off_g = on_g[band], off_g[band]
    off_f = off_g.astype(np.float32)
    if frame > 0:
        # 7 px across, 3 px scale; a step of 4 noise sigmas (the print's edges are tens) is
        # kept
        bg = cv2.bilateralFilter(off_f, 7, 4.0 * frame, 3.0)
    else:
        bg = off_f
    diff = np.maximum(on_g.astype(np.float32) - bg, 0.0)
    if normalize:
        level = np.maximum(bg + np.float32(offset), max(1.0, 0.1 * mean))
        gain = (mean + offset) / level
        diff *= gain.astype(np.float32)
        if blur_var > 0:
            # Where the albedo changes under the profile, the blurred product of laser and
            # albedo divided by the blurred albedo is not the laser's profile: to first
            # order in the blur's variance s2 it is P + s2 grad(P) . grad(log albedo).
            lv, lu = np.gradient(np.log(level))
            pv, pu = np.gradient(diff)
            diff = (diff - np.float32(blur_var) * (pv * lv + pu * lu)).astype(np.float32)
    else:
        gain = np.ones(1, np.float32)
    # each scan line's additive noise: the laser-on frame's, times the gain at its centre
    pos = np.clip(np.nan_to_num(np.rint(stripe.centre)) - lo, 0, hi - lo - 1).astype(int)
    if gain.size == 1:
        g = np.ones(pos.size)
    elif stripe.direction == "columns":
        g = gain[pos, np.arange(pos.size)]
    else:
        g = gain[np.arange(pos.size), pos]
    line_noise = np.where(stripe.found, frame * g, np.nan)
    whole = np.zeros(full_shape, np.float32)
    whole[band] = diff
    return refine_centres(stripe, whole, line_noise, sigma_along=sigma_along)


def _albedo_offset(on: np.ndarray, off: np.ndarray,
                   direction: Direction = "columns") -> tuple[float, float]:
    """:func:`albedo_offset` (NaN where it returns 0 for want of two levels) and the noise
    estimate of the plain difference image it used (``_estimate_difference_noise``; for
    ``direction="rows"`` of the transposed images)."""
    a = as_gray(on, "the laser-on image", None)
    b = as_gray(off, "the laser-off image", None)
    if direction == "rows":
        a, b = a.T, b.T
    b = np.ascontiguousarray(b)
    diff = _core._difference_image(np.ascontiguousarray(a), b, False,
                                   -1.0, -1.0)  # max(on - off, 0), once for both uses
    noise = float(_core._estimate_difference_noise(diff))
    # Per column the peak of the difference averaged over 5 px along the stripe (less noise,
    # the same peak), as cv2.blur(diff, (5, 1)) gives it (the 5-sum / 5 in double, rounded to
    # float), found in C++ without filtering the whole image; the first row on ties.
    m, total = _core._column_peaks(diff, 2)
    m = np.asarray(m, dtype=np.intp)
    peak = (np.asarray(total) * 0.2).astype(np.float32)
    # the laser-off level (Gaussian, sigma 1 px) under the peak and whether it is flat (max /
    # min within 7 x 7 px below 1.2), computed on a window around each column's peak
    level, flat = _level_at(b, m)
    top = float(np.iinfo(a.dtype).max)
    cols = np.arange(a.shape[1])
    lo, hi = np.clip(m - 2, 0, a.shape[0] - 1), np.clip(m + 2, 0, a.shape[0] - 1)
    # 5 sigma of the 5-pixel mean (sqrt(5) less noise than a pixel): at 3 grey levels of
    # noise, 5 sigmas of a pixel left too few dark squares' peaks for the fit
    ok = flat & (peak > max(5.0 * noise / np.sqrt(5.0), 3.0)) & (a[lo, cols] < top) & \
        (a[m, cols] < top) & (a[hi, cols] < top)
    return _affine_offset(peak[ok], level[ok]), noise


def _affine_offset(peak: np.ndarray, level: np.ndarray) -> float:
    """The offset a of the peaks' fit as proportional to level + a (see albedo_offset); NaN
    when the peaks do not lie on two clearly different levels."""
    if peak.size < 20:
        return float("nan")
    p2, p98 = np.percentile(level, [2, 98])
    if not p98 > 2.0 * max(p2, 1.0):
        return float("nan")
    split = np.sqrt(max(p2, 1.0) * p98)
    dark = level < split
    if dark.sum() < 10 or (~dark).sum() < 10:
        return float("nan")
    pd, pl = float(np.median(peak[dark])), float(np.median(peak[~dark]))
    od, ol = float(np.median(level[dark])), float(np.median(level[~dark]))
    if pl <= pd:
        return float("inf")
    return max((pd * ol - pl * od) / (pl - pd), -0.5 * od)


def _reflect101(i: np.ndarray, n: int) -> np.ndarray:
    """Indices mirrored into 0..n-1 as OpenCV's BORDER_REFLECT_101 does (``gfedcb|abcdefgh``)."""
    if n == 1:
        return np.zeros_like(i)
    i = np.abs(i) % (2 * (n - 1))
    return np.where(i >= n, 2 * (n - 1) - i, i)


def _level_at(off: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column c, with ``g = cv2.GaussianBlur(off.astype(np.float32), (0, 0), 1.0)``:
    ``g[m[c], c]`` and whether ``max <= 1.2 * max(min, 1)`` over the 7 x 7 pixels of ``g``
    around it that lie in the image (``cv2.dilate`` / ``cv2.erode`` with a 7 x 7 box), the
    same values as filtering the whole image, at a fraction of its cost.

    The 15 x 15 pixel window of ``off`` around each (m[c], c) (mirrored at the image border
    as GaussianBlur's BORDER_REFLECT_101) holds every pixel the 9-tap kernel reads for the
    central 7 x 7: the windows side by side make one 15-row image for GaussianBlur, whose
    value at a pixel depends only on its neighbours, except in OpenCV's scalar loop over an
    image's last (width mod vector width, 8 here) columns, which rounds differently from its
    vector loop: windows reaching those columns are taken from a blur of the image's last
    24..87 columns, started at a multiple of 64 so that the same columns fall in its scalar
    loop. (That these are OpenCV's values to the bit is a test, run on this OpenCV build.)
    """
    import cv2
    from numpy.lib.stride_tricks import sliding_window_view

    h, w = off.shape
    r7 = np.arange(-3, 4)
    rows = m[:, None] + r7                                   # (w, 7)
    cols = np.arange(w)[:, None] + r7                        # (w, 7)
    inside = ((rows >= 0) & (rows < h))[:, :, None] & ((cols >= 0) & (cols < w))[:, None, :]
    rc, cc = np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)
    if h < 15 or w < 128:  # small images: the whole image
        g = cv2.GaussianBlur(off.astype(np.float32), (0, 0), 1.0)
        win = g[rc[:, :, None], cc[:, None, :]]
    else:
        pad = cv2.copyMakeBorder(off, 7, 7, 7, 7, cv2.BORDER_REFLECT_101)
        mosaic = np.zeros((15, -(-15 * w // 64) * 64), np.float32)  # no scalar tail in it
        mosaic[:, :15 * w].reshape(15, w, 15)[...] = \
            sliding_window_view(pad, (15, 15))[m, np.arange(w)].transpose(1, 0, 2)
        g = cv2.GaussianBlur(mosaic, (0, 0), 1.0)
        win = g[:, :15 * w].reshape(15, w, 15)[4:11, :, 4:11].transpose(1, 0, 2).copy()
        x0 = max(0, (w - 24) // 64 * 64)
        tail = np.arange(x0 + 7, w)  # windows from column x0 + 4 on: the strip's own pixels
        strip = cv2.GaussianBlur(off[:, x0:].astype(np.float32), (0, 0), 1.0)
        win[tail] = strip[rc[tail][:, :, None], cc[tail][:, None, :] - x0]
    inf = np.float32(np.inf)
    hi = np.where(inside, win, -inf).max(axis=(1, 2))
    lo = np.where(inside, win, inf).min(axis=(1, 2))
    return win[:, 3, 3], hi <= 1.2 * np.maximum(lo, 1.0)


