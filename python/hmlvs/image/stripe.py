"""The image pipeline: laser on/off images -> stripe centres, board corners, calibration points.

The pixel work (difference image, sub-pixel stripe centres) runs in C++ (``hmlvs._core``) on
the numpy buffers in place; corners come from OpenCV's ``findChessboardCornersSB``. Pixels
are (u = column, v = row), 0-based, pixel centres at integers.

Typical use::

    d = hmlvs.difference_image(on, off)             # paper Eq. 23
    stripe = hmlvs.extract_stripe(d)                 # one centre per image column
    corners = hmlvs.image.corners.find_corners(off, board, expected=predicted_corner_pixels)
    pts = hmlvs.image.points.calibration_points(stripe, corners, board, mode="corners")
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import enum
from numbers import Integral, Real
from typing import Any, Literal

import numpy as np

from .. import _core

Direction = Literal["columns", "rows"]
Method = Literal["centroid", "gaussian", "steger"]


class StripeStatus(enum.IntEnum):
    """Outcome of one scan line (image column or row) of :func:`extract_stripe`."""

    FOUND = 0       #: one stripe peak, centre measured
    NONE = 1        #: nothing above the threshold
    MULTIPLE = 2    #: two or more plausible peaks (reflections): no centre is guessed
    TOO_NARROW = 3  #: only peaks narrower than ``min_width`` (noise, hot pixels)
    TOO_WIDE = 4    #: only peaks wider than ``max_width`` (glare, blobs)
    FIT_FAILED = 5  #: a peak the method could not fit (saturated flat top; Steger: at the edge)
    # Set by :func:`assess_stripe` (the session pipeline's :func:`stripe_from_pair` runs it)
    # on scan lines that had a centre; ``centre`` keeps it, ``found`` no longer counts it.
    SATURATED = 6    #: the laser-on image is saturated under the peak
    CLIPPED = 7      #: the profile (centre +- one FWHM) runs off the image border
    DOUBLE_PEAK = 8  #: the peak has two humps (a reflection or split line next to it)
    ALBEDO_EDGE = 9  #: the laser-off image (the albedo) steps under the profile
    # Set by the session pipeline (:func:`hmlvs.image.views.views_from_images`) on found
    # centres that lie off the view's one stripe line (a reflection or glint beyond it).
    OFF_LINE = 10    #: a centre off the view's stripe line, left out of the calibration


# ------------------------------------------------------------------------------------------
# Input checks


def as_gray(image: Any, name: str, channel: int | None) -> np.ndarray:
    """A 2D uint8/uint16 view of ``image``; colour is converted (or one channel taken)."""
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array (an image), got {type(image).__name__}")
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{name} must be an 8- or 16-bit image (uint8 or uint16), got dtype "
                         f"{image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3:
        nch = image.shape[2]
        if nch not in (3, 4):
            raise ValueError(f"{name} has {nch} channels; expected 1 (gray), 3 (BGR) or 4 (BGRA)")
        if channel is not None:
            if not 0 <= channel < nch:
                raise ValueError(f"channel must be in 0..{nch - 1} for {name} with {nch} "
                                 f"channels, got {channel}")
            return image[:, :, channel]  # a strided view; the core reads it in place
        import cv2
        code = cv2.COLOR_BGR2GRAY if nch == 3 else cv2.COLOR_BGRA2GRAY
        return cv2.cvtColor(np.ascontiguousarray(image), code)
    if image.ndim != 2:
        raise ValueError(f"{name} must be a 2D grayscale or 3D colour array, got shape "
                         f"{image.shape}")
    if channel is not None:
        raise ValueError(f"channel={channel} was given but {name} is grayscale")
    if image.size == 0:
        raise ValueError(f"{name} is empty (shape {image.shape})")
    return image


def difference_image(on: np.ndarray, off: np.ndarray, channel: int | None = None,
                     normalize: bool = False, scale: float | None = None,
                     floor: float | None = None, offset: float = 0.0) -> np.ndarray:
    """Laser-on minus laser-off, clipped at zero (paper Eq. 23), optionally albedo-normalised.

    Parameters
    ----------
    on, off : 8- or 16-bit images of the same size and depth, grayscale (rows x cols) or
        colour (rows x cols x 3 BGR / 4 BGRA as OpenCV reads them).
    channel : for colour images, the channel to use (e.g. 2 for the red channel of a red
        laser in BGR); None converts colour to gray.
    normalize, scale, floor : divide by the laser-off frame: ``(on - off) * scale /
        max(off + offset, floor)``; ``scale`` defaults to the mean of ``off + offset``,
        ``floor`` to 0.1 x the mean of ``off`` (at least 1).
    offset : the laser's return taken as proportional to ``off + offset`` rather than to
        ``off`` (see :func:`albedo_offset`); ``inf``: not normalised.

    Returns
    -------
    (rows, cols) array of the input's dtype: ``on - off`` where ``on > off``, else 0.
    """
    a = as_gray(on, "the laser-on image", channel)
    b = as_gray(off, "the laser-off image", channel)
    if a.shape != b.shape:
        raise ValueError(f"the laser-on image is {a.shape[1]} x {a.shape[0]} pixels but the "
                         f"laser-off image is {b.shape[1]} x {b.shape[0]}")
    offset = real_number(offset, "offset")
    if np.isnan(offset):
        raise ValueError("offset must be a number or inf, got nan")
    if normalize and np.isinf(offset):
        return _core._difference_image(a, b, False, -1.0, -1.0)
    # offset != 0: in C++, per pixel in double precision, rounded half to even: the value of
    # np.clip(np.rint((on - off)^+ * s / np.maximum(off + offset, floor)), 0, max)
    return _core._difference_image(a, b, bool(normalize),
                                   -1.0 if scale is None else _positive(scale, "scale"),
                                   -1.0 if floor is None else _positive(floor, "floor"),
                                   offset if normalize else 0.0)


def albedo_offset(on: np.ndarray, off: np.ndarray, direction: Direction = "columns") -> float:
    """How the laser's return follows the laser-off frame: the offset a (grey levels) for
    which the stripe's peak is proportional to ``off + a`` (0: to the laser-off frame itself,
    what plain normalisation assumes; ``inf``: the return does not follow it).

    A board's print reflects the laser in other proportions than the ambient light (toner
    that is black to the eye returns a red or infrared laser far better): dividing by the
    laser-off frame then makes the stripe several times brighter on the dark squares than on
    the light ones, an automatic threshold loses it on the light ones, and where the stripe
    crosses an edge its profile stays skewed. With two surfaces (a checkerboard's print and
    paper) the return is an affine function of the laser-off level, fitted here: the median
    peak of the difference image (averaged over 5 px along the stripe) and the median
    laser-off level under it, on the scan lines whose peak lies on a dark and on a light
    surface (each away from edges, unsaturated, well above the noise). Returns 0 when the
    stripe does not cross two clearly different levels (fewer than 10 scan lines on either).
    Computed in C++ (the fit :func:`stripe_from_pair` makes).
    """
    if direction not in _DIRECTIONS:
        raise ValueError(f"direction must be 'columns' or 'rows', got {direction!r}")
    a = as_gray(on, "the laser-on image", None)
    b = as_gray(off, "the laser-off image", None)
    if a.shape != b.shape:
        raise ValueError(f"the laser-on image is {a.shape[1]} x {a.shape[0]} pixels but the "
                         f"laser-off image is {b.shape[1]} x {b.shape[0]}")
    offset = float(_core._fit_albedo_offset(a, b, _DIRECTIONS[direction])[0])
    return 0.0 if np.isnan(offset) else offset


# ------------------------------------------------------------------------------------------
# Stripe centres


@dataclass(frozen=True)
class StripeResult:
    """Sub-pixel stripe centres, one entry per scan line.

    For ``direction="columns"`` (a roughly horizontal stripe) the scan lines are image
    columns: ``position`` is the column u and ``centre`` the sub-pixel row v. For
    ``direction="rows"`` they are image rows: ``position`` is v and ``centre`` is u.

    Attributes
    ----------
    position : (n,) scan line index (u for columns, v for rows)
    centre : (n,) sub-pixel centre across the scan line (px), NaN unless found
    intensity : (n,) peak pixel value of the chosen (or strongest) peak, NaN if none
    width : (n,) full width at half maximum of that peak (px), NaN if none
    sigma : (n,) 1-sigma uncertainty of ``centre`` from pixel noise alone (px), NaN unless
        found. It does not include biases (blur, albedo edges, model error).
    status : (n,) :class:`StripeStatus` codes (uint8)
    num_peaks : (n,) number of peaks of plausible or too large width on the scan line
    direction, method : the options used
    threshold, noise : intensity threshold and per-pixel noise level used
    residual : (n,) asymmetry of the profile about its centre (RMS over the FWHM of the
        difference of mirrored samples, relative to the peak; 0 for a symmetric profile),
        NaN where no centre was measured. A calibration may weight or drop columns by it.
    """

    position: np.ndarray
    centre: np.ndarray
    intensity: np.ndarray
    width: np.ndarray
    sigma: np.ndarray
    status: np.ndarray
    num_peaks: np.ndarray
    direction: str
    method: str
    threshold: float
    noise: float
    residual: np.ndarray | None = None

    @property
    def found(self) -> np.ndarray:
        """(n,) bool: scan lines with a measured centre."""
        return self.status == StripeStatus.FOUND

    @property
    def pixels(self) -> np.ndarray:
        """(k, 2) pixels (u, v) of the found centres."""
        return self.pixels_of(self.found)

    def pixels_of(self, lines: np.ndarray) -> np.ndarray:
        """(k, 2) pixels (u, v) of the centres of the scan lines ``lines`` (a mask)."""
        pos = np.asarray(self.position)[lines].astype(float)
        centre = np.asarray(self.centre)[lines]
        if self.direction == "columns":
            return np.stack([pos, centre], axis=1)
        return np.stack([centre, pos], axis=1)

    def counts(self) -> dict[str, int]:
        """Number of scan lines per status, by name (``{"FOUND": 612, "NONE": 28, ...}``)."""
        return {s.name: int(np.count_nonzero(self.status == s)) for s in StripeStatus}


_DIRECTIONS = {"columns": _core._StripeDirection.columns, "rows": _core._StripeDirection.rows}
_METHODS = {"centroid": _core._StripeMethod.centroid, "gaussian": _core._StripeMethod.gaussian,
            "steger": _core._StripeMethod.steger}


@dataclass(frozen=True)
class StripeOptions:
    """Options of :func:`extract_stripe` (see there), checked on construction: a wrong type
    or a non-finite value gives a ``ValueError`` naming the option. Range checks that
    relate options (``min_width < max_width``, ``steger_sigma``, ``dominance``) are the
    C++ core's, with its sentences."""

    direction: Direction = "columns"
    method: Method = "centroid"
    threshold: float | None = None
    min_width: float = 2.0
    max_width: float = 40.0
    noise: float | None = None
    steger_sigma: float = 1.5
    dominance: float = 0.0
    channel: int | None = None
    steger_sigma_along: float | None = None
    detect_sigma_along: float = 0.0

    def __post_init__(self) -> None:
        if self.direction not in _DIRECTIONS:
            raise ValueError(f"direction must be 'columns' or 'rows', got {self.direction!r}")
        if self.method not in _METHODS:
            raise ValueError("method must be 'centroid', 'gaussian' or 'steger', got "
                             f"{self.method!r}")
        for name in ("threshold", "noise", "steger_sigma_along"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, _nonneg(v, name))
        for name in ("min_width", "max_width", "steger_sigma", "dominance",
                     "detect_sigma_along"):
            object.__setattr__(self, name, finite_number(getattr(self, name), name))
        c = self.channel
        if c is not None and (isinstance(c, bool) or not isinstance(c, Integral) or c < 0):
            raise ValueError(f"stripe.channel must be None or an integer >= 0, got {c!r}")

    def to_core(self) -> Any:
        """The C++ option struct (the one place it is built)."""
        o = _core._StripeOptions()
        o.direction = _DIRECTIONS[self.direction]
        o.method = _METHODS[self.method]
        o.threshold = -1.0 if self.threshold is None else self.threshold
        o.noise = -1.0 if self.noise is None else self.noise
        o.min_width, o.max_width = self.min_width, self.max_width
        o.steger_sigma, o.dominance = self.steger_sigma, self.dominance
        o.steger_sigma_along = 0.0 if self.steger_sigma_along is None else self.steger_sigma_along
        o.detect_sigma_along = self.detect_sigma_along
        return o


def extract_stripe(image: np.ndarray, direction: Direction = "columns",
                   method: Method = "centroid", threshold: float | None = None,
                   min_width: float = 2.0, max_width: float = 40.0,
                   noise: float | None = None, steger_sigma: float = 1.5,
                   dominance: float = 0.0, channel: int | None = None,
                   steger_sigma_along: float | None = None,
                   detect_sigma_along: float = 0.0,
                   options: StripeOptions | None = None) -> StripeResult:
    """Sub-pixel laser stripe centres, one per image column (or row), computed in C++.

    Parameters
    ----------
    image : difference image (see :func:`difference_image`), 8- or 16-bit, grayscale or
        colour (converted, or ``channel`` taken). It is read in place, without a copy.
    direction : "columns" for a roughly horizontal stripe (one row coordinate per column),
        "rows" for a roughly vertical one (one column coordinate per row).
    method : "centroid" (gray centroid of ``I - threshold`` over the run of pixels above the
        threshold), "gaussian" (three-point Gaussian fit through the peak pixel) or "steger"
        (Hessian line detector at scale ``steger_sigma``; for curved or steep stripes).
        Its kernel along the stripe is cut short symmetrically near the image's edges, so
        that a slanted stripe is not bent by a replicated border.
    threshold : a pixel belongs to a peak when its value exceeds this. Default: automatic,
        ``max(5 * noise, 0.15 * image maximum)``.
    min_width, max_width : accepted full width at half maximum of a peak (px). Narrower
        peaks are noise and ignored; wider ones (glare) compete with the stripe. The default
        40 px admits the 20-30 px wide stripes of defocused high-resolution cameras.
    noise : per-pixel noise standard deviation (intensity units) for ``sigma``. Default:
        estimated from the image's background as a zero-clipped difference of two noisy
        frames, plus the quantisation noise of two rounded frames.
    dominance : 0 (default) reports a scan line with two plausible peaks as MULTIPLE. A
        ratio d >= 1 instead accepts the strongest peak if it is d times brighter than any
        other.
    steger_sigma_along : Steger's smoothing scale along the stripe (px), default
        ``steger_sigma``. A straight stripe stays unbiased at any scale; a larger one
        averages more laser speckle but blurs where the stripe bends or jumps.
    detect_sigma_along : find and size the peaks (``threshold``, ``min_width``,
        ``max_width``, ``dominance``, ``intensity``, ``width``) on the image smoothed along
        the stripe at this scale (px; 0, the default: on the image itself), where the
        noise is lower by the kernel's gain (:func:`smoothing_noise_gain`) and a faint
        stripe on a noisy image clears the threshold; the centres are still measured on
        the image. The automatic threshold then uses the smoothed noise and maximum.
    options : a :class:`StripeOptions` holding all of the above instead (then the keyword
        options are ignored)

    Returns
    -------
    StripeResult
    """
    if options is None:
        options = StripeOptions(direction=direction, method=method, threshold=threshold,
                                min_width=min_width, max_width=max_width, noise=noise,
                                steger_sigma=steger_sigma, dominance=dominance,
                                channel=channel, steger_sigma_along=steger_sigma_along,
                                detect_sigma_along=detect_sigma_along)
    elif not isinstance(options, StripeOptions):
        raise ValueError(f"options must be a StripeOptions, got {options!r}")
    direction, method = options.direction, options.method
    img = as_gray(image, "the image", options.channel)
    r = _core._extract_stripe(img, options.to_core())
    n = r.centre.shape[0]
    return StripeResult(
        position=np.arange(n), centre=np.asarray(r.centre), intensity=np.asarray(r.intensity),
        width=np.asarray(r.width), sigma=np.asarray(r.sigma),
        status=np.asarray(r.status, dtype=np.uint8), num_peaks=np.asarray(r.num_peaks),
        direction=direction, method=method, threshold=float(r.threshold), noise=float(r.noise),
        residual=np.asarray(r.residual))


def assess_stripe(stripe: StripeResult, image: np.ndarray, on: np.ndarray | None = None,
                  off: np.ndarray | None = None, *, albedo_step: float = 1.5,
                  albedo_offset: float = 0.0, hump: float = 0.3, dip: float = 0.7
                  ) -> StripeResult:
    """Quality checks of the centres of :func:`extract_stripe` (computed in C++).

    Scan lines that had a centre keep it but change their status when it cannot be trusted:
    ``CLIPPED`` (the profile, centre +- one FWHM, runs off the image), ``DOUBLE_PEAK`` (a
    second hump of at least ``hump`` x the peak behind a dip below ``dip`` x the hump, on the
    profile smoothed at FWHM / 6 against speckle), ``SATURATED`` (the laser-on frame ``on``,
    or ``image`` itself if ``on`` is None, reaches the pixel type's maximum within the centre
    +- FWHM / 2) and ``ALBEDO_EDGE`` (the laser-off frame ``off``, averaged over 3 x 3 pixels
    against its noise and raised by ``albedo_offset``, varies by more than ``albedo_step``
    (max / min) within the centre +- one FWHM: the stripe crosses a square's edge there and
    its reflected profile is skewed; ``albedo_step <= 1``: no check; ``albedo_offset`` >= 0:
    the laser's albedo taken as the laser-off level plus it, as the albedo normalisation of
    :func:`difference_image` ``offset`` does).

    Parameters
    ----------
    stripe : the result of :func:`extract_stripe` on ``image``
    image : the (grayscale) image the stripe was extracted from
    on, off : the laser-on and laser-off frames (grayscale, ``image``'s size and depth), or
        None

    Returns
    -------
    StripeResult : ``stripe`` with the new statuses
    """
    if not isinstance(stripe, StripeResult):
        raise ValueError(f"stripe must be a StripeResult, got {type(stripe).__name__}")
    img = as_gray(image, "the image", None)
    frames = [None if x is None else as_gray(x, name, None)
              for x, name in ((on, "the laser-on image"), (off, "the laser-off image"))]
    o = _core._StripeQualityOptions()
    o.albedo_step = finite_number(albedo_step, "albedo_step")
    o.albedo_offset = finite_number(albedo_offset, "albedo_offset")
    if o.albedo_offset < 0:
        raise ValueError(f"albedo_offset must be >= 0, got {albedo_offset!r}")
    o.hump, o.dip = finite_number(hump, "hump"), finite_number(dip, "dip")
    status = _core._assess_stripe(img, frames[0], frames[1], _DIRECTIONS[stripe.direction], o,
                                  np.asarray(stripe.centre, float), np.asarray(stripe.width, float),
                                  np.asarray(stripe.status, np.uint8), float(stripe.threshold))
    return replace(stripe, status=np.asarray(status, dtype=np.uint8))


#: :func:`refine_centres`' default speckle: the profile's noise that grows with it, as a
#: fraction of the intensity, set against the additive noise of one pixel. Measured on 9
#: sessions of an independent renderer (10 % laser speckle, 1 grey level of noise): the
#: per-view mean error, which the calibration feels, is about as small from 0.05 to 0.1
#: (0.0099 and 0.0095 px RMS over 144 views, against 0.0113 px for Steger's centre) and
#: grows again at 0.3 (flanks weighed so much that their asymmetries show).
SPECKLE = 0.1


def refine_centres(stripe: StripeResult, image: np.ndarray, noise: Any, *,
                   speckle: float = SPECKLE, noise_floor: float = 0.02,
                   sigma_along: float = 0.0) -> StripeResult:
    """Noise-weighted symmetric centres of the stripe's found scan lines (computed in C++).

    The centre c of a scan line is the root of ``sum_p w(p - c) I(p)``, with the odd weight
    ``w(x) = P'(x) / (n^2 + (speckle P(x))^2)``, ``P`` a Gaussian of the scan line's FWHM
    and peak and ``n`` its additive noise: exact for any profile symmetric about its centre
    (whatever its shape) but for the sampling at whole pixels (measured: at most 0.0024 px on
    a profile with a 1 px sigma core, periodic in the centre's sub-pixel position), and the
    best linear shift estimate under additive noise plus
    laser speckle, which weighs the flanks more than the speckled top. Measured on an
    independent renderer's sessions (tests/oracles/independent_check.py), each view's mean error
    drops from 0.0113 to 0.0095 px RMS against Steger's centre, which it starts from.

    Parameters
    ----------
    stripe : the result of :func:`extract_stripe` on (an integer version of) ``image``
    image : (rows, cols) the stripe's image as floats, e.g. the albedo-normalised difference
        without rounding
    noise : the additive noise (standard deviation of one pixel of ``image``, before any
        smoothing), one number or one per scan line; NaN: the scan line keeps its centre
    speckle : the profile's relative noise (see :data:`SPECKLE`); 0: additive noise only
    noise_floor : the additive noise is taken as at least this fraction of the peak, so that
        on a nearly noise-free image the far tails do not take over the weights
    sigma_along : first smooth ``image`` along the stripe with a Gaussian of this scale (px;
        0: not), as Steger's ``steger_sigma_along``; the scan lines within 3 x ``sigma_along``
        of the image's ends, where the kernel would reach past them, keep their centre

    Returns
    -------
    StripeResult : ``stripe`` with ``method="weighted"``, the refined centres and their
    ``sigma`` (from the noise model; white noise reduced by the smoothing along); a found
    scan line whose root is not found, or lies more than half a profile sigma from its
    centre, becomes ``FIT_FAILED``. Scan lines whose window (centre +- 4 profile sigmas)
    leaves the image keep their centre.
    """
    import cv2

    if not isinstance(stripe, StripeResult):
        raise ValueError(f"stripe must be a StripeResult, got {type(stripe).__name__}")
    img = np.asarray(image)
    if img.ndim != 2 or not np.issubdtype(img.dtype, np.number):
        raise ValueError(f"image must be a 2D numeric array, got shape {img.shape} of "
                         f"{img.dtype}")
    img = np.ascontiguousarray(img, dtype=np.float32)
    if not np.isfinite(img).all():
        raise ValueError("image holds NaN or infinite values")
    n_scan = img.shape[1] if stripe.direction == "columns" else img.shape[0]
    if stripe.centre.shape[0] != n_scan:
        raise ValueError(f"the stripe has {stripe.centre.shape[0]} scan lines but the image "
                         f"{n_scan} ({stripe.direction})")
    nz = np.broadcast_to(np.asarray(noise, dtype=float), (n_scan,)).copy()
    sigma_along = _nonneg(sigma_along, "sigma_along")
    factor = 1.0
    if sigma_along > 0:
        r = int(np.ceil(4 * sigma_along))
        k = cv2.getGaussianKernel(2 * r + 1, sigma_along).astype(np.float32)
        one = np.ones((1, 1), np.float32)
        kx, ky = (k, one) if stripe.direction == "columns" else (one, k)
        img = cv2.sepFilter2D(img, -1, kx, ky, borderType=cv2.BORDER_REFLECT_101)
        edge = int(np.ceil(3 * sigma_along))
        nz[:edge] = np.nan
        nz[max(0, n_scan - edge):] = np.nan
        # white noise through the kernel along: variance / (2 sqrt(pi) sigma_along)
        factor = float(np.sqrt(1.0 / max(1.0, 2.0 * np.sqrt(np.pi) * sigma_along)))
    o = _core._StripeRefineOptions()
    o.speckle = _nonneg(speckle, "speckle")
    o.noise_floor = _nonneg(noise_floor, "noise_floor")
    centre, sig, status = _core._refine_stripe(
        img, _DIRECTIONS[stripe.direction], nz, o, np.asarray(stripe.centre, float),
        np.asarray(stripe.width, float), np.asarray(stripe.sigma, float),
        np.asarray(stripe.status, np.uint8))
    centre, sig = np.asarray(centre), np.asarray(sig)
    done = np.isfinite(nz) & (stripe.status == StripeStatus.FOUND)
    sig = np.where(done, sig * factor, stripe.sigma)
    return replace(stripe, centre=centre, sigma=sig, status=np.asarray(status, np.uint8),
                   method="weighted")


def real_number(x: Any, name: str) -> float:
    if isinstance(x, bool) or not isinstance(x, Real):
        raise ValueError(f"stripe.{name} must be a number, got {x!r}")
    return float(x)


def finite_number(x: Any, name: str) -> float:
    v = real_number(x, name)
    if not np.isfinite(v):
        raise ValueError(f"stripe.{name} must be a finite number, got {x!r}")
    return v


def _positive(x: Any, name: str) -> float:
    x = float(x)
    if not (np.isfinite(x) and x > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {x}")
    return x


def _nonneg(x: Any, name: str) -> float:
    v = real_number(x, name)
    if not (np.isfinite(v) and v >= 0):
        raise ValueError(f"stripe.{name} must be a finite number >= 0, got {x!r}")
    return v


def smoothing_noise_gain(sigma: float) -> float:
    """The factor by which :func:`extract_stripe`'s ``detect_sigma_along`` smoothing at
    ``sigma`` (px, in [0.5, 40]) lowers independent per-pixel noise: sqrt(sum g^2) of its
    sampled Gaussian (about 1 / sqrt(2 sqrt(pi) sigma); 0.376 at 2 px)."""
    return float(_core._smoothing_noise_gain(finite_number(sigma, "sigma")))


def normalized_threshold(on: np.ndarray, off: np.ndarray, d: np.ndarray,
                          offset: float = 0.0, sigma: float | None = None,
                          along: float | tuple[float, ...] = 0.0) -> Any:
    """Automatic threshold for an albedo-normalised difference image.

    Normalising multiplies the noise by the gain mean(off) / max(off, floor), which is
    largest on dark surfaces (black squares): the global 5-sigma rule of
    :func:`extract_stripe` would let noise peaks through there. Use 5 x the plain
    difference's noise x the 95th percentile of the gain instead (and at least 0.15 x the
    image maximum, as for the plain image). ``sigma``: the plain difference's noise when
    known (``_estimate_difference_noise`` of it), else estimated here. ``along``: the
    ``detect_sigma_along`` the stripe is found with (px; 0: none), whose smoothing lowers
    the noise term by :func:`smoothing_noise_gain`; a tuple of them gives a tuple of
    thresholds.
    """
    if sigma is None:
        raw = _core._difference_image(on, off, False, -1.0, -1.0)
        sigma = float(_core._estimate_difference_noise(raw))
    mean = float(off.mean())
    gain = (mean + offset) / np.maximum(off[::4, ::4].astype(float) + offset,
                                        max(1.0, 0.1 * mean))
    noise = 5.0 * sigma * float(np.percentile(gain, 95))
    top = 0.15 * float(d[::4].max())
    out = tuple(max(noise * (smoothing_noise_gain(a) if a > 0.0 else 1.0), top)
                for a in (along if isinstance(along, tuple) else (along,)))
    return out if isinstance(along, tuple) else out[0]
