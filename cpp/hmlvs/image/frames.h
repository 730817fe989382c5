// The stripe of one camera frame as the session pipeline extracts it, in one call: a laser-on
// frame with its laser-off frame (or its background estimated from it), the difference image,
// its albedo normalisation by the laser-off frame (with the offset of the laser's return
// fitted to the stripe), the automatic thresholds, the peaks found on the difference smoothed
// along the stripe, Steger's centres at a scale fitted to the stripe, their noise-weighted
// refinement on the unrounded difference with a denoised laser-off frame, and the quality
// checks. The reference is the composition of the whole-image steps (DifferenceImage,
// ExtractStripe, RefineStripeCentres, AssessStripe and the NumPy glue of
// hmlvs.image.session.stripe_from_pair, kept in tests/oracles/reference_frames.py); here only the
// statistics the thresholds need look at every pixel, in 8- or 16-bit integers, and every
// other value (the normalised difference, its smoothing, the denoised laser-off frame) is
// computed where a scan line reads it: around the stripe and wherever a bound on the pixels
// says a value could clear a threshold.
#pragma once

#include <cstdint>
#include <limits>

#include "hmlvs/image/image.h"

namespace hmlvs {

/// Options of StripeFromFrames, as hmlvs.image.session.stripe_from_pair takes them.
struct FrameStripeOptions {
  /// The extraction's options as given; threshold and noise negative: automatic.
  StripeOptions stripe;
  /// Whether the option was given (else the pipeline's default): without a method, Steger's
  /// centres at half the stripe's median FWHM (at least 3 px), refined by the noise-weighted
  /// symmetric centre (RefineStripeCentres) on the unrounded, denoised difference.
  bool method_given = false;
  bool steger_sigma_given = false;
  bool steger_sigma_along_given = false;
  bool detect_sigma_along_given = false;
  bool dominance_given = false;
  /// Divide the difference by the laser-off frame plus the albedo offset (DifferenceOptions).
  bool normalize = true;
  /// The albedo offset (grey levels); NaN: fitted to the frames (FitAlbedoOffset); inf: the
  /// difference is not normalised.
  double albedo_offset = std::numeric_limits<double>::quiet_NaN();
  /// Run AssessStripe's checks.
  bool assess = true;
  /// StripeQualityOptions::albedo_step; NaN: 0 (no check) when normalised, else 1.5.
  double albedo_step = std::numeric_limits<double>::quiet_NaN();
  /// Variance of the camera's blur (px^2), for the first-order correction of the normalised
  /// difference at albedo steps; 0: none.
  double blur_var = 0.0;
  /// Steger's smoothing along the stripe as a multiple of its scale across, in [1, 10].
  double smooth_along = 1.0;
  /// Measure the found centres' residuals (StripeResult::residual, the profiles' asymmetry);
  /// false leaves them NaN (a caller that does not read them, as measurement).
  bool residual = true;
  /// The defaults of the pipeline (hmlvs.image.session): the smoothing along the stripe of
  /// the image a normalised stripe's peaks are found on when the threshold is automatic
  /// (detect_sigma_along, px: 2.7x less noise, at most 4 px of a jump's ends blurred
  /// together), and for a laser-on frame alone the dominance its peaks need (what the opening
  /// leaves of a board is fainter than the laser), the stripe width of its first opening and
  /// the most columns the stripe's width is first measured on.
  static constexpr double kDetectAlong = 2.0;
  static constexpr double kAloneDominance = 1.5;
  static constexpr double kAloneFirstWidth = 16.0;
  static constexpr int kAloneFirstColumns = 160;
};

/// The outcome of StripeFromFrames.
struct FrameStripe {
  StripeResult stripe;
  /// Whether the albedo offset was fitted, and its value (NaN: the stripe does not lie on two
  /// clearly different levels and 0 was used; inf: its return does not follow the laser-off
  /// frame and the difference was not normalised).
  bool offset_fitted = false;
  double albedo_offset = std::numeric_limits<double>::quiet_NaN();
  /// An automatic threshold at or above every pixel of the difference image (no stripe):
  /// the threshold is stripe.threshold, the image's maximum image_max.
  bool no_pixel = false;
  double image_max = 0.0;
  /// Whether the pipeline's default centres were refined (false when no scan line had a
  /// centre to refine, or a method was given).
  bool refined = false;
};

/// The stripe of a laser-on frame `on` with its laser-off frame `off` (same size), or, when
/// `off` has no data, of `on` alone: its background estimated by EstimateBackground at the
/// stripe's width (the median FWHM of the peaks ExtractStripe finds, centroid centres, on
/// every k-th column of the frame minus its opening at a width of 16 px, k = ceil(cols /
/// 160); 16 px when none is found), the stripe found against it with dominance 1.5 unless
/// given, and scan lines whose centre jumps from its neighbours' marked kMultiple (DropJumps:
/// on Steger's centres before the refinement, and again on the refined ones); Steger's scale,
/// unless given, from the same first width. `background`, if not null, receives the background
/// used (rows x cols, contiguous). With direction kRows (a roughly vertical stripe) the frames
/// are worked on transposed, the opening included. Throws std::invalid_argument for empty or
/// mismatched frames or invalid options.
template <typename T>
FrameStripe StripeFromFrames(const ImageView<T>& on, const ImageView<T>& off,
                             const FrameStripeOptions& options, T* background = nullptr);

/// The laser-on frame without its stripe: every column opened (erosion, then dilation, edges
/// replicated) with a vertical line of max(9, 2 ceil(1.5 width) + 1) pixels, which removes bright
/// structures narrower than that along the column (a roughly horizontal stripe of FWHM `width`)
/// and keeps larger ones (a board's squares). The values of OpenCV's
/// morphologyEx(MORPH_OPEN, ones(k, 1), borderType=BORDER_REPLICATE). Written to `out`
/// (rows x cols, contiguous). Throws std::invalid_argument for an empty frame or a width that
/// is not a finite number.
template <typename T>
void EstimateBackground(const ImageView<T>& on, double width, T* out);

/// How the laser's return follows the laser-off frame (hmlvs.image.stripe.albedo_offset): the
/// offset a for which the stripe's peak is proportional to off + a, fitted to the scan lines
/// (image columns; rows with kRows) whose peak lies on a dark and on a light flat surface. NaN
/// when the stripe does not lie on two clearly different levels, inf when the peaks do not
/// grow with the level. `noise`, if not null, receives the noise of the plain difference
/// (EstimateDifferenceNoise, of the transposed frames for kRows).
template <typename T>
double FitAlbedoOffset(const ImageView<T>& on, const ImageView<T>& off, StripeDirection direction,
                       double* noise = nullptr);

/// Found scan lines whose centre lies more than `jump` px from the running median of the found
/// centres (`window` of them, edges repeated) become kMultiple: without a laser-off frame a
/// leftover of the board can outshine a faint stripe in a few neighbouring scan lines, and the
/// stripe is continuous where those are not.
void DropJumps(StripeResult* stripe, int window = 41, double jump = 1.0);

}  // namespace hmlvs
