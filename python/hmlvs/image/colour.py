"""Colour laser-on frames without a laser-off frame: the stripe in the laser's colour.

A real capture is often one colour frame per pose with the laser on (no laser-off frame):
the board's squares, the sheet it is printed on, glare and a darkened room all lie under the
stripe. The laser shows most in one channel (:func:`laser_channel`);
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

from .. import _core
from .stripe import StripeResult, StripeStatus, as_gray, assess_stripe, extract_stripe, real_number

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
    background (:func:`estimate_background` at stripe FWHM ``width``
    px), same dtype as ``on``. ``channel``: the laser's (default:
    :func:`laser_channel`)."""

    if not is_colour(on) or on.dtype not in (np.uint8, np.uint16):
        raise ValueError("laser_feature needs an 8- or 16-bit colour (BGR/BGRA) image")
    laser = laser_channel(on) if channel is None else int(channel)
    return plane_feature(np.ascontiguousarray(on[:, :, laser]), width)


def plane_feature(plane: np.ndarray, width: float = BACKGROUND_WIDTH) -> np.ndarray:
    """One 8- or 16-bit image plane (a grey frame, or a colour frame's laser channel) less its
    background (:func:`estimate_background` at stripe FWHM ``width`` px), same dtype."""
    bg = estimate_background(plane, width)
    return np.clip(plane.astype(np.float32) - bg, 0.0, None).astype(plane.dtype)


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

    A ``direction`` of "rows" (a stripe running down the image) is found on the frame
    transposed, its scan lines the image rows.

    Raises ``ValueError`` when the automatic threshold leaves no pixel (no stripe).
    """
    if stripe_options.get("direction", "columns") == "rows":
        rest = {k: v for k, v in stripe_options.items() if k != "direction"}
        return replace(colour_stripe(transposed(on), channel, **rest), direction="rows")
    if not is_colour(on) or on.dtype not in (np.uint8, np.uint16):
        raise ValueError("colour_stripe needs an 8- or 16-bit colour (BGR/BGRA) image")
    channel = laser_channel(on) if channel is None else channel
    return feature_stripe(np.ascontiguousarray(on[:, :, channel]), **stripe_options)


def feature_stripe(plane: np.ndarray, **stripe_options: Any) -> StripeResult:
    """The stripe of one 8- or 16-bit image plane of a laser-on frame alone (a grey frame,
    or a colour frame's laser channel) on its :func:`plane_feature`, as
    :func:`colour_stripe` finds it (its options; ``direction`` "rows": transposed)."""
    if stripe_options.get("direction", "columns") == "rows":
        rest = {k: v for k, v in stripe_options.items() if k != "direction"}
        return replace(feature_stripe(transposed(plane), **rest), direction="rows")
    if plane.ndim != 2 or plane.dtype not in (np.uint8, np.uint16):
        raise ValueError("feature_stripe needs an 8- or 16-bit image plane")
    feat = plane_feature(plane)
    first = extract_stripe(feat, method="centroid", noise=feature_noise(feat), dominance=1.5)
    w = first.width[first.found]
    if w.size:
        feat = plane_feature(plane, float(np.clip(np.median(w), *WIDTH_RANGE)))
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
    return drop_jumps(replace(assessed, status=status))


def board_gray(image: np.ndarray) -> np.ndarray:
    """The whole image in grey (all channels), for the board's corners."""
    import cv2

    if not is_colour(image):
        return image
    code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
    return cv2.cvtColor(np.ascontiguousarray(image), code)


def laser_channel(on: np.ndarray, off: np.ndarray | None = None,
                  direction: str = "columns") -> int | None:
    """The colour channel that shows the laser: None for a grayscale image; for colour
    (BGR / BGRA) the channel with the strongest laser-on minus laser-off difference (its
    99.9th-percentile excess), or without a laser-off frame the channel whose stripe stands
    out most from its background (:func:`estimate_background`) in a typical column: the
    median over the columns of their largest excess. (Not a percentile over the image: where
    a stripe's core saturates to white every channel reaches the top there, and the channel
    with the darkest background wins; measured on the Blaser frames, 7 of 55 laser-on
    frames then gave green for a red laser, none with the median.) A stripe that runs down
    the image (``direction`` "rows") is judged on the frames transposed."""
    if not isinstance(on, np.ndarray) or on.ndim != 3 or on.shape[2] == 1:
        return None
    if direction == "rows":
        return laser_channel(transposed(on), transposed(off))
    if on.shape[2] not in (3, 4):
        raise ValueError(f"the laser-on image has {on.shape[2]} channels; expected 1 (gray), "
                         "3 (BGR) or 4 (BGRA)")
    score = []
    for c in range(3):
        a = on[:, :, c]
        b = (estimate_background(np.ascontiguousarray(a)) if off is None
             else off[:, :, c] if isinstance(off, np.ndarray) and off.ndim == 3 else None)
        if b is None:
            return None  # a colour laser-on frame with a gray laser-off one: convert both
        d = a.astype(np.float64) - b
        score.append(float(np.percentile(d, 99.9)) if off is not None
                     else float(np.median(d.max(axis=0))))
    return int(np.argmax(score))


def estimate_background(on: np.ndarray, width: float = 8.0) -> np.ndarray:
    """The laser-on image without its stripe: a morphological opening of every column (a
    vertical line of 2 * ceil(1.5 * width) + 1 px, at least 9) removes bright structures
    narrower than that along the column, such as a roughly horizontal stripe of FWHM
    ``width``, and keeps the board's squares and edges (larger than the line). Stands in
    for the laser-off frame of a session taken without one; the stripe must run across the
    columns (``direction="columns"``). Computed in C++ (the values of OpenCV's
    ``morphologyEx(MORPH_OPEN, ones((k, 1)), borderType=BORDER_REPLICATE)``; a colour image
    channel by channel)."""
    if is_colour(on) and on.dtype in (np.uint8, np.uint16):
        return np.dstack([estimate_background(on[:, :, c], width) for c in range(on.shape[2])])
    return _core._estimate_background(as_gray(on, "the laser-on image", None),
                                      real_number(width, "width"))


def drop_jumps(stripe: StripeResult, window: int = 41, jump: float = 1.0) -> StripeResult:
    """Scan lines whose centre lies more than ``jump`` px from the running median of the
    found centres (``window`` of them) become MULTIPLE: without a laser-off frame a leftover
    of the board (near a square's corner) can outshine a faint stripe in a few neighbouring
    columns, and the stripe is continuous where those are not (computed in C++)."""
    status = _core._drop_jumps(np.asarray(stripe.centre, float),
                               np.asarray(stripe.status, np.uint8))
    return replace(stripe, status=np.asarray(status, np.uint8))


def transposed(image: np.ndarray | None) -> np.ndarray | None:
    """The image with its rows and columns swapped (channels kept), contiguous."""
    if not isinstance(image, np.ndarray):
        return image
    return np.ascontiguousarray(np.swapaxes(image, 0, 1))


#: a found stripe centre has the laser's colour when, within LASER_HUE_HALF px across the
#: stripe, one channel exceeds the next brightest by LASER_HUE_EXCESS of the full scale (on the
#: laser-on frame less the laser-off one when there is one), that channel the one most centres
#: show. Measured on real colour frames (8-bit): the found centres of true stripes exceed by
#: 29-116 grey levels (medians per frame: a red stripe, the Blaser frames at 640 and 1280 px
#: wide, a green one on a hand-held board), glare and board edges found as a stripe by
#: -24 to 14 (0.08 x 255 = 20.4)
LASER_HUE_EXCESS = 0.08
LASER_HUE_HALF = 4


def laser_coloured(stripe: StripeResult, on: np.ndarray, off: np.ndarray | None = None
                   ) -> int | None:
    """How many of ``stripe``'s found centres show the laser's colour (see
    :data:`LASER_HUE_EXCESS`); None for a gray frame, or a colour one whose channels are all
    equal (a gray camera stored as colour), where colour cannot tell."""
    if not is_colour(on) or on.dtype not in (np.uint8, np.uint16):
        return None
    paired = isinstance(off, np.ndarray) and off.shape == on.shape
    if _equal_channels(on) and (not paired or _equal_channels(off)):
        return None
    found = stripe.found
    if not found.any():
        return 0
    line = stripe.position[found].astype(np.intp)
    k = np.arange(-LASER_HUE_HALF, LASER_HUE_HALF + 1)
    columns = stripe.direction != "rows"
    across = np.clip(np.rint(stripe.centre[found]).astype(np.intp)[:, None] + k, 0,
                     on.shape[0 if columns else 1] - 1)

    def near(image: np.ndarray) -> np.ndarray:  # (n, 2 half + 1, 3) beside the centres
        return (image[across, line[:, None], :3] if columns
                else image[line[:, None], across, :3]).astype(np.int32)

    px = near(on) - near(off) if paired else near(on)
    ranked = np.sort(px, axis=2)
    excess = ranked[:, :, 2] - ranked[:, :, 1]
    best = excess.argmax(axis=1)
    hue = px[np.arange(len(line)), best].argmax(axis=1)
    bright = excess.max(axis=1) >= LASER_HUE_EXCESS * np.iinfo(on.dtype).max
    if not bright.any():
        return 0
    return int((bright & (hue == np.bincount(hue[bright], minlength=3).argmax())).sum())


def _equal_channels(image: np.ndarray) -> bool:
    """Whether a colour image's first three channels are all equal (a gray camera's)."""
    return bool(np.array_equal(image[:, :, 0], image[:, :, 1])
                and np.array_equal(image[:, :, 1], image[:, :, 2]))
