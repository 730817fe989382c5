"""Colour laser-on frames without a laser-off frame: the stripe in the laser's colour.

A real capture is often one colour frame per pose with the laser on (no laser-off frame):
the board's squares, the sheet it is printed on, glare and a darkened room all lie under the
stripe. The laser shows most in one channel (:func:`~hmlvs.image.session.laser_channel`);
the stripe is found on that channel less its background, estimated by opening each column
with a vertical line longer than the stripe is wide (the stripe goes, the board's squares
and edges, taller than the line, stay): :func:`laser_feature`. No division by the
background (an albedo normalisation needs a real laser-off frame: on an estimated one it
divides by a guess and, on a dark frame, by almost nothing).

What was measured on the Blaser UR5e sessions (640 x 480, 25 frames: 14 with the board in a
lit room, 11 laser-only in the dark, both with saturated stripe cores), against an
independent extractor's centres (a half-maximum centroid on a saturation-aware colour
contrast): the red channel less its opening sits 0.1-0.3 px from it on lit and dark frames
alike (spread 0.3-0.5 px on lit frames); a colour contrast red - c green, which would take
out a neutral board's squares, sits 0.5-1.0 px off on the lit frames and 0.1 px on the dark
ones: the camera's chroma (colour sampled at half resolution, green pulled down next to a
red stripe) bends it, and a lit/dark disagreement is what a calibration mixing both kinds of
frame cannot absorb.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from .stripe import StripeResult, StripeStatus, assess_stripe, extract_stripe

#: the first opening's stripe width (px): a line of 2 ceil(1.5 x 10) + 1 = 31 px; the second
#: fits the stripe's median FWHM measured on the first (4-45 px: the Blaser frames' stripes
#: are 6-10 px wide on the board, up to ~45 px as a defocused glow on the dark frames)
BACKGROUND_WIDTH = 10.0
WIDTH_RANGE = (4.0, 45.0)


def is_colour(image: Any) -> bool:
    """A 3- or 4-channel (BGR / BGRA) array."""
    return isinstance(image, np.ndarray) and image.ndim == 3 and image.shape[2] in (3, 4)


def laser_feature(on: np.ndarray, channel: int | None = None,
                  width: float = BACKGROUND_WIDTH) -> np.ndarray:
    """The laser's light in a colour laser-on frame: its channel less the channel's
    background (:func:`~hmlvs.image.session.estimate_background` at stripe FWHM ``width``
    px), same dtype as ``on``. ``channel``: the laser's (default:
    :func:`~hmlvs.image.session.laser_channel`)."""
    from .session import estimate_background, laser_channel

    if not is_colour(on) or on.dtype not in (np.uint8, np.uint16):
        raise ValueError("laser_feature needs an 8- or 16-bit colour (BGR/BGRA) image")
    laser = laser_channel(on) if channel is None else int(channel)
    plane = np.ascontiguousarray(on[:, :, laser])
    bg = estimate_background(plane, width)
    return np.clip(plane.astype(np.float32) - bg, 0.0, None).astype(on.dtype)


def feature_noise(feature: np.ndarray) -> float:
    """The feature image's noise: 1.4826 x its median absolute deviation, at least one grey
    level of an 8-bit image (most of the image is clipped to 0, where the MAD is 0)."""
    f = feature.astype(np.float32)
    mad = float(np.median(np.abs(f - np.median(f))))
    return max(1.4826 * mad, np.iinfo(feature.dtype).max / 255.0)


def colour_stripe(on: np.ndarray, channel: int | None = None,
                  **stripe_options: Any) -> StripeResult:
    """The stripe of a colour laser-on frame alone, on :func:`laser_feature` (opened at the
    stripe's median FWHM, measured on a first opening at :data:`BACKGROUND_WIDTH`).

    Steger's centres at half the stripe's median FWHM (at least 2 px; a first centroid pass
    measures it), which also average the colour blocks of a Bayer camera's chroma across the
    profile; where two peaks compete the strongest is taken when 1.5 x brighter (a specular
    spot, a reflection off the robot); centres more than 1 px from the running median of
    their neighbours are MULTIPLE (see ``session._drop_jumps``). ``stripe_options`` as
    :func:`~hmlvs.image.stripe.extract_stripe` (method, threshold, widths, dominance,
    steger_sigma) override these defaults.

    Raises ``ValueError`` when the automatic threshold leaves no pixel (no stripe).
    """
    from .session import _drop_jumps, laser_channel

    channel = laser_channel(on) if channel is None else channel
    feat = laser_feature(on, channel)
    first = extract_stripe(feat, method="centroid", noise=feature_noise(feat), dominance=1.5)
    w = first.width[first.found]
    if w.size:
        feat = laser_feature(on, channel, float(np.clip(np.median(w), *WIDTH_RANGE)))
    known = {"method", "threshold", "min_width", "max_width", "noise", "steger_sigma",
             "dominance", "steger_sigma_along", "detect_sigma_along"}
    opts = {k: v for k, v in stripe_options.items() if k in known and v is not None}
    opts.setdefault("noise", feature_noise(feat))
    opts.setdefault("dominance", 1.5)
    if opts.get("method") is None:
        first = extract_stripe(feat, **dict(opts, method="centroid"))
        w = first.width[first.found]
        opts["method"] = "steger"
        opts.setdefault("steger_sigma",
                        float(np.clip(0.5 * np.median(w), 2.0, 20.0)) if w.size else 3.0)
    stripe = extract_stripe(feat, **opts)
    if opts.get("threshold") is None and not stripe.found.any() \
            and stripe.threshold >= float(feat.max()):
        raise ValueError(f"the automatic threshold {stripe.threshold:.4g} leaves no pixel of "
                         f"the laser's light (its maximum is {int(feat.max())}): no stripe")
    assessed = assess_stripe(stripe, feat)
    # A saturated core is a plateau, symmetric about the stripe's centre, which Steger's
    # centre takes (its middle): it stays FOUND. On a dark frame the feature is the laser's
    # channel itself, and the stripe on the sheet saturates over most of its length (the
    # Blaser laser-only frames: up to 1,300 saturated pixels a frame).
    status = np.where(assessed.status == StripeStatus.SATURATED, StripeStatus.FOUND,
                      assessed.status).astype(np.uint8)
    return _drop_jumps(replace(assessed, status=status))


def board_gray(image: np.ndarray) -> np.ndarray:
    """The whole image in grey (all channels), for the board's corners."""
    import cv2

    if not is_colour(image):
        return image
    code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
    return cv2.cvtColor(np.ascontiguousarray(image), code)
