"""One frame's stripe in the C++ pipeline (cpp/hmlvs/image/frames.h): its options
(:func:`frames_options`, checked once for many frames), the stripe of grey frames
(:func:`frames_stripe`), and of a grey laser-on frame alone the better of that and the laser
feature (:func:`alone_way`). :func:`hmlvs.image.session.stripe_from_pair` is the whole
pipeline of a pair of frames of any kind."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _core
from .colour import BACKGROUND_WIDTH, estimate_background, feature_stripe, transposed
from .stripe import StripeOptions, StripeResult, finite_number, real_number

#: a grey laser-on frame alone: its stripe is found against its normalised estimated
#: background (the C++ pipeline) unless that finds fewer than FEATURE_FALLBACK times the
#: scan lines the laser feature does (:func:`~hmlvs.image.colour.feature_stripe`, the
#: colour frames' way: no division by a guessed background), and then there. Measured on
#: the real Blaser frames seen as grey (their red channel: a fine board of 5 mm squares on a
#: white sheet under a red stripe): the normalised background takes the board's leftovers
#: for noise and finds 0-0.46 times the feature's scan lines on 8 of the 14 board frames (on
#: 4 no pixel above its threshold), 0.64-1.0 times on the others, 0.79-1.29 on the
#: laser-only frames; on renders of the example sensor (squares of 30 mm, a bright stripe)
#: 0.74-0.95 times, and its centres are the closer there (0.05-0.22 px RMS against
#: 0.07-0.22)
FEATURE_FALLBACK = 0.5


def alone_stripe(on_g: np.ndarray, core: Any, stripe_options: dict[str, Any],
                 background: bool = True
                 ) -> tuple[StripeResult, np.ndarray | None, float | None]:
    """The stripe of a grey laser-on frame alone, the background it was found against (with
    ``background``; else None) and the albedo offset fitted (see :func:`alone_way`)."""
    return alone_way(on_g, core, stripe_options, background)[0]


def alone_way(on_g: np.ndarray, core: Any, stripe_options: dict[str, Any],
              background: bool = True
              ) -> tuple[tuple[StripeResult, np.ndarray | None, float | None], str]:
    """:func:`alone_stripe` and the way it was found: "frames" (against the normalised
    estimated background, the C++ options ``core`` of ``stripe_options``) or "feature" (on
    the laser feature: see :data:`FEATURE_FALLBACK`, automatic options only). Raises
    ``ValueError`` when neither way finds a stripe."""
    want = background
    try:
        stripe, background, fitted = frames_stripe(on_g, None, core, background=want)
        error = None
    except ValueError as e:  # its threshold leaves no pixel
        stripe, error = None, e
    automatic = all(stripe_options.get(k) is None for k in ("threshold", "method"))
    # the feature finds a centre on at most every scan line: a stripe found on half of them
    # or more is kept without looking (the same choice, at the cost of the normalised way)
    enough = stripe is not None and stripe.found.sum() >= FEATURE_FALLBACK * len(stripe.found)
    feature = None
    if automatic and not enough and on_g.dtype in (np.uint8, np.uint16):
        try:
            feature = feature_stripe(on_g, **stripe_options)
        except ValueError:
            pass
    if feature is not None and (stripe is None or
                                stripe.found.sum() < FEATURE_FALLBACK * feature.found.sum()):
        width = float(np.median(feature.width[feature.found])) if feature.found.any() \
            else BACKGROUND_WIDTH
        if not want:
            bg = None
        elif feature.direction == "rows":
            bg = transposed(estimate_background(transposed(on_g), width))
        else:
            bg = estimate_background(on_g, width)
        return (feature, bg, None), "feature"
    if error is not None:
        raise error
    return (stripe, background, fitted), "frames"


#: the options of :func:`extract_stripe` whose None is the pipeline's choice, not a value
_CHOSEN = ("method", "threshold", "noise", "steger_sigma", "steger_sigma_along")


def frames_options(*, normalize: bool = True, **stripe_options: Any) -> Any:
    """The C++ options of :func:`stripe_from_pair` with ``stripe_options`` (checked: an
    unknown option raises ``TypeError``, a wrong value ``ValueError`` naming it), built once
    for many frames (:class:`hmlvs.Measurer`)."""
    o = dict(stripe_options)
    assess = o.pop("assess", True)
    albedo_step = o.pop("albedo_step", None)
    albedo_offset_ = o.pop("albedo_offset", None)
    blur_var = checked_blur_var(o.pop("blur_var", None))
    along = smooth_along_of(o.pop("smooth_along", None))
    opts = StripeOptions(**{k: v for k, v in o.items() if not (k in _CHOSEN and v is None)
                            and k != "channel"})
    fo = _core._FrameStripeOptions()
    fo.stripe = opts.to_core()
    fo.method_given = o.get("method") is not None
    fo.steger_sigma_given = o.get("steger_sigma") is not None
    fo.steger_sigma_along_given = o.get("steger_sigma_along") is not None
    fo.detect_sigma_along_given = "detect_sigma_along" in o
    fo.dominance_given = "dominance" in o
    fo.normalize = bool(normalize)
    if albedo_offset_ is not None:
        a = real_number(albedo_offset_, "offset")
        if np.isnan(a):
            raise ValueError("offset must be a number or inf, got nan")
        fo.albedo_offset = a
    fo.assess = bool(assess)
    if albedo_step is not None:
        fo.albedo_step = finite_number(albedo_step, "albedo_step")
    fo.blur_var = blur_var
    fo.smooth_along = along
    return fo


def frames_stripe(on_g: np.ndarray, off_g: np.ndarray | None, options: Any,
                  background: bool = False
                  ) -> tuple[StripeResult, np.ndarray | None, float | None]:
    """:func:`stripe_from_pair` of grey frames with the C++ ``options`` of
    :func:`frames_options`: the stripe, the background estimated for a laser-on frame alone
    (with ``background``; else None) and the albedo offset fitted (see
    :func:`_stripe_and_background`)."""
    r, fitted, offset, no_pixel, image_max, refined, bg = _core._stripe_from_frames(
        on_g, off_g, options, bool(background))
    if no_pixel:
        raise ValueError(f"the automatic threshold {r.threshold:.4g} leaves no pixel of the "
                         f"difference image (its maximum is {int(image_max)}): no stripe")
    o = options.stripe
    direction = "columns" if o.direction == _core._StripeDirection.columns else "rows"
    if not options.method_given:
        method = "weighted" if refined else "steger"
    else:
        method = o.method.name
    n = r.centre.shape[0]
    stripe = StripeResult(
        position=np.arange(n), centre=np.asarray(r.centre), intensity=np.asarray(r.intensity),
        width=np.asarray(r.width), sigma=np.asarray(r.sigma),
        status=np.asarray(r.status, dtype=np.uint8), num_peaks=np.asarray(r.num_peaks),
        direction=direction, method=method, threshold=float(r.threshold),
        noise=float(r.noise), residual=np.asarray(r.residual))
    return stripe, bg, (float(offset) if fitted else None)


def _in_range(value: Any, lo: float, hi: float) -> float | None:
    """``value`` as a float when it is a number in [lo, hi], else None."""
    if isinstance(value, bool):
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) and lo <= v <= hi else None


def checked_blur_var(value: Any) -> float:
    """The ``blur_var`` stripe option, checked (None: 0, no correction at albedo steps)."""
    if value is None:
        return 0.0
    v = _in_range(value, 0.0, MAX_BLUR_VAR)
    if v is None:
        raise ValueError(f"blur_var must lie in [0, {MAX_BLUR_VAR:g}] px^2 (the variance of "
                         f"the camera's blur, for the correction at albedo steps), got "
                         f"{value!r}")
    return v


#: the largest blur variance (px^2) the correction at albedo steps takes or fits: a blur of
#: 2 px (1 sigma); beyond it the first-order correction no longer holds
MAX_BLUR_VAR = 4.0


def smooth_along_of(value: Any) -> float:
    """The ``smooth_along`` stripe option, checked (None: 1, the same scale as across)."""
    if value is None:
        return 1.0
    v = _in_range(value, 1.0, 10.0)
    if v is None:
        raise ValueError(f"smooth_along must lie in [1, 10] (Steger's scale along the stripe "
                         f"as a multiple of the scale across it), got {value!r}")
    return v
