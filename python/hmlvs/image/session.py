"""A session of laser on/off images -> stripes and a calibration data set."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import _core
from .colour import (  # noqa: F401 (laser_channel, estimate_background re-exported)
    board_gray,
    colour_stripe,
    drop_jumps,
    estimate_background,
    is_colour,
    laser_channel,
)
from .direction import either_way
from .frames import MAX_BLUR_VAR, alone_stripe, checked_blur_var, frames_options, frames_stripe
from .stripe import (
    StripeResult,
    StripeStatus,
    as_gray,
)

#: the laser-off name of a pair without a laser-off frame (shown in its report)
ESTIMATED_OFF = "none: background estimated from the laser-on image"

# ------------------------------------------------------------------------------------------
# A session of images -> a calibration data set


class PairRejected(Exception):
    """A whole image pair is unusable (the message says why)."""


_BOARD_POSE_HINT = ("check the board's origin, row_direction and col_direction in the "
                    "manifest and this pair's pose")


def opencv_failure(err: Exception, stage: str, hint: str = _BOARD_POSE_HINT) -> PairRejected:
    """An OpenCV error inside one pair's processing, as that pair's rejection: OpenCV
    asserts on degenerate input (corners predicted far from the detected ones, as with a
    wrong board origin or direction in the manifest), which concerns this pair only."""
    lines = str(err).strip().splitlines() or [type(err).__name__]
    what = getattr(err, "err", "") or lines[-1]
    func = getattr(err, "func", "")
    return PairRejected(f"{stage}: OpenCV failed ({func + ': ' if func else ''}{what})"
                   + (f"; {hint}" if hint else ""))


def _load(item: Any, folder: Any, what: str) -> tuple[np.ndarray, str]:
    import os

    from .._io import read_image
    if isinstance(item, np.ndarray):
        return item, "<array>"
    if not isinstance(item, (str, Path)):
        raise PairRejected(f"the {what} image must be a file name or an array, got "
                      f"{type(item).__name__}")
    path = Path(item)
    if folder is not None and not path.is_absolute():
        path = Path(folder) / path
    try:
        os.fsencode(path)  # before is_file, which says False for a name no file can have
        if not path.is_file():
            raise PairRejected(f"the {what} image file {path} does not exist")
        img = read_image(path)  # by bytes: cv2.imread crashes on a name that is not UTF-8
    except UnicodeError:
        raise PairRejected(f"the {what} image file {str(path)!r}: its name holds a character no "
                      "file name can (an unpaired surrogate); rename it") from None
    except ValueError as e:
        raise PairRejected(str(e)) from None
    except OSError as e:
        raise PairRejected(f"the {what} image file {path} cannot be read ({e.strerror})") from None
    if img is None:
        raise PairRejected(f"the {what} image file {path.name} cannot be read as an image")
    return img, path.name


def read_session_manifest(source: Any) -> tuple[list[dict[str, Any]], dict[str, Any], Any]:
    from ..data.manifest import read_manifest

    return read_manifest(source)


def manifest_direction(doc: dict[str, Any], stripe_options: dict[str, Any]
                       ) -> dict[str, Any]:
    """``stripe_options`` with the manifest's ``stripe_direction`` ("columns" or "rows": the
    sensor's stripe runs that way in every frame) unless the options give a direction."""
    way = doc.get("stripe_direction")
    if way in (None, "auto") or stripe_options.get("direction") not in (None, "auto"):
        return stripe_options
    return dict(stripe_options, direction=way)


def record_id(rec: Any, index: int) -> str:
    return str(rec.get("id", f"p{index:03d}")) if isinstance(rec, dict) else f"p{index:03d}"


def record_names(rec: Any) -> tuple[str, str]:
    if not isinstance(rec, dict):
        return "?", "?"
    return tuple(str(rec.get(k, "?")) if not isinstance(rec.get(k), np.ndarray) else "<array>"
                 for k in ("on", "off"))  # type: ignore[return-value]


@dataclass
class Pair:
    """One laser on/off pair after the checks shared by calibration and measurement."""

    on_name: str
    off_name: str
    joints: np.ndarray | None  # rad; None when the entry gives a pose
    pose: np.ndarray | None  # base_from_hand (4, 4); None in a bench session
    on: np.ndarray | None  # None once the stripe and corners are found
    off: np.ndarray | None  # the laser-off frame, or the background estimated from the
    # laser-on one
    stripe: StripeResult
    size: tuple[int, int]
    offset: float | None = None  # the albedo offset fitted (see _stripe_and_background)
    board: np.ndarray | None = None  # the frame for the board's corners, when not ``off``

    @property
    def board_image(self) -> np.ndarray:
        """The frame the board's corners are found on: a colour frame's grey (all channels),
        else the laser-off frame (or the background estimated for it)."""
        return self.board if self.board is not None else self.off


def read_pair(rec: Any, index: int, folder: Any, unit: str, robot: Any,
               size: tuple[int, int] | None, channel: int | None, normalize: bool,
               stripe_options: dict[str, Any], min_stripe: int,
               defer: bool = False) -> Pair:
    """Load, check and extract the stripe of one manifest record; raises PairRejected.

    A record without ``off`` is a laser-on image alone: its background (the board under
    ambient light) is estimated from it (:func:`estimate_background`) and stands in for the
    laser-off frame, and the report's laser-off name says so. With ``defer``, a pair whose
    albedo offset could not be fitted (``offset`` NaN) is returned without the check of
    ``min_stripe``: its stripe is to be extracted again with the session's offset
    (:func:`restripe`)."""
    if not isinstance(rec, dict):
        raise PairRejected(f"record {index} is not a mapping with on, off and joints")
    if "on" not in rec:
        raise PairRejected("the record lacks 'on'")
    joints, pose = record_pose(rec, robot, unit)
    on, on_name = _load(rec["on"], folder, "laser-on")
    off = None
    off_name = ESTIMATED_OFF
    if rec.get("off") is not None:
        off, off_name = _load(rec["off"], folder, "laser-off")
    # a colour frame alone: the stripe from the laser's colour (hmlvs.image.colour), unless
    # a channel is named
    by_colour = off is None and channel is None and is_colour(on)
    board = board_gray(on if off is None else off) if is_colour(on) else None
    if channel is None:
        try:
            channel = laser_channel(on, off)
        except ValueError as e:
            raise PairRejected(str(e)) from None
    try:
        on_g = as_gray(on, "the laser-on image", channel)
        off_g = None if off is None else as_gray(off, "the laser-off image", channel)
    except ValueError as e:
        raise PairRejected(str(e)) from None
    if off_g is not None and (on_g.shape != off_g.shape or on_g.dtype != off_g.dtype):
        raise PairRejected(f"the laser-on image ({on_g.shape[1]} x {on_g.shape[0]}, "
                      f"{on_g.dtype}) and the laser-off image ({off_g.shape[1]} x "
                      f"{off_g.shape[0]}, {off_g.dtype}) differ in size or depth")
    if size is None:
        size = (on_g.shape[1], on_g.shape[0])
    if (on_g.shape[1], on_g.shape[0]) != size:
        raise PairRejected(f"the images are {on_g.shape[1]} x {on_g.shape[0]} pixels but the "
                      f"session's are {size[0]} x {size[1]}")
    top = float(np.iinfo(on_g.dtype).max)
    if off_g is not None and int(off_g.max()) == 0:
        raise PairRejected("the laser-off image is all black")
    if int(on_g.max()) == 0:
        raise PairRejected("the laser-on image is all black")
    if off_g is not None:
        diff_big = np.abs(on_g.astype(np.int32) - off_g.astype(np.int32)) > 0.1 * top
        if diff_big.mean() > 0.05:
            raise PairRejected(f"the laser-on and laser-off images differ in "
                          f"{100 * diff_big.mean():.0f}% of the pixels, far more than a "
                          "stripe: they are not a pair taken at the same pose")

    def extract(options: dict[str, Any]) -> tuple[StripeResult, Any, float | None]:
        if by_colour:  # the laser's channel judged the stripe's way (rows: transposed)
            ch = channel if options["direction"] == "columns" else None
            return colour_stripe(on, ch, **options), board, None
        return _stripe_and_background(on_g, off_g, normalize, options)

    try:
        stripe, off_g, offset = either_way(extract, stripe_options, on, off)
    except ValueError as e:  # the threshold leaves no pixel
        raise PairRejected(f"no laser stripe found in {on_name}: {e}") from None
    pair = Pair(str(on_name), str(off_name), joints, pose, on_g, off_g, stripe, size, offset,
                 board)
    if not (defer and stripe_pending(pair)):
        check_stripe(pair, min_stripe)
    return pair


def stripe_pending(pair: Pair) -> bool:
    """Whether the pair's stripe waits for the session's albedo offset (see read_pair)."""
    return pair.offset is not None and bool(np.isnan(pair.offset))


def stripe_direction(on: np.ndarray, off: np.ndarray | None = None, **stripe_options: Any
                     ) -> str:
    """Which way the stripe of a laser on/off pair runs (``off`` may be None): "columns"
    (across the image, one centre per image column) or "rows" (down it), as
    :func:`either_way` decides with :func:`stripe_from_pair`."""
    options = dict(stripe_options, direction="auto")
    return either_way(lambda o: (stripe_from_pair(on, off, **o), None, None), options, on,
                      off)[0].direction


def with_direction(stripe_options: dict[str, Any], on: np.ndarray, off: np.ndarray | None
                   ) -> dict[str, Any]:
    """``stripe_options`` with the stripe's ``direction``: as given, or when not given (or
    "auto") the pair's own (:func:`stripe_direction`; "columns" when it has no stripe)."""
    given = stripe_options.get("direction")
    if given is not None and given != "auto":
        return stripe_options
    try:
        way = stripe_direction(on, off, **{k: v for k, v in stripe_options.items()
                                           if k != "direction"})
    except ValueError:  # no stripe in this frame: the pipeline's own way
        way = "columns"
    return dict(stripe_options, direction=way)


def check_stripe(pair: Pair, min_stripe: int) -> None:
    if pair.stripe.found.sum() < min_stripe:
        raise PairRejected(f"no laser stripe found in {pair.on_name}: only "
                      f"{int(pair.stripe.found.sum())} scan lines have one "
                      f"({_counts_text(pair.stripe.counts())})")


def restripe(pair: Pair, offset: float, normalize: bool, stripe_options: dict[str, Any],
              min_stripe: int) -> Pair:
    """The pair's stripe extracted again with the albedo offset ``offset``; raises PairRejected."""
    try:
        stripe = _stripe_and_background(
            pair.on, pair.off, normalize,
            dict(stripe_options, albedo_offset=offset, direction=pair.stripe.direction))[0]
    except ValueError as e:
        raise PairRejected(f"no laser stripe found in {pair.on_name}: {e}") from None
    pair = replace(pair, stripe=stripe)
    check_stripe(pair, min_stripe)
    return pair


def _stripe_and_background(on_g: np.ndarray, off_g: np.ndarray | None, normalize: bool,
                           stripe_options: dict[str, Any], background: bool = True
                           ) -> tuple[StripeResult, np.ndarray | None, float | None]:
    """The stripe of a pair, its laser-off frame (estimated when None: see
    :func:`stripe_from_pair`) and the albedo offset fitted to a given laser-off frame (NaN
    when the stripe does not lie on two clearly different levels and 0 was used; None when
    none was fitted: given, no normalisation, or no laser-off frame)."""
    core = frames_options(normalize=normalize, **stripe_options)
    if off_g is None:  # the background estimated only when asked for (``background``)
        return alone_stripe(on_g, core, stripe_options, background)
    stripe, _, fitted = frames_stripe(on_g, off_g, core)
    return stripe, off_g, fitted


def stripe_from_pair(on: np.ndarray, off: np.ndarray | None, *, normalize: bool = True,
                     channel: int | None = None, assess: bool = True,
                     **stripe_options: Any) -> StripeResult:
    """The stripe of one laser on/off pair, as the session pipeline extracts it.

    Difference image (paper Eq. 23; divided by the laser-off frame with ``normalize``, which
    removes most of the pull of the board's edges on the stripe: by ``off + a``, the laser's
    return being an affine function of the laser-off level whose offset ``a`` is fitted to
    the stripe by :func:`~hmlvs.image.stripe.albedo_offset`, or given as ``albedo_offset``;
    0 divides by the laser-off frame itself) and :func:`extract_stripe`
    with ``stripe_options``; for a normalised image without a given threshold, a noise-aware
    one, the peaks found on the image smoothed along the stripe (``detect_sigma_along``,
    default :data:`DETECT_ALONG`); without a given ``method``, Steger's at ``steger_sigma``
    = half the stripe's median FWHM (at least 3 px), robust to laser speckle, and along
    the stripe ``smooth_along`` (default 1; calibration sessions use
    :data:`BOARD_SMOOTH_ALONG`) times that, then refined
    by :func:`~hmlvs.image.stripe.refine_centres` (noise-weighted symmetric centres, on the
    unrounded difference with a denoised laser-off frame; ``method`` "weighted"). With
    ``assess`` the centres are checked by :func:`assess_stripe` (saturation of the laser-on
    frame, clipping, double peaks, and albedo steps of the laser-off frame under the profile
    by more than ``albedo_step``, default 1.5 without ``normalize`` and no check with it).
    ``blur_var`` (px^2, default 0: none): the variance of the camera's blur (optics and the
    pixel's area, about 0.33 for a 0.5 px blur). Dividing by the laser-off frame does not
    undo an albedo step under a blurred profile (the blur of a product is not the product
    of the blurs); to first order in the blur's variance s2 the normalised profile P is
    P_true + s2 grad(P) . grad(log albedo), which is subtracted before the centre fit.
    Measured on noise-free independent renders (0.5 px blur): column error 0.017 -> 0.011
    px RMS, each view's mean error 0.0041 -> 0.0023 px. Calibration sessions fit it
    (:func:`session_blur_var`).
    ``off``
    None: a laser-on image alone, its background estimated (:func:`estimate_background` at
    the stripe's median FWHM, first measured on a sample of at most 160 columns against an
    opening at a stripe width of 16 px, which also sets Steger's scale), the peaks taken
    when 1.5 x brighter than any other (``dominance``, unless given) and centres that jump
    from their neighbours' dropped (MULTIPLE; before the refinement, and again after it);
    with automatic options, on the laser feature instead where that finds twice the scan
    lines (a dim stripe on a bright, fine board: :func:`alone_way`).
    Without a ``direction`` (or with "auto") the frame's own is taken
    (:func:`either_way`): "columns" for a stripe that runs across the image, "rows" for one
    that runs down it.
    Colour frames use ``channel``, by default the laser's (:func:`laser_channel`); a colour
    laser-on frame alone without a channel goes to :func:`~hmlvs.image.colour.colour_stripe`.

    The whole pipeline runs in C++ (``hmlvs._core``, cpp/hmlvs/image/frames.h), one call
    per frame that releases the GIL, computing the normalised difference, its smoothing and
    the denoised laser-off frame only around the stripe and wherever a pixel could clear a
    threshold; tests/oracles/reference_frames.py holds the NumPy composition of the whole-image
    steps it reproduces (tests/parity/test_frames.py compares them).

    Raises ``ValueError`` naming the threshold when an automatic one leaves no pixel of the
    image above it (nothing to find, rather than a silent empty stripe).
    """
    def extract(options: dict[str, Any]) -> tuple[StripeResult, Any, Any]:
        if off is None and channel is None and is_colour(on):
            return colour_stripe(on, None, **options), None, None
        ch = laser_channel(on, off, options["direction"]) if channel is None else channel
        on_g = as_gray(on, "the laser-on image", ch)
        off_g = None if off is None else as_gray(off, "the laser-off image", ch)
        return _stripe_and_background(on_g, off_g, normalize, dict(options, assess=assess),
                                      background=False)

    return either_way(extract, stripe_options, on, off)[0]


#: Steger's default smoothing along the stripe, as a multiple of its scale across it, in
#: calibration sessions (:func:`dataset_from_images`), where the stripe lies on the board's
#: plane. Measured on 9 sessions of an independent renderer (16 views each, 10 % laser
#: speckle): centre error 0.059-0.069 px RMS (at most 0.26-0.36 px) at 1, 0.044-0.052 px
#: (at most 0.16-0.25 px) at 2; each view's mean error, which the calibration feels, is
#: unchanged.
BOARD_SMOOTH_ALONG = 2.0

#: The smoothing along the stripe (px) of the image a normalised stripe's peaks are found
#: on (``detect_sigma_along`` of :func:`~hmlvs.image.stripe.extract_stripe`): 2.7x less
#: noise, at most 4 px of a jump's ends blurred together (the C++ pipeline's default).
DETECT_ALONG = float(_core._FrameStripeOptions.detect_along)


#: the blur variance (px^2) at which a pair's centre shift per unit variance is measured
_EDGE_REF = 0.5


def edge_shift(pair: Pair, normalize: bool, stripe_options: dict[str, Any]) -> np.ndarray:
    """Per scan line, how far the pair's stripe centre moves per px^2 of assumed blur
    variance (the correction at albedo steps, :func:`stripe_from_pair` ``blur_var``): the
    centres extracted again at a reference variance, against the pair's. 0 where either
    has no centre, and everywhere without a laser-off frame or normalisation (no
    correction is made there). ``stripe_options`` must be those the pair's stripe was
    extracted with."""
    k = np.zeros(pair.stripe.centre.shape)
    if not normalize or pair.off_name == ESTIMATED_OFF or pair.on is None:
        return k
    base = checked_blur_var(stripe_options.get("blur_var"))
    ref = _stripe_and_background(pair.on, pair.off, normalize,
                                 dict(stripe_options, blur_var=base + _EDGE_REF,
                                      direction=pair.stripe.direction))[0]
    ok = _centred(pair.stripe) & _centred(ref)
    k[ok] = (ref.centre[ok] - pair.stripe.centre[ok]) / _EDGE_REF
    return k


def _detrend(values: np.ndarray, ok: np.ndarray, scale: float = 15.0) -> np.ndarray:
    """``values`` minus their Gaussian-weighted local mean over the ``ok`` scan lines
    (``scale`` scan lines): what changes faster than a smooth stripe."""
    from scipy.ndimage import gaussian_filter1d

    w = ok.astype(float)
    x = np.where(ok, values, 0.0)
    mean = gaussian_filter1d(x, scale, mode="nearest") / np.maximum(
        gaussian_filter1d(w, scale, mode="nearest"), 1e-12)
    return np.where(ok, values - mean, 0.0)


def session_blur_var(stripes: list[tuple[StripeResult, np.ndarray]]) -> float:
    """The camera's blur variance (px^2) that best removes the bumps albedo steps leave on
    a session's stripes: each (stripe, :func:`edge_shift`) pair's centres, less their
    local mean along the stripe (a smooth curve on the board), regressed on the shift's,
    pooled over the session; clipped to [0, MAX_BLUR_VAR]. 0 when no stripe crosses a
    step. Measured on independent renders with 0.5 px of optical blur (0.33 px^2 with the
    pixel's area): 0.25-0.44; with 1 px (1.08 px^2): 1.12-1.30."""
    num = den = 0.0
    for stripe, k in stripes:
        ok = _centred(stripe) & np.isfinite(k)
        if ok.sum() < 20:
            continue
        r = _detrend(stripe.centre, ok)
        kd = _detrend(k, ok)
        num -= float(np.sum(r * kd))
        den += float(np.sum(kd * kd))
    if not den > 0:
        return 0.0
    return float(np.clip(num / den, 0.0, MAX_BLUR_VAR))


def with_blur_var(stripe: StripeResult, k: np.ndarray, var: float) -> StripeResult:
    """The stripe's centres moved by ``var`` px^2 of blur variance along their shifts ``k``
    (first order; exact at the reference variance)."""
    if var == 0.0 or not np.any(k):
        return stripe
    return replace(stripe, centre=np.where(_centred(stripe), stripe.centre + var * k,
                                           stripe.centre))


def _centred(stripe: StripeResult) -> np.ndarray:
    """The scan lines with a measured centre on the board: found, or flagged ALBEDO_EDGE
    (a centre at a square's edge, corrected like the others but left out of the
    calibration points; the blur fit needs exactly those lines)."""
    return (stripe.found | (stripe.status == StripeStatus.ALBEDO_EDGE)) & \
        np.isfinite(stripe.centre)


def manifest_robot(doc: dict[str, Any], robot: Any, source: Any) -> Any:
    """The arm of a manifest: ``robot`` when given; else the manifest's ``robot:``, a built-in
    arm's name or a mapping in the :meth:`hmlvs.Robot.to_dict` form; else None (the default,
    SCORBOT ER-VII)."""
    from ..data.robot_file import robot_from_description

    if robot is not None or doc.get("robot") is None:
        return robot
    return robot_from_description(doc["robot"], str(source))


def require_poses(records: list[Any], why: str) -> None:
    """Refuse a bench session (records without a robot pose) where poses are needed."""
    if any(isinstance(r, dict) and "pose" not in r and "joints" not in r for r in records):
        raise ValueError(f"the session has no robot poses (a bench session): {why}")


def record_pose(rec: dict[str, Any], robot: Any, unit: str
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(joints in rad or None, base_from_hand pose in mm) of a record, (None, None) for a
    bench session's record (neither ``pose`` nor ``joints``); raises PairRejected.

    A ``pose`` is a 4x4 matrix (mm) or a mapping ``{position, quaternion | rotation_vector}``
    (see :func:`hmlvs.data.poses.pose_from_entry`; records from a manifest come with their
    ``pose_format`` applied, as 4x4 in mm).
    """
    if "pose" in rec:
        from ..data.poses import PoseFormat, pose_from_entry

        try:
            return None, pose_from_entry(rec["pose"], PoseFormat())
        except ValueError as e:
            raise PairRejected(str(e)) from None
    if "joints" not in rec:
        return None, None  # a bench session's record: no robot pose
    joints = np.asarray(rec["joints"], dtype=float).reshape(-1)
    if joints.shape != (robot.dof,) or not np.all(np.isfinite(joints)):
        raise PairRejected(f"joint readings must be {robot.dof} finite numbers, got "
                      f"{np.asarray(rec['joints']).tolist()}")
    if unit == "deg":
        joints = np.radians(joints)
    return joints, robot.poses(joints[None])[0]


def _counts_text(counts: dict[str, int]) -> str:
    return ", ".join(f"{k.lower()} {v}" for k, v in counts.items() if v)


def core_options(stripe_options: dict[str, Any]) -> dict[str, Any]:
    """The options of :func:`extract_stripe` among the pipeline's stripe options."""
    return {k: v for k, v in stripe_options.items()
            if k not in ("albedo_step", "albedo_offset", "smooth_along", "blur_var")}
