// The image pipeline's pixel work: the laser on/off difference image (paper Eq. 23) and
// sub-pixel laser stripe centres.
//
// Images are strided views of 8- or 16-bit grayscale buffers (rows x cols, strides in
// elements), so that a numpy array, an OpenCV Mat or a camera driver's buffer can be read
// without a copy. Pixel (u = column, v = row) is 0-based with pixel centres at integers.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>

namespace hmlvs {

/// A read-only strided 2D view. Element (r, c) is data[r * row_stride + c * col_stride].
template <typename T>
struct ImageView {
  const T* data = nullptr;
  int rows = 0;
  int cols = 0;
  std::ptrdiff_t row_stride = 0;  // in elements
  std::ptrdiff_t col_stride = 1;  // in elements
  const T& operator()(int r, int c) const { return data[r * row_stride + c * col_stride]; }
};

/// Options of the difference image.
struct DifferenceOptions {
  /// Divide by the laser-off image (the surface's albedo under ambient light), so that the
  /// stripe's profile no longer steps where it crosses a black/white edge of the board:
  ///   D = (on - off) * scale / max(off, floor), rounded and clipped to the pixel type.
  /// Without it the centre of a stripe running along a square edge is pulled towards the
  /// white side by a large fraction of a pixel.
  bool normalize = false;
  /// Normalisation gain; negative: the mean of the laser-off image (keeps D's magnitude).
  double scale = -1.0;
  /// Smallest divisor; negative: 0.1 x the mean of the laser-off image (at least 1).
  double floor = -1.0;
  /// With `normalize`, the laser's return taken as proportional to off + offset rather than
  /// to off (a finite number; 0: plain normalisation). A non-zero offset computes, in double
  /// precision per pixel,
  ///   D = rint(clip((on - off)^+ * scale / max(off + offset, floor), 0, max of T))
  /// rounded half to even, with scale defaulting to mean(off) + offset: the same value as
  /// the NumPy expression of hmlvs.difference_image. (offset 0 keeps the faster rule of the
  /// plain normalisation: a gain per laser-off value, in single precision for 8-bit images,
  /// rounded half up.)
  double offset = 0.0;
};

/// D = on - off where on > off, else 0 (paper Eq. 23), optionally albedo-normalised, written
/// to `out` (rows x cols, contiguous row-major). Throws std::invalid_argument if the two
/// views differ in size or the options are invalid.
template <typename T>
void DifferenceImage(const ImageView<T>& on, const ImageView<T>& off, T* out,
                     const DifferenceOptions& options = DifferenceOptions());

/// Per image column c, the row of the largest sum of `image` over the columns
/// c - half_width .. c + half_width (mirrored beyond the image as OpenCV's BORDER_REFLECT_101
/// does) and that sum: the peak of a box filter along the rows (cv2.blur with a kernel of
/// (2 half_width + 1) x 1 gives sum / (2 half_width + 1)) without filtering the whole image.
/// On ties the first (smallest) row. Throws std::invalid_argument for an empty image or a
/// negative half_width.
struct ColumnPeaks {
  Eigen::VectorXi row;  // per column: the row of the largest sum
  Eigen::VectorXd sum;  // per column: that sum (an integer)
};
template <typename T>
ColumnPeaks FindColumnPeaks(const ImageView<T>& image, int half_width);

/// Which way the stripe is scanned: one centre per image column (a roughly horizontal
/// stripe; the centre is a row coordinate v) or one per image row (a roughly vertical stripe;
/// the centre is a column coordinate u).
enum class StripeDirection : int { kColumns = 0, kRows = 1 };

/// How the sub-pixel centre of the chosen peak is computed.
///  - kCentroid: gray centroid of (I - threshold) over the run of pixels above threshold.
///  - kGaussian: three-point Gaussian fit (log-parabola) through the peak pixel and its two
///    neighbours along the scan line (kFitFailed for a saturated peak).
///  - kSteger: Steger's Hessian line detector: Gaussian-smoothed derivatives at the peak
///    pixel, the line normal from the Hessian's most negative eigenvalue, the sub-pixel
///    centre along that normal, intersected with the scan line. Follows curved and slanted
///    stripes without the bias of a 1D profile.
enum class StripeMethod : int { kCentroid = 0, kGaussian = 1, kSteger = 2 };

/// The outcome for one scan line.
enum class StripeStatus : std::uint8_t {
  kFound = 0,      // one stripe peak, centre measured
  kNone = 1,       // no pixel above threshold
  kMultiple = 2,   // two or more plausible peaks (reflections): no centre is guessed
  kTooNarrow = 3,  // only peaks narrower than min_width (noise, hot pixels)
  kTooWide = 4,    // only peaks wider than max_width (glare, out-of-focus blobs)
  kFitFailed = 5,  // a peak was found but the chosen method could not fit it (e.g. a
                   // saturated flat top for the Gaussian fit, a Hessian that is not a line, or
                   // for Steger a scan line within ceil(steger_sigma) of the image's edge)
  // Set only by AssessStripe, on scan lines ExtractStripe found (the centre is kept):
  kSaturated = 6,   // the laser-on image reaches its pixel type's maximum under the peak
  kClipped = 7,     // the profile (centre +- one FWHM) runs off the image border
  kDoublePeak = 8,  // the peak has two humps (a reflection or a split line next to it)
  kAlbedoEdge = 9,  // the laser-off image (the surface's albedo) steps under the profile
};

struct StripeOptions {
  StripeDirection direction = StripeDirection::kColumns;
  StripeMethod method = StripeMethod::kCentroid;
  /// Intensity a pixel must exceed to belong to a peak. Negative: automatic,
  /// max(5 * noise, 0.15 * image maximum) with both taken from every 4th row.
  double threshold = -1.0;
  /// Accepted full width at half maximum of a peak (px, along the scan line).
  double min_width = 2.0;
  double max_width = 40.0;
  /// Standard deviation of the per-pixel noise (intensity units), used for the uncertainty.
  /// Negative: estimated from the image as a zero-clipped difference of two noisy frames
  /// (see EstimateDifferenceNoise).
  double noise = -1.0;
  /// Smoothing scale (px) of Steger's derivatives across the stripe (along the scan line).
  double steger_sigma = 1.5;
  /// Smoothing scale (px) of Steger's derivatives along the stripe (across scan lines); 0:
  /// steger_sigma. A straight stripe stays unbiased at any scale (the kernel is symmetric);
  /// a larger one averages more speckle but blurs where the stripe bends or jumps.
  double steger_sigma_along = 0.0;
  /// 0: a second plausible peak makes the scan line kMultiple. A value d >= 1 accepts the
  /// strongest peak when its intensity is at least d times every other peak's.
  double dominance = 0.0;
  /// Smoothing scale (px) along the stripe (across scan lines) of the image the peaks are
  /// found and sized on; 0: the image itself. Centres are still measured on the image. The
  /// automatic threshold then takes the smoothed noise (noise x the kernel's noise gain)
  /// and the smoothed maximum; a given threshold applies to the smoothed image.
  double detect_sigma_along = 0.0;
};

/// One entry per scan line (image column for kColumns, image row for kRows).
struct StripeResult {
  Eigen::VectorXd centre;     // sub-pixel stripe centre across the scan line (px), NaN if none
  Eigen::VectorXd intensity;  // peak pixel value of the chosen (or strongest) peak, NaN if none
  Eigen::VectorXd width;      // FWHM of that peak along the scan line (px), NaN if none
  Eigen::VectorXd sigma;      // 1-sigma uncertainty of centre from pixel noise (px), NaN if none
  Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1> status;  // StripeStatus per scan line
  Eigen::VectorXi num_peaks;  // peaks of plausible (or too large) width on the scan line
  /// Asymmetry of the found profile about its centre: RMS over the FWHM of the difference
  /// of mirrored samples I(c + x) - I(c - x), relative to the peak (0 for a symmetric
  /// profile; NaN unless found). Large where the profile is skewed (albedo edges, humps).
  Eigen::VectorXd residual;
  double threshold = 0.0;  // the threshold used
  double noise = 0.0;      // the noise level used
};

/// Sub-pixel stripe centres, one per scan line. Throws std::invalid_argument for an empty
/// image or invalid options.
template <typename T>
StripeResult ExtractStripe(const ImageView<T>& image, const StripeOptions& options);

/// Options of AssessStripe.
struct StripeQualityOptions {
  /// A found scan line whose laser-off image, averaged over 3 x 3 pixels (the sensor's
  /// noise on a dark square would pass for a step) and raised by albedo_offset, varies by
  /// more than this factor (max / min) within the centre +- one FWHM is kAlbedoEdge; <= 1
  /// turns the check off.
  double albedo_step = 1.5;
  /// Added to the laser-off level before the ratio (>= 0): the laser's albedo taken as the
  /// level plus this offset, as the albedo normalisation does.
  double albedo_offset = 0.0;
  /// A second hump of at least this fraction of the peak, separated from it by a dip below
  /// dip x the hump, makes the scan line kDoublePeak; 0 turns the check off.
  double hump = 0.3;
  double dip = 0.7;
};

/// Quality checks of ExtractStripe's found scan lines, which keep their centre but change
/// their status: kClipped (the profile runs off the image), kDoublePeak (two humps on the
/// profile of `image`, smoothed at FWHM / 6 against speckle), kSaturated (the laser-on frame
/// `on`, or `image` itself if `on` has no data, reaches the pixel type's maximum within the
/// centre +- FWHM / 2) and kAlbedoEdge (the laser-off frame `off`, if it has data, steps).
/// `image` is the image the stripe was extracted from; `on` and `off`, if given, have its
/// size. Throws std::invalid_argument for mismatched sizes or results.
template <typename T>
void AssessStripe(const ImageView<T>& image, const ImageView<T>& on, const ImageView<T>& off,
                  StripeDirection direction, const StripeQualityOptions& options,
                  StripeResult* result);

/// Options of RefineStripeCentres.
struct StripeRefineOptions {
  /// Relative noise of the profile that grows with it, 1-sigma as a fraction of the
  /// intensity (laser speckle), against the additive noise of each scan line.
  double speckle = 0.1;
  /// The additive noise is taken as at least this fraction of the peak, so that on a nearly
  /// noise-free image the far tails of the profile do not take over the weights.
  double noise_floor = 0.02;
  int max_iterations = 20;
  double tolerance = 1e-4;  // px: convergence of the centre
};

/// Noise-weighted symmetric centres of found scan lines: the root c of
///   sum_p w(p - c) I(p) = 0,   w(x) = P'(x) / (n^2 + (speckle P(x))^2),
/// P a Gaussian of the scan line's FWHM and peak, n its additive noise. w is odd, so the
/// centre of any profile symmetric about its centre is exact, whatever its shape, but for the
/// sampling at whole pixels (a few thousandths of a pixel for a 1 px sigma core); the weights
/// are those of the best linear shift estimate under additive noise plus speckle, which
/// weighs the flanks more than the speckled top (Steger's derivative of a Gaussian does
/// not). Refines `result`'s kFound scan lines in place (centre and sigma) where `noise` (one
/// additive noise standard deviation per scan line, intensity units of `image`) is finite
/// and the window (centre +- 4 profile sigmas) lies inside the image; others keep their
/// centre. A scan line whose root is not found, or lies more than half a profile sigma from
/// the given centre, becomes kFitFailed. `image`: the stripe's image as floats (e.g. the
/// albedo-normalised difference, smoothed along the stripe). Throws std::invalid_argument for
/// an empty image, a result or noise of another length, or invalid options.
void RefineStripeCentres(const ImageView<float>& image, StripeDirection direction,
                         const Eigen::VectorXd& noise, const StripeRefineOptions& options,
                         StripeResult* result);

/// Noise standard deviation of a zero-clipped difference image D = max(0, X), X ~ N(0, s^2)
/// in the background: s = sqrt(2 mean(D^2)) over pixels of every `row_step`-th row at or
/// below a cut of four times a first, percentile-based estimate (so that the stripe does not
/// count), combined with the quantisation noise of two rounded frames (variance 1/6).
template <typename T>
double EstimateDifferenceNoise(const ImageView<T>& image, int row_step = 4);

/// The factor by which smoothing with the sampled Gaussian of scale `sigma` (px, radius
/// ceil(3.5 sigma), as StripeOptions::detect_sigma_along uses it) lowers independent
/// per-pixel noise: sqrt(sum g^2).
double SmoothingNoiseGain(double sigma);

}  // namespace hmlvs
