// The per-scan-line work of the stripe extraction, shared by ExtractStripe, AssessStripe and
// RefineStripeCentres (image.cpp, on whole images) and StripeFromFrames (frames.cpp, on
// images computed only where a scan line reads them). Internal: not part of the library's
// interface.
//
// A "view" is anything with the members of ScanView: n_scan and n_prof, at(s, p) (the value
// of scan line s at profile coordinate p), clamped(s, p) (the same with both clamped to the
// image), Pixel (its pixel type) and Deriv (Steger's smoothed derivatives at (s, p)).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "hmlvs/image/image.h"

namespace hmlvs::scan {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kMaxRuns = 8;  // runs stored per scan line; more count as "multiple"

template <typename T>
void RequireImage(const ImageView<T>& im, const char* name) {
  if (im.data == nullptr || im.rows <= 0 || im.cols <= 0) {
    std::ostringstream msg;
    msg << name << " is empty (" << im.rows << " x " << im.cols << " pixels)";
    throw std::invalid_argument(msg.str());
  }
}

// Throws std::invalid_argument unless the laser-on and laser-off frames have one size.
template <typename T>
void RequireSameSize(const ImageView<T>& on, const ImageView<T>& off) {
  if (on.rows != off.rows || on.cols != off.cols) {
    std::ostringstream msg;
    msg << "the laser-on image is " << on.cols << " x " << on.rows
        << " pixels but the laser-off image is " << off.cols << " x " << off.rows;
    throw std::invalid_argument(msg.str());
  }
}

struct Kernels {
  int radius = 0;
  std::vector<double> g0, g1, g2;  // smoothing, first and second derivative (correlation)
  double sum_sq0 = 0.0, sum_sq1 = 0.0;
};

// Sampled Gaussian derivative kernels of scale sigma and the given radius (default
// ceil(3.5 sigma)), normalised so that they are exact on constants (g0), ramps (g1) and
// parabolas (g2). Radius 0 is the sample itself, with no derivatives.
inline Kernels MakeKernels(double sigma, int radius = -1) {
  Kernels k;
  k.radius = radius >= 0 ? radius : static_cast<int>(std::ceil(3.5 * sigma));
  const int n = 2 * k.radius + 1;
  k.g0.resize(n);
  k.g1.assign(n, 0.0);
  k.g2.assign(n, 0.0);
  double s0 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double x = i - k.radius;
    k.g0[i] = std::exp(-x * x / (2.0 * sigma * sigma));
    s0 += k.g0[i];
  }
  for (double& g : k.g0) g /= s0;
  for (const double g : k.g0) k.sum_sq0 += g * g;
  if (k.radius == 0) return k;
  double m2 = 0.0, mean2 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double x = i - k.radius;
    k.g1[i] = x * k.g0[i];
    m2 += x * x * k.g0[i];
    k.g2[i] = (x * x - sigma * sigma) * k.g0[i];
    mean2 += k.g2[i];
  }
  double q2 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double x = i - k.radius;
    k.g1[i] /= m2;
    k.g2[i] -= mean2 * k.g0[i];
    q2 += x * x * k.g2[i];
  }
  for (int i = 0; i < n; ++i) {
    k.g2[i] *= 2.0 / q2;
    k.sum_sq1 += k.g1[i] * k.g1[i];
  }
  return k;
}

struct Derivatives {
  double gs, gp, gss, gsp, gpp;
};

// Gaussian derivatives at (s, p): ks along s (across scan lines), kp along p (the profile).
template <class V>
Derivatives SmoothedDerivatives(const V& v, const Kernels& ks, const Kernels& kp, int s, int p) {
  Derivatives d{0, 0, 0, 0, 0};
  const int rs = ks.radius, rp = kp.radius;
  for (int dp = -rp; dp <= rp; ++dp) {
    double h0 = 0.0, h1 = 0.0, h2 = 0.0;
    for (int ds = -rs; ds <= rs; ++ds) {
      const double x = v.clamped(s + ds, p + dp);
      h0 += ks.g0[ds + rs] * x;
      h1 += ks.g1[ds + rs] * x;
      h2 += ks.g2[ds + rs] * x;
    }
    d.gs += kp.g0[dp + rp] * h1;
    d.gp += kp.g1[dp + rp] * h0;
    d.gss += kp.g0[dp + rp] * h2;
    d.gpp += kp.g2[dp + rp] * h0;
    d.gsp += kp.g1[dp + rp] * h1;
  }
  return d;
}

// A scan line view: the image seen as scan lines s (columns or rows) along which the
// profile coordinate p runs.
template <typename T>
struct ScanView {
  using Pixel = T;
  const T* data;
  int n_scan;
  int n_prof;
  std::ptrdiff_t ss;  // element step between scan lines
  std::ptrdiff_t sp;  // element step along a profile
  double at(int s, int p) const { return static_cast<double>(data[s * ss + p * sp]); }
  double clamped(int s, int p) const {
    s = std::clamp(s, 0, n_scan - 1);
    p = std::clamp(p, 0, n_prof - 1);
    return at(s, p);
  }
  Derivatives Deriv(const Kernels& ks, const Kernels& kp, int s, int p) const {
    return SmoothedDerivatives(*this, ks, kp, s, p);
  }
};

template <typename T>
ScanView<T> MakeScanView(const ImageView<T>& im, StripeDirection dir) {
  if (dir == StripeDirection::kColumns) {
    return {im.data, im.cols, im.rows, im.col_stride, im.row_stride};
  }
  return {im.data, im.rows, im.cols, im.row_stride, im.col_stride};
}

struct Runs {
  explicit Runs(int n_scan = 0)
      : begin(static_cast<size_t>(n_scan) * kMaxRuns), end(begin.size()), count(n_scan, 0) {}
  void Add(int s, int b, int e) {
    const int k = count[s]++;
    if (k < kMaxRuns) {
      begin[static_cast<size_t>(s) * kMaxRuns + k] = b;
      end[static_cast<size_t>(s) * kMaxRuns + k] = e;
    }
  }
  std::vector<int> begin, end, count;
};

struct Peak {
  int b = 0, e = 0, m = 0;
  int lo = 0, hi = 0;  // the half-maximum walk's last pixels either side of m
  double value = 0.0;
  double width = 0.0;
};

// Peak pixel and full width at half maximum (linear interpolation of the half-maximum
// crossings). A crossing beyond the image border is taken at the border (-0.5 or n - 0.5);
// a walk longer than `limit` pixels gives an infinite width.
template <class V>
Peak MeasurePeak(const V& v, int s, int b, int e, int limit) {
  Peak pk;
  pk.b = b;
  pk.e = e;
  pk.m = b;
  pk.value = v.at(s, b);
  for (int p = b + 1; p < e; ++p) {
    const double x = v.at(s, p);
    if (x > pk.value) {
      pk.value = x;
      pk.m = p;
    }
  }
  const double half = 0.5 * pk.value;
  int i = pk.m;
  while (i > 0 && v.at(s, i - 1) > half && pk.m - i <= limit) --i;
  int j = pk.m;
  while (j < v.n_prof - 1 && v.at(s, j + 1) > half && j - pk.m <= limit) ++j;
  pk.lo = i;
  pk.hi = j;
  if (pk.m - i > limit || j - pk.m > limit) {
    pk.width = std::numeric_limits<double>::infinity();
    return pk;
  }
  double left = -0.5, right = v.n_prof - 0.5;
  if (i > 0) {
    const double lo = v.at(s, i - 1), hi = v.at(s, i);
    left = (i - 1) + (half - lo) / (hi - lo);
  }
  if (j < v.n_prof - 1) {
    const double hi = v.at(s, j), lo = v.at(s, j + 1);
    right = j + (hi - half) / (hi - lo);
  }
  pk.width = right - left;
  return pk;
}

// Steger's kernels: across the scan line (along the profile) at steger_sigma; along the stripe
// (across scan lines) at steger_sigma_along, cut short symmetrically near the first and last
// scan lines (radius = the distance to the image's edge), so that a slanted stripe is not bent
// by a replicated border. A kernel cut below ceil(steger_sigma) does not measure the line's
// direction: those scan lines are not fitted.
struct StegerKernels {
  Kernels across;
  int min_along = 0;
  std::vector<Kernels> along;  // by radius 0 .. full
  const Kernels& Along(int s, int n_scan) const {
    const int r = std::min({static_cast<int>(along.size()) - 1, s, n_scan - 1 - s});
    return along[static_cast<size_t>(r)];
  }
};

inline StegerKernels MakeStegerKernels(double sigma, double sigma_along) {
  StegerKernels k;
  k.across = MakeKernels(sigma);
  const int full = static_cast<int>(std::ceil(3.5 * sigma_along));
  for (int r = 0; r <= full; ++r) k.along.push_back(MakeKernels(sigma_along, r));
  k.min_along = std::min(full, static_cast<int>(std::ceil(sigma)));
  return k;
}

// The Steger kernels of the options (empty unless the method is Steger's).
inline StegerKernels StegerKernelsOf(const StripeOptions& o) {
  if (o.method != StripeMethod::kSteger) return StegerKernels();
  return MakeStegerKernels(o.steger_sigma,
                           o.steger_sigma_along > 0.0 ? o.steger_sigma_along : o.steger_sigma);
}

struct Centre {
  bool ok = false;
  double centre = kNaN;
  double sigma = kNaN;
};

template <class V>
Centre CentroidCentre(const V& v, int s, const Peak& pk, double thr, double noise) {
  double w_sum = 0.0, wp_sum = 0.0;
  for (int p = pk.b; p < pk.e; ++p) {
    const double w = v.at(s, p) - thr;
    w_sum += w;
    wp_sum += w * p;
  }
  Centre c;
  if (!(w_sum > 0.0)) return c;
  c.centre = wp_sum / w_sum;
  double m2 = 0.0;
  for (int p = pk.b; p < pk.e; ++p) m2 += (p - c.centre) * (p - c.centre);
  c.sigma = noise * std::sqrt(m2) / w_sum;
  c.ok = true;
  return c;
}

template <class V>
Centre GaussianCentre(const V& v, int s, const Peak& pk, double noise) {
  Centre c;
  if (pk.m <= 0 || pk.m >= v.n_prof - 1) return c;
  // a saturated peak has a flat top the log-parabola cannot place
  if (pk.value >= static_cast<double>(std::numeric_limits<typename V::Pixel>::max())) return c;
  // Neighbours below half a quantum are taken as 0.5 so that the logarithm exists.
  const double a = std::max(v.at(s, pk.m - 1), 0.5);
  const double b = std::max(v.at(s, pk.m), 0.5);
  const double cc = std::max(v.at(s, pk.m + 1), 0.5);
  const double la = std::log(a), lb = std::log(b), lc = std::log(cc);
  const double num = la - lc;
  const double den = la - 2.0 * lb + lc;
  if (!(den < 0.0)) return c;  // flat (saturated) or not a maximum
  const double delta = 0.5 * num / den;
  if (!(std::abs(delta) <= 1.0)) return c;
  const double da = (den - num) / (2.0 * den * den) / a;
  const double db = num / (den * den) / b;
  const double dc = (-den - num) / (2.0 * den * den) / cc;
  c.centre = pk.m + delta;
  c.sigma = noise * std::sqrt(da * da + db * db + dc * dc);
  c.ok = true;
  return c;
}

constexpr int kMaxStegerSteps = 3;

template <class V>
Centre StegerCentre(const V& v, int s, const Peak& pk, const StegerKernels& k, double noise) {
  Centre c;
  int m = pk.m;
  const Kernels& ks = k.Along(s, v.n_scan);
  if (ks.radius < k.min_along) return c;  // too close to the image's first or last scan line
  for (int step = 0; step < kMaxStegerSteps; ++step) {
    const Derivatives d = v.Deriv(ks, k.across, s, m);
    const double mean = 0.5 * (d.gss + d.gpp);
    const double rad = std::sqrt(0.25 * (d.gss - d.gpp) * (d.gss - d.gpp) + d.gsp * d.gsp);
    const double lambda = mean - rad;  // most negative eigenvalue: across a bright line
    if (!(lambda < 0.0)) return c;
    double ns = d.gsp, np = lambda - d.gss;
    const double ns2 = lambda - d.gpp, np2 = d.gsp;
    if (ns2 * ns2 + np2 * np2 > ns * ns + np * np) {
      ns = ns2;
      np = np2;
    }
    const double norm = std::sqrt(ns * ns + np * np);
    if (!(norm > 0.0)) return c;
    ns /= norm;
    np /= norm;
    if (std::abs(np) < 0.5) return c;  // the line runs along the scan line: wrong direction
    const double t = -(ns * d.gs + np * d.gp) / lambda;
    const double centre = m + t / np;
    if (std::abs(centre - m) <= 0.5 || step == kMaxStegerSteps - 1) {
      if (!(std::abs(centre - m) <= 1.0)) return c;
      c.centre = centre;
      // the noise of gp, the derivative across the line that places the centre
      c.sigma = noise * std::sqrt(ks.sum_sq0 * k.across.sum_sq1) / std::abs(lambda) / std::abs(np);
      c.ok = true;
      return c;
    }
    const int next = static_cast<int>(std::lround(centre));
    if (next < 0 || next >= v.n_prof) return c;
    m = next;
  }
  return c;
}

// Linear interpolation of the profile of scan line s at p (clamped to the image).
template <class V>
double Interpolate(const V& v, int s, double p) {
  if (v.n_prof < 2) return v.at(s, 0);
  p = std::clamp(p, 0.0, static_cast<double>(v.n_prof - 1));
  const int i = std::min(static_cast<int>(p), v.n_prof - 2);
  const double f = p - i;
  return (1.0 - f) * v.at(s, i) + f * v.at(s, i + 1);
}

// Asymmetry of the profile about `centre`: RMS of I(c + x) - I(c - x) for x = 0.5, 1, ...
// up to half the FWHM (at least one sample), over the peak value.
template <class V>
double Asymmetry(const V& v, int s, double centre, double width, double peak) {
  const int n = std::max(1, static_cast<int>(std::floor(width)));
  double sum = 0.0;
  for (int k = 1; k <= n; ++k) {
    const double x = 0.5 * k;
    const double d = Interpolate(v, s, centre + x) - Interpolate(v, s, centre - x);
    sum += d * d;
  }
  return std::sqrt(sum / n) / std::max(peak, 1e-12);
}

// DifferenceImage's value at a pixel as a function of the laser-on value's excess over the
// laser-off value, diff = max(on - off, 0) (a whole number), and the laser-off value y: the
// plain difference, or one of the two rules of the albedo normalisation (DifferenceOptions).
template <typename T>
struct DifferenceRule {
  using Acc = std::conditional_t<sizeof(T) == 1, float, double>;
  static constexpr double kTop = static_cast<double>(std::numeric_limits<T>::max());
  bool normalize = false;
  bool offset_rule = false;  // a non-zero offset: double precision, rounded half to even
  double scale = 1.0, offset = 0.0, floor = 1.0;
  std::vector<Acc> gain;      // the plain normalisation's gain per laser-off value
  std::vector<double> bound;  // per laser-off value: the gain, rounded up (see Bound)

  DifferenceRule() = default;
  // `mean`: the laser-off image's mean (the default scale and floor)
  DifferenceRule(const DifferenceOptions& o, double mean) : normalize(o.normalize) {
    if (!normalize) return;
    floor = o.floor > 0.0 ? o.floor : std::max(1.0, 0.1 * mean);
    offset = o.offset;
    offset_rule = o.offset != 0.0;
    scale = o.scale > 0.0 ? o.scale : mean + (offset_rule ? o.offset : 0.0);
    const size_t n = static_cast<size_t>(std::numeric_limits<T>::max()) + 1;
    bound.resize(n);
    if (offset_rule) {
      for (size_t y = 0; y < n; ++y) bound[y] = scale / std::max(y + offset, floor);
    } else {
      // Single precision for 8-bit images (exact enough: values below 2^12), double for 16
      gain.resize(n);
      for (size_t y = 0; y < n; ++y) {
        gain[y] = static_cast<Acc>(scale / std::max(static_cast<double>(y), floor));
        bound[y] = static_cast<double>(gain[y]);
      }
    }
    for (double& b : bound) b *= 1.0 + 1e-9;
  }
  T operator()(double diff, T y) const {
    if (!normalize) return static_cast<T>(diff);
    if (offset_rule) {
      // d = max(x - y, 0) * s / max(y + offset, floor) in NumPy's order, clipped, rounded half
      // to even by adding and subtracting 2^52 (exact for 0 <= d < 2^51 under the default
      // rounding mode; clipping before rounding gives NumPy's rint-then-clip)
      constexpr double kRound = 0x1p52;
      const double d = diff * scale / std::max(y + offset, floor);
      return static_cast<T>(static_cast<int>((std::min(std::max(d, 0.0), kTop) + kRound) - kRound));
    }
    // d >= 0.5 so truncating rounds (an int: a 64-bit conversion is ~10x slower)
    const Acc d = std::min(static_cast<Acc>(kTop), static_cast<Acc>(diff) * gain[y] + Acc(0.5));
    return static_cast<T>(static_cast<int>(d));
  }
  T At(T x, T y) const { return (*this)(static_cast<double>(std::max(x, y) - y), y); }
  // 8-bit: the value of every (laser-off y, laser-on x) pair at table[y << 8 | x]
  void Table(std::vector<T>* table) const {
    static_assert(sizeof(T) == 1, "a table of every pair of 8-bit values");
    table->assign(256 * 256, T(0));
    for (int y = 0; y < 256; ++y) {
      T* row = table->data() + (y << 8);
      if (!normalize) {
        for (int x = y + 1; x < 256; ++x) row[x] = static_cast<T>(x - y);
      } else if (offset_rule) {
        constexpr double kRound = 0x1p52;
        const double den = std::max(y + offset, floor);
        for (int x = y + 1; x < 256; ++x) {
          const double d = (x - y) * scale / den;
          row[x] = static_cast<T>(
              static_cast<int>((std::min(std::max(d, 0.0), kTop) + kRound) - kRound));
        }
      } else {
        const Acc g = gain[y];
        for (int x = y + 1; x < 256; ++x) {
          row[x] = static_cast<T>(static_cast<int>(
              std::min(static_cast<Acc>(kTop), static_cast<Acc>(x - y) * g + Acc(0.5))));
        }
      }
    }
  }
  // At least the value of any pixel whose diff is at most `diff` and laser-off value at least
  // `y` (the value grows with diff and falls with y)
  double Bound(double diff, T y) const {
    return normalize ? std::min(kTop, diff * bound[y] + 0.5) : diff;
  }
};

// Throws std::invalid_argument, with a sentence naming the option, for invalid options.
void ValidateOptions(const StripeOptions& o);

// A result of n scan lines with nothing found yet (threshold and noise as given).
void ResetResult(int n, StripeResult* res);

// Scan line s of ExtractStripe: its `count` runs above the threshold [begin[k], end[k]) of
// the detection view dv -> peaks (sized on dv), the choice of one, its status and its centre
// (measured on v). `res` holds threshold and noise and receives scan line s.
template <class V, class DV>
void ScanLine(const V& v, const DV& dv, int s, const int* begin, const int* end, int count,
              const StripeOptions& o, const StegerKernels& kernels, StripeResult* res) {
  if (count == 0) return;
  if (count > kMaxRuns) {
    res->status[s] = static_cast<std::uint8_t>(StripeStatus::kMultiple);
    res->num_peaks[s] = count;
    return;
  }
  const int limit = static_cast<int>(std::ceil(o.max_width)) + 2;
  Peak best_valid, best_wide, best_narrow;
  int n_valid = 0, n_wide = 0, n_narrow = 0;
  double second = 0.0;  // strongest competitor other than best_valid
  Peak peaks[kMaxRuns];
  for (int k = 0; k < count; ++k) peaks[k] = MeasurePeak(dv, s, begin[k], end[k], limit);
  // A run whose half-maximum span holds a stronger run's peak is that peak's shoulder
  // (noise splitting a wide profile where it crosses the threshold), not a peak.
  bool shoulder[kMaxRuns] = {};
  for (int k = 0; k < count; ++k) {
    for (int k2 = 0; k2 < count && !shoulder[k]; ++k2) {
      const bool stronger =
          peaks[k2].value > peaks[k].value || (peaks[k2].value == peaks[k].value && k2 < k);
      shoulder[k] = k2 != k && stronger && peaks[k2].m >= peaks[k].lo && peaks[k2].m <= peaks[k].hi;
    }
  }
  for (int k = 0; k < count; ++k) {
    const Peak& pk = peaks[k];
    if (shoulder[k]) continue;
    if (pk.width < o.min_width) {
      if (n_narrow++ == 0 || pk.value > best_narrow.value) best_narrow = pk;
    } else if (pk.width > o.max_width) {
      if (n_wide++ == 0 || pk.value > best_wide.value) best_wide = pk;
    } else if (n_valid++ == 0 || pk.value > best_valid.value) {
      best_valid = pk;
    }
  }
  res->num_peaks[s] = n_valid + n_wide;
  if (n_valid == 0) {
    const Peak& shown = n_wide > 0 ? best_wide : best_narrow;
    res->status[s] =
        static_cast<std::uint8_t>(n_wide > 0 ? StripeStatus::kTooWide : StripeStatus::kTooNarrow);
    res->intensity[s] = shown.value;
    res->width[s] = shown.width;
    return;
  }
  for (int k = 0; k < count; ++k) {
    const Peak& pk = peaks[k];
    const bool competitor = pk.width >= o.min_width && !shoulder[k];
    const bool is_best = pk.b == best_valid.b;
    if (competitor && !is_best) second = std::max(second, pk.value);
  }
  res->intensity[s] = best_valid.value;
  res->width[s] = best_valid.width;
  if (res->num_peaks[s] > 1 && !(o.dominance >= 1.0 && best_valid.value >= o.dominance * second)) {
    res->status[s] = static_cast<std::uint8_t>(StripeStatus::kMultiple);
    return;
  }
  Centre c;
  switch (o.method) {
    case StripeMethod::kCentroid:
      c = CentroidCentre(v, s, best_valid, res->threshold, res->noise);
      break;
    case StripeMethod::kGaussian:
      c = GaussianCentre(v, s, best_valid, res->noise);
      break;
    case StripeMethod::kSteger:
      c = StegerCentre(v, s, best_valid, kernels, res->noise);
      break;
  }
  if (!c.ok) {
    res->status[s] = static_cast<std::uint8_t>(StripeStatus::kFitFailed);
    return;
  }
  res->status[s] = static_cast<std::uint8_t>(StripeStatus::kFound);
  res->centre[s] = c.centre;
  res->sigma[s] = c.sigma;
  res->residual[s] = Asymmetry(v, s, c.centre, best_valid.width, best_valid.value);
}

// Throws std::invalid_argument for invalid quality options.
void ValidateQualityOptions(const StripeQualityOptions& o);

// The checks of AssessStripe on scan line s (found; centre c, FWHM w): `v` the stripe's
// image, `von` the laser-on frame (or v), `voff` the laser-off frame when `with_off`;
// `thr` the threshold the stripe was found with; `y` a buffer. Returns the new status.
template <class V, class VOn, class VOff>
StripeStatus AssessLine(const V& v, const VOn& von, const VOff& voff, bool with_off,
                        const StripeQualityOptions& o, int s, double c, double w, double thr,
                        std::vector<double>* y) {
  const double tmax = static_cast<double>(std::numeric_limits<typename VOn::Pixel>::max());
  const int n = v.n_scan;
  if (c - w < -0.5 || c + w > v.n_prof - 0.5) return StripeStatus::kClipped;
  const int lo = std::max(0, static_cast<int>(std::ceil(c - 0.5 * w)));
  const int hi = std::min(v.n_prof - 1, static_cast<int>(std::floor(c + 0.5 * w)));
  for (int p = lo; p <= hi; ++p) {
    if (von.at(s, p) >= tmax) return StripeStatus::kSaturated;
  }
  if (o.hump > 0.0) {
    // the run above threshold around the centre, smoothed at FWHM / 6 (speckle)
    const int m = std::clamp(static_cast<int>(std::lround(c)), 0, v.n_prof - 1);
    int b = m, e = m;
    while (b > 0 && v.at(s, b - 1) > thr) --b;
    while (e < v.n_prof - 1 && v.at(s, e + 1) > thr) ++e;
    const double sg = std::max(0.5, w / 6.0);
    const int r = static_cast<int>(std::ceil(2.5 * sg));
    double g[64];  // the kernel's weights (r <= 25 for the largest accepted FWHM of 40 px)
    const bool stored = 2 * r + 1 <= 64;
    if (stored) {
      for (int k = -r; k <= r; ++k) g[k + r] = std::exp(-0.5 * k * k / (sg * sg));
    }
    y->assign(static_cast<size_t>(e - b + 1), 0.0);
    for (int p = b; p <= e; ++p) {
      double acc = 0.0, wsum = 0.0;
      for (int k = -r; k <= r; ++k) {
        const int q = std::clamp(p + k, b, e);
        const double gk = stored ? g[k + r] : std::exp(-0.5 * k * k / (sg * sg));
        acc += gk * v.at(s, q);
        wsum += gk;
      }
      (*y)[p - b] = acc / wsum;
    }
    const std::vector<double>& yy = *y;
    int top = std::clamp(m, b, e) - b;
    const int reach = std::max(1, static_cast<int>(std::ceil(0.5 * w)));
    for (int q = std::max(0, top - reach); q <= std::min(e - b, top + reach); ++q) {
      if (yy[q] > yy[top]) top = q;
    }
    bool twin = false;
    for (int dir = -1; dir <= 1 && !twin; dir += 2) {
      double dip = yy[top];
      for (int q = top + dir; q >= 0 && q <= e - b && !twin; q += dir) {
        dip = std::min(dip, yy[q]);
        twin = yy[q] >= o.hump * yy[top] && dip < o.dip * yy[q];
      }
    }
    if (twin) return StripeStatus::kDoublePeak;
  }
  if (with_off) {
    // 3 x 3 means: one grey level of noise on a dark square's level of 10 would otherwise
    // pass for a step in half the scan lines that cross such a square
    const int a = std::max(0, static_cast<int>(std::floor(c - w)));
    const int z = std::min(v.n_prof - 1, static_cast<int>(std::ceil(c + w)));
    double mn = std::numeric_limits<double>::infinity(), mx = -mn;
    for (int p = a; p <= z; ++p) {
      double sum = 0.0;
      int count = 0;
      for (int t = std::max(0, s - 1); t <= std::min(n - 1, s + 1); ++t) {
        for (int q = std::max(0, p - 1); q <= std::min(v.n_prof - 1, p + 1); ++q) {
          sum += voff.at(t, q);
          ++count;
        }
      }
      const double mean = sum / count;
      mn = std::min(mn, mean);
      mx = std::max(mx, mean);
    }
    if (mx + o.albedo_offset > o.albedo_step * std::max(mn + o.albedo_offset, 1.0)) {
      return StripeStatus::kAlbedoEdge;
    }
  }
  return StripeStatus::kFound;
}

// Throws std::invalid_argument for invalid refinement options.
void ValidateRefineOptions(const StripeRefineOptions& o);

// RefineStripeCentres on scan line s (kFound, additive noise `noise`): updates the centre,
// sigma and status of `res` at s. `v` holds the image as floats.
template <class V>
void RefineLine(const V& v, int s, double noise, const StripeRefineOptions& o, StripeResult* res) {
  const double k2 = o.speckle * o.speckle;
  const double c0 = res->centre[s];
  const double sp = std::max(0.5, res->width[s] / (2.0 * std::sqrt(2.0 * std::log(2.0))));
  if (!std::isfinite(noise) || noise < 0.0 || !std::isfinite(c0) || !std::isfinite(sp)) return;
  const int hw = static_cast<int>(std::ceil(4.0 * sp));
  if (c0 - hw - 1.0 < 0.0 || c0 + hw + 1.0 > v.n_prof - 1.0) return;
  // the profile's peak: the largest sample within one profile sigma of the centre
  double peak = 0.0;
  for (int p = static_cast<int>(std::ceil(c0 - sp)); p <= static_cast<int>(std::floor(c0 + sp));
       ++p) {
    peak = std::max(peak, v.at(s, p));
  }
  const double add = std::max(noise, o.noise_floor * peak);
  const double a2 = add * add;
  auto set_failed = [&] {
    res->status[s] = static_cast<std::uint8_t>(StripeStatus::kFitFailed);
    res->centre[s] = kNaN;
    res->sigma[s] = kNaN;
  };
  if (!(peak > 0.0) || !(a2 > 0.0 || k2 > 0.0)) {
    set_failed();
    return;
  }
  const double inv_s2 = 1.0 / (sp * sp);
  double c = c0, f_sum = 0.0, df_sum = 0.0, var_sum = 0.0;
  bool converged = false;
  for (int it = 0; it < o.max_iterations; ++it) {
    const int m = static_cast<int>(std::lround(c));
    if (m - hw < 0 || m + hw > v.n_prof - 1) break;
    f_sum = df_sum = var_sum = 0.0;
    // P(x) = peak exp(-x^2 / (2 sp^2)) at x = p - c, by the recurrence exp(-(x + 1)^2 / 2 s2)
    // = exp(-x^2 / 2 s2) exp(-(2 x + 1) / 2 s2), whose factor shrinks by exp(-1 / s2) a step
    const double x0 = (m - hw) - c;
    double g = peak * std::exp(-0.5 * x0 * x0 * inv_s2);
    double ratio = std::exp(-0.5 * (2.0 * x0 + 1.0) * inv_s2);
    const double shrink = std::exp(-inv_s2);
    for (int p = m - hw; p <= m + hw; ++p, g *= ratio, ratio *= shrink) {
      const double x = p - c;
      const double pp = g;                                      // P(x)
      const double dp = -x * inv_s2 * pp;                       // P'(x)
      const double ddp = (x * x * inv_s2 - 1.0) * inv_s2 * pp;  // P''(x)
      const double den = a2 + k2 * pp * pp;
      const double inv = 1.0 / den;
      const double w = dp * inv;
      const double dw = (ddp - dp * 2.0 * k2 * pp * dp * inv) * inv;
      const double y = v.at(s, p);
      f_sum += w * y;
      df_sum -= dw * y;  // d/dc of w(p - c) y
      var_sum += w * w * den;
    }
    if (!(df_sum < 0.0 || df_sum > 0.0) || !std::isfinite(f_sum)) break;
    const double step = std::clamp(-f_sum / df_sum, -0.5, 0.5);
    c += step;
    if (std::abs(step) < o.tolerance) {
      converged = true;
      break;
    }
  }
  if (!converged || !(std::abs(c - c0) <= 0.5 * sp)) {
    set_failed();
    return;
  }
  res->centre[s] = c;
  res->sigma[s] = std::sqrt(var_sum) / std::abs(df_sum);
}

// The noise standard deviation of EstimateDifferenceNoise from the histogram of the sampled
// pixels (n of them).
double NoiseFromHistogram(const std::vector<std::uint64_t>& hist, std::uint64_t n);

// One output line: acc = sum_k w[k] line[s + k], the inner loop over contiguous floats.
void SumShifted(const float* __restrict line, const float* __restrict w, int taps, int n,
                float* __restrict acc);

}  // namespace hmlvs::scan
