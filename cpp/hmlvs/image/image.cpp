#include "hmlvs/image/image.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace hmlvs {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kMaxRuns = 8;  // runs stored per scan line; more count as "multiple"
constexpr int kBlock = 32;   // scan lines tested together for "nothing above threshold"
constexpr int kMaxStegerSteps = 3;

template <typename T>
void RequireImage(const ImageView<T>& im, const char* name) {
  if (im.data == nullptr || im.rows <= 0 || im.cols <= 0) {
    std::ostringstream msg;
    msg << name << " is empty (" << im.rows << " x " << im.cols << " pixels)";
    throw std::invalid_argument(msg.str());
  }
}

// A scan line view: the image seen as scan lines s (columns or rows) along which the
// profile coordinate p runs.
template <typename T>
struct ScanView {
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
};

template <typename T>
ScanView<T> MakeScanView(const ImageView<T>& im, StripeDirection dir) {
  if (dir == StripeDirection::kColumns) {
    return {im.data, im.cols, im.rows, im.col_stride, im.row_stride};
  }
  return {im.data, im.rows, im.cols, im.row_stride, im.col_stride};
}

struct Runs {
  explicit Runs(int n_scan)
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

// Runs of pixels above `thr`, scan lines adjacent in memory: stream over the profile
// coordinate and keep per-scan-line state. Blocks of scan lines with nothing above
// threshold and no open run are skipped after one max-reduction.
template <typename T, bool kUnitStride>
void DetectStreaming(const ScanView<T>& v, T thr, Runs* runs) {
  std::vector<int> start(v.n_scan, -1);
  const int nb = (v.n_scan + kBlock - 1) / kBlock;
  std::vector<int> open(nb, 0);
  const std::ptrdiff_t ss = kUnitStride ? 1 : v.ss;
  for (int p = 0; p < v.n_prof; ++p) {
    const T* line = v.data + p * v.sp;
    for (int b = 0; b < nb; ++b) {
      const int s0 = b * kBlock;
      const int s1 = std::min(s0 + kBlock, v.n_scan);
      if (open[b] == 0) {
        T m = 0;
        for (int s = s0; s < s1; ++s) m = std::max(m, line[s * ss]);
        if (m <= thr) continue;
      }
      for (int s = s0; s < s1; ++s) {
        const bool above = line[s * ss] > thr;
        int& st = start[s];
        if (above) {
          if (st < 0) {
            st = p;
            ++open[b];
          }
        } else if (st >= 0) {
          runs->Add(s, st, p);
          st = -1;
          --open[b];
        }
      }
    }
  }
  for (int s = 0; s < v.n_scan; ++s) {
    if (start[s] >= 0) runs->Add(s, start[s], v.n_prof);
  }
}

// Runs of pixels above `thr`, profiles contiguous (or strided): one scan line at a time.
template <typename T, bool kUnitStride>
void DetectPerLine(const ScanView<T>& v, T thr, Runs* runs) {
  const std::ptrdiff_t sp = kUnitStride ? 1 : v.sp;
  for (int s = 0; s < v.n_scan; ++s) {
    const T* line = v.data + s * v.ss;
    int p = 0;
    while (p < v.n_prof) {
      if (p + kBlock <= v.n_prof) {
        T m = 0;
        for (int k = 0; k < kBlock; ++k) m = std::max(m, line[(p + k) * sp]);
        if (m <= thr) {
          p += kBlock;
          continue;
        }
      }
      const int stop = std::min(p + kBlock, v.n_prof);
      for (; p < stop; ++p) {
        if (line[p * sp] > thr) {
          const int b = p;
          while (p < v.n_prof && line[p * sp] > thr) ++p;
          runs->Add(s, b, p);
          break;
        }
      }
    }
  }
}

struct Peak {
  int b = 0, e = 0, m = 0;
  int lo = 0, hi = 0;  // the half-maximum walk's last pixels either side of m
  double value = 0.0;
  double width = 0.0;
};

// Peak pixel and full width at half maximum (linear interpolation of the half-maximum
// crossings). A crossing beyond the image border is taken at the border (-0.5 or n - 0.5);
// a walk longer than `limit` pixels gives an infinite width.
template <typename T>
Peak MeasurePeak(const ScanView<T>& v, int s, int b, int e, int limit) {
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

struct Kernels {
  int radius = 0;
  std::vector<double> g0, g1, g2;  // smoothing, first and second derivative (correlation)
  double sum_sq0 = 0.0, sum_sq1 = 0.0;
};

// Sampled Gaussian derivative kernels of scale sigma and the given radius (default
// ceil(3.5 sigma)), normalised so that they are exact on constants (g0), ramps (g1) and
// parabolas (g2). Radius 0 is the sample itself, with no derivatives.
Kernels MakeKernels(double sigma, int radius = -1) {
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

StegerKernels MakeStegerKernels(double sigma, double sigma_along) {
  StegerKernels k;
  k.across = MakeKernels(sigma);
  const int full = static_cast<int>(std::ceil(3.5 * sigma_along));
  for (int r = 0; r <= full; ++r) k.along.push_back(MakeKernels(sigma_along, r));
  k.min_along = std::min(full, static_cast<int>(std::ceil(sigma)));
  return k;
}

struct Derivatives {
  double gs, gp, gss, gsp, gpp;
};

// Gaussian derivatives at (s, p): ks along s (across scan lines), kp along p (the profile).
template <typename T>
Derivatives SmoothedDerivatives(const ScanView<T>& v, const Kernels& ks, const Kernels& kp, int s,
                                int p) {
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

struct Centre {
  bool ok = false;
  double centre = kNaN;
  double sigma = kNaN;
};

template <typename T>
Centre CentroidCentre(const ScanView<T>& v, int s, const Peak& pk, double thr, double noise) {
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

template <typename T>
Centre GaussianCentre(const ScanView<T>& v, int s, const Peak& pk, double noise) {
  Centre c;
  if (pk.m <= 0 || pk.m >= v.n_prof - 1) return c;
  // a saturated peak has a flat top the log-parabola cannot place
  if (pk.value >= static_cast<double>(std::numeric_limits<T>::max())) return c;
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

template <typename T>
Centre StegerCentre(const ScanView<T>& v, int s, const Peak& pk, const StegerKernels& k,
                    double noise) {
  Centre c;
  int m = pk.m;
  const Kernels& ks = k.Along(s, v.n_scan);
  if (ks.radius < k.min_along) return c;  // too close to the image's first or last scan line
  for (int step = 0; step < kMaxStegerSteps; ++step) {
    const Derivatives d = SmoothedDerivatives(v, ks, k.across, s, m);
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
template <typename T>
double Interpolate(const ScanView<T>& v, int s, double p) {
  if (v.n_prof < 2) return v.at(s, 0);
  p = std::clamp(p, 0.0, static_cast<double>(v.n_prof - 1));
  const int i = std::min(static_cast<int>(p), v.n_prof - 2);
  const double f = p - i;
  return (1.0 - f) * v.at(s, i) + f * v.at(s, i + 1);
}

// Asymmetry of the profile about `centre`: RMS of I(c + x) - I(c - x) for x = 0.5, 1, ...
// up to half the FWHM (at least one sample), over the peak value.
template <typename T>
double Asymmetry(const ScanView<T>& v, int s, double centre, double width, double peak) {
  const int n = std::max(1, static_cast<int>(std::floor(width)));
  double sum = 0.0;
  for (int k = 1; k <= n; ++k) {
    const double x = 0.5 * k;
    const double d = Interpolate(v, s, centre + x) - Interpolate(v, s, centre - x);
    sum += d * d;
  }
  return std::sqrt(sum / n) / std::max(peak, 1e-12);
}

template <typename T>
void ValidateOptions(const StripeOptions& o) {
  std::ostringstream msg;
  if (o.direction != StripeDirection::kColumns && o.direction != StripeDirection::kRows) {
    msg << "direction must be columns or rows";
  } else if (o.method != StripeMethod::kCentroid && o.method != StripeMethod::kGaussian &&
             o.method != StripeMethod::kSteger) {
    msg << "method must be centroid, gaussian or steger";
  } else if (!std::isfinite(o.threshold)) {
    msg << "threshold must be a finite number (negative for automatic), got " << o.threshold;
  } else if (!(o.min_width >= 0.0) || !(o.max_width > o.min_width) || !std::isfinite(o.max_width)) {
    msg << "stripe widths must satisfy 0 <= min_width < max_width < inf, got min_width "
        << o.min_width << " and max_width " << o.max_width;
  } else if (!std::isfinite(o.noise)) {
    msg << "noise must be a finite number (negative to estimate it), got " << o.noise;
  } else if (!(o.steger_sigma >= 0.5 && o.steger_sigma <= 20.0)) {
    msg << "steger_sigma must lie in [0.5, 20] px, got " << o.steger_sigma;
  } else if (!(o.steger_sigma_along <= 0.0 ||
               (o.steger_sigma_along >= 0.5 && o.steger_sigma_along <= 40.0))) {
    msg << "steger_sigma_along must be 0 (= steger_sigma) or lie in [0.5, 40] px, got "
        << o.steger_sigma_along;
  } else if (!(o.dominance == 0.0 || (o.dominance >= 1.0 && std::isfinite(o.dominance)))) {
    msg << "dominance must be 0 (off) or a finite ratio >= 1, got " << o.dominance;
  } else if (!(o.detect_sigma_along == 0.0 ||
               (o.detect_sigma_along >= 0.5 && o.detect_sigma_along <= 40.0))) {
    msg << "detect_sigma_along must be 0 (off) or lie in [0.5, 40] px, got "
        << o.detect_sigma_along;
  } else {
    return;
  }
  throw std::invalid_argument(msg.str());
}

}  // namespace

template <typename T>
void DifferenceImage(const ImageView<T>& on, const ImageView<T>& off, T* out,
                     const DifferenceOptions& o) {
  RequireImage(on, "the laser-on image");
  RequireImage(off, "the laser-off image");
  if (on.rows != off.rows || on.cols != off.cols) {
    std::ostringstream msg;
    msg << "the laser-on image is " << on.cols << " x " << on.rows
        << " pixels but the laser-off image is " << off.cols << " x " << off.rows;
    throw std::invalid_argument(msg.str());
  }
  if (!std::isfinite(o.scale) || !std::isfinite(o.floor) || o.scale == 0.0 || o.floor == 0.0) {
    std::ostringstream msg;
    msg << "normalisation scale and floor must be finite and positive (or negative for "
           "automatic), got scale "
        << o.scale << " and floor " << o.floor;
    throw std::invalid_argument(msg.str());
  }
  if (!std::isfinite(o.offset)) {
    std::ostringstream msg;
    msg << "the normalisation offset must be a finite number, got " << o.offset;
    throw std::invalid_argument(msg.str());
  }
  // Loop bounds and strides in locals: writes through a uint8_t pointer may alias anything,
  // so struct members read in the loop would be reloaded every pixel and block vectorising.
  const int rows = on.rows, cols = on.cols;
  const std::ptrdiff_t on_rs = on.row_stride, on_cs = on.col_stride;
  const std::ptrdiff_t off_rs = off.row_stride, off_cs = off.col_stride;
  const bool contiguous = on_cs == 1 && off_cs == 1;
  if (!o.normalize) {
    for (int r = 0; r < rows; ++r) {
      const T* a = on.data + r * on_rs;
      const T* b = off.data + r * off_rs;
      T* dst = out + static_cast<std::ptrdiff_t>(r) * cols;
      if (contiguous) {
        // branch-free max(a, b) - b, which compilers vectorise
        for (int c = 0; c < cols; ++c) dst[c] = static_cast<T>(std::max(a[c], b[c]) - b[c]);
      } else {
        for (int c = 0; c < cols; ++c) {
          const T x = a[c * on_cs], y = b[c * off_cs];
          dst[c] = static_cast<T>(std::max(x, y) - y);
        }
      }
    }
    return;
  }
  std::uint64_t sum = 0;
  for (int r = 0; r < rows; ++r) {
    const T* b = off.data + r * off_rs;
    std::uint64_t row = 0;
    for (int c = 0; c < cols; ++c) row += b[c * off_cs];
    sum += row;
  }
  const double mean = static_cast<double>(sum) / (static_cast<double>(rows) * cols);
  const double floor = o.floor > 0.0 ? o.floor : std::max(1.0, 0.1 * mean);
  if (o.offset != 0.0) {
    // Double precision, one pass, the operations in NumPy's order (so the result is the
    // same to the bit): d = max(x - y, 0) * s / max(y + offset, floor), clipped to the
    // pixel range, then rounded half to even by adding and subtracting 2^52 (exact for
    // 0 <= d < 2^51 under the default rounding mode; clipping before rounding gives
    // NumPy's rint-then-clip, the bounds being integers).
    const double s = o.scale > 0.0 ? o.scale : mean + o.offset;
    const double offset = o.offset;
    const double top = static_cast<double>(std::numeric_limits<T>::max());
    constexpr double kRound = 0x1p52;
    auto value = [s, offset, floor, top](T on_value, T off_value) {
      const double x = on_value, y = off_value;
      const double d = std::max(x - y, 0.0) * s / std::max(y + offset, floor);
      return static_cast<T>(static_cast<int>((std::min(std::max(d, 0.0), top) + kRound) - kRound));
    };
    if constexpr (sizeof(T) == 1) {
      // 8-bit: the value of every (laser-off, laser-on) pair once (a loop that vectorises,
      // see cpp/CMakeLists.txt), then one table look-up per pixel
      std::vector<T> table(256 * 256);
      for (int y = 0; y < 256; ++y) {
        T* row = table.data() + y * 256;
        for (int x = 0; x < 256; ++x) row[x] = value(static_cast<T>(x), static_cast<T>(y));
      }
      const T* t = table.data();
      for (int r = 0; r < rows; ++r) {
        const T* a = on.data + r * on_rs;
        const T* b = off.data + r * off_rs;
        T* dst = out + static_cast<std::ptrdiff_t>(r) * cols;
        for (int c = 0; c < cols; ++c) dst[c] = t[(b[c * off_cs] << 8) | a[c * on_cs]];
      }
    } else {
      for (int r = 0; r < rows; ++r) {
        const T* a = on.data + r * on_rs;
        const T* b = off.data + r * off_rs;
        T* dst = out + static_cast<std::ptrdiff_t>(r) * cols;
        if (contiguous) {  // unit strides: the loop vectorises (see cpp/CMakeLists.txt)
          for (int c = 0; c < cols; ++c) dst[c] = value(a[c], b[c]);
        } else {
          for (int c = 0; c < cols; ++c) dst[c] = value(a[c * on_cs], b[c * off_cs]);
        }
      }
    }
    return;
  }
  const double scale = o.scale > 0.0 ? o.scale : mean;
  // Single precision for 8-bit images (exact enough: values below 2^12, and ~10x faster
  // here than double), double for 16-bit.
  using Acc = std::conditional_t<sizeof(T) == 1, float, double>;
  const Acc tmax = static_cast<Acc>(std::numeric_limits<T>::max());
  // gain per laser-off value: one multiplication per pixel instead of a division
  std::vector<Acc> gain(static_cast<size_t>(std::numeric_limits<T>::max()) + 1);
  for (size_t y = 0; y < gain.size(); ++y) {
    gain[y] = static_cast<Acc>(scale / std::max(static_cast<double>(y), floor));
  }
  const Acc* g = gain.data();
  for (int r = 0; r < rows; ++r) {
    const T* a = on.data + r * on_rs;
    const T* b = off.data + r * off_rs;
    T* dst = out + static_cast<std::ptrdiff_t>(r) * cols;
    for (int c = 0; c < cols; ++c) {
      const T x = a[c * on_cs], y = b[c * off_cs];
      // branch-free: max(0, x - y) is 0 where x <= y, and d >= 0.5 so truncating rounds
      const Acc d = std::min(
          tmax, std::max(Acc(0), static_cast<Acc>(x) - static_cast<Acc>(y)) * g[y] + Acc(0.5));
      dst[c] = static_cast<T>(static_cast<int>(d));  // int: a 64-bit conversion is ~10x slower
    }
  }
}

namespace {

// FindColumnPeaks' row loop with sums of type Acc (wide enough for k pixels of type T).
template <typename Acc, typename T>
void ColumnPeakRows(const ImageView<T>& image, int h, const std::vector<int>& src,
                    std::vector<int>* arg, std::vector<double>* best_sum) {
  const int rows = image.rows, cols = image.cols, k = 2 * h + 1;
  const int n = cols + k - 1;
  std::vector<Acc> padded(static_cast<size_t>(n)), sum(static_cast<size_t>(cols));
  std::vector<Acc> best(static_cast<size_t>(cols), 0);
  const std::ptrdiff_t rs = image.row_stride, cs = image.col_stride;
  Acc* pad = padded.data();
  Acc* sm = sum.data();
  Acc* bst = best.data();
  int* ag = arg->data();
  for (int r = 0; r < rows; ++r) {
    const T* a = image.data + r * rs;
    for (int i = 0; i < h && i < n; ++i) pad[i] = a[src[static_cast<size_t>(i)] * cs];
    if (cs == 1) {
      for (int c = 0; c < cols; ++c) pad[h + c] = a[c];
    } else {
      for (int c = 0; c < cols; ++c) pad[h + c] = a[c * cs];
    }
    for (int i = h + cols; i < n; ++i) pad[i] = a[src[static_cast<size_t>(i)] * cs];
    for (int c = 0; c < cols; ++c) sm[c] = pad[c];
    for (int j = 1; j < k; ++j) {
      for (int c = 0; c < cols; ++c) sm[c] = static_cast<Acc>(sm[c] + pad[c + j]);
    }
    // strictly greater: a tie keeps the first row (np.argmax); an all-zero column row 0
    for (int c = 0; c < cols; ++c) {
      const bool gt = sm[c] > bst[c];
      bst[c] = gt ? sm[c] : bst[c];
      ag[c] = gt ? r : ag[c];
    }
  }
  for (int c = 0; c < cols; ++c) (*best_sum)[static_cast<size_t>(c)] = bst[c];
}

}  // namespace

template <typename T>
ColumnPeaks FindColumnPeaks(const ImageView<T>& image, int half_width) {
  RequireImage(image, "the image");
  if (half_width < 0 || half_width > 1000) {
    throw std::invalid_argument("half_width must lie in 0..1000, got " +
                                std::to_string(half_width));
  }
  const int cols = image.cols, h = half_width, k = 2 * half_width + 1;
  // OpenCV's borderInterpolate for BORDER_REFLECT_101: the column read at padded index i
  std::vector<int> src(static_cast<size_t>(cols + k - 1));
  for (size_t i = 0; i < src.size(); ++i) {
    int p = static_cast<int>(i) - h;
    while (cols > 1 && (p < 0 || p >= cols)) p = p < 0 ? -p : 2 * (cols - 1) - p;
    src[i] = cols > 1 ? p : 0;
  }
  std::vector<int> arg(static_cast<size_t>(cols), 0);
  std::vector<double> sum(static_cast<size_t>(cols), 0.0);
  // the narrowest sums that hold k pixels (more lanes per vector): 16 bits for 8-bit
  // images and up to 257 pixels, else 32 (k <= 2001 pixels below 2^16 each)
  if (sizeof(T) == 1 && k <= 257) {
    ColumnPeakRows<std::uint16_t>(image, h, src, &arg, &sum);
  } else {
    ColumnPeakRows<std::uint32_t>(image, h, src, &arg, &sum);
  }
  ColumnPeaks out;
  out.row = Eigen::Map<const Eigen::VectorXi>(arg.data(), cols);
  out.sum = Eigen::Map<const Eigen::VectorXd>(sum.data(), cols);
  return out;
}

template <typename T>
double EstimateDifferenceNoise(const ImageView<T>& image, int row_step) {
  RequireImage(image, "the image");
  row_step = std::max(1, row_step);
  const size_t bins = static_cast<size_t>(std::numeric_limits<T>::max()) + 1;
  // four interleaved histograms: a background of a few grey levels increments the same bins
  // over and over, and one histogram would wait on each increment's store
  std::vector<std::uint32_t> part(4 * bins, 0);
  std::vector<std::uint64_t> hist(bins, 0);
  std::uint64_t n = 0, since = 0;
  std::uint32_t* h0 = part.data();
  std::uint32_t* h1 = h0 + bins;
  std::uint32_t* h2 = h1 + bins;
  std::uint32_t* h3 = h2 + bins;
  for (int r = 0; r < image.rows; r += row_step) {
    const T* a = image.data + r * image.row_stride;
    const std::ptrdiff_t cs = image.col_stride;
    int c = 0;
    for (; c + 4 <= image.cols; c += 4) {
      ++h0[a[c * cs]];
      ++h1[a[(c + 1) * cs]];
      ++h2[a[(c + 2) * cs]];
      ++h3[a[(c + 3) * cs]];
    }
    for (; c < image.cols; ++c) ++h0[a[c * cs]];
    n += static_cast<std::uint64_t>(image.cols);
    since += static_cast<std::uint64_t>(image.cols);
    if (since >= (std::uint64_t{1} << 31)) {  // before a 32-bit count could overflow
      for (size_t i = 0; i < bins; ++i) {
        hist[i] += std::uint64_t{h0[i]} + h1[i] + h2[i] + h3[i];
        h0[i] = h1[i] = h2[i] = h3[i] = 0;
      }
      since = 0;
    }
  }
  for (size_t i = 0; i < bins; ++i) hist[i] += std::uint64_t{h0[i]} + h1[i] + h2[i] + h3[i];
  // first guess: for X ~ N(0, s^2), P(max(0, X) <= s) = 0.8413
  const double target = 0.8413 * static_cast<double>(n);
  std::uint64_t cum = 0;
  size_t s0 = 0;
  for (; s0 < hist.size(); ++s0) {
    cum += hist[s0];
    if (static_cast<double>(cum) >= target) break;
  }
  const size_t cut = std::min(hist.size() - 1, std::max<size_t>(2, 4 * s0));
  double sum2 = 0.0;
  std::uint64_t count = 0;
  for (size_t x = 0; x <= cut; ++x) {
    sum2 += static_cast<double>(hist[x]) * static_cast<double>(x) * static_cast<double>(x);
    count += hist[x];
  }
  const double var = count > 0 ? 2.0 * sum2 / static_cast<double>(count) : 0.0;
  return std::sqrt(var + 1.0 / 6.0);
}

// One output line: acc = sum_k w[k] line[s + k], the inner loop over contiguous floats.
void SumShifted(const float* __restrict line, const float* __restrict w, int taps, int n,
                float* __restrict acc) {
  for (int s = 0; s < n; ++s) acc[s] = w[0] * line[s];
  for (int k = 1; k < taps; ++k) {
    const float wk = w[k];
    const float* __restrict b = line + k;
    for (int s = 0; s < n; ++s) acc[s] += wk * b[s];
  }
}

// The scan view smoothed across scan lines (along the stripe) with the kernel g (edges
// replicated), stored with adjacent scan lines contiguous (ss = 1, sp = n_scan). Per profile
// line a sum of shifted copies, so that the inner loops run over contiguous scan lines.
template <typename T>
std::vector<float> SmoothAlong(const ScanView<T>& v, const Kernels& g) {
  const int n = v.n_scan;
  const int r = g.radius;
  std::vector<float> out(static_cast<size_t>(n) * static_cast<size_t>(v.n_prof));
  std::vector<float> line(static_cast<size_t>(n + 2 * r));
  const std::vector<float> w(g.g0.begin(), g.g0.end());
  for (int p = 0; p < v.n_prof; ++p) {
    // the profile line padded by r replicated values either side
    const T* src = v.data + p * v.sp;
    float* mid = line.data() + r;
    if (v.ss == 1) {
      for (int s = 0; s < n; ++s) mid[s] = static_cast<float>(src[s]);
    } else {
      for (int s = 0; s < n; ++s) mid[s] = static_cast<float>(src[s * v.ss]);
    }
    for (int i = 1; i <= r; ++i) {
      mid[-i] = mid[0];
      mid[n - 1 + i] = mid[n - 1];
    }
    SumShifted(line.data(), w.data(), 2 * r + 1, n,
               out.data() + static_cast<size_t>(p) * static_cast<size_t>(n));
  }
  return out;
}

template <typename T>
Runs DetectRuns(const ScanView<T>& v, T thr) {
  Runs runs(v.n_scan);
  if (std::abs(v.ss) <= std::abs(v.sp)) {
    if (v.ss == 1) {
      DetectStreaming<T, true>(v, thr, &runs);
    } else {
      DetectStreaming<T, false>(v, thr, &runs);
    }
  } else if (v.sp == 1) {
    DetectPerLine<T, true>(v, thr, &runs);
  } else {
    DetectPerLine<T, false>(v, thr, &runs);
  }
  return runs;
}

template <typename T>
StripeResult ExtractStripe(const ImageView<T>& image, const StripeOptions& o) {
  RequireImage(image, "the image");
  ValidateOptions<T>(o);
  const ScanView<T> v = MakeScanView(image, o.direction);
  StripeResult res;
  res.noise = o.noise >= 0.0 ? o.noise : EstimateDifferenceNoise(image);
  // The detection image: the image itself, or smoothed along the stripe, where the noise
  // is lower by the kernel's gain sqrt(sum g^2) and a faint stripe clears the threshold.
  const bool smoothed = o.detect_sigma_along > 0.0;
  std::vector<float> smooth;
  ScanView<float> dv{nullptr, v.n_scan, v.n_prof, 1, v.n_scan};
  double noise_gain = 1.0;
  if (smoothed) {
    const Kernels g = MakeKernels(o.detect_sigma_along);
    noise_gain = std::sqrt(g.sum_sq0);
    smooth = SmoothAlong(v, g);
    dv.data = smooth.data();
  }
  if (o.threshold >= 0.0) {
    res.threshold = o.threshold;
  } else {
    double mx = 0.0;
    if (smoothed) {
      for (size_t i = 0; i < smooth.size(); i += 4) mx = std::max(mx, double{smooth[i]});
    } else {
      T m = 0;
      for (int r = 0; r < image.rows; r += 4) {
        for (int c = 0; c < image.cols; ++c) m = std::max(m, image(r, c));
      }
      mx = static_cast<double>(m);
    }
    res.threshold = std::max(5.0 * res.noise * noise_gain, 0.15 * mx);
  }
  // v > threshold  <=>  v > floor(threshold) for integer pixel values
  const double tmax = static_cast<double>(std::numeric_limits<T>::max());
  const Runs runs = smoothed
                        ? DetectRuns(dv, static_cast<float>(res.threshold))
                        : DetectRuns(v, static_cast<T>(std::min(std::floor(res.threshold), tmax)));

  const int n = v.n_scan;
  res.centre.setConstant(n, kNaN);
  res.intensity.setConstant(n, kNaN);
  res.width.setConstant(n, kNaN);
  res.sigma.setConstant(n, kNaN);
  res.residual.setConstant(n, kNaN);
  res.status.setConstant(n, static_cast<std::uint8_t>(StripeStatus::kNone));
  res.num_peaks.setZero(n);
  const StegerKernels kernels =
      o.method == StripeMethod::kSteger
          ? MakeStegerKernels(o.steger_sigma,
                              o.steger_sigma_along > 0.0 ? o.steger_sigma_along : o.steger_sigma)
          : StegerKernels();
  const int limit = static_cast<int>(std::ceil(o.max_width)) + 2;

  for (int s = 0; s < n; ++s) {
    const int count = runs.count[s];
    if (count == 0) continue;
    if (count > kMaxRuns) {
      res.status[s] = static_cast<std::uint8_t>(StripeStatus::kMultiple);
      res.num_peaks[s] = count;
      continue;
    }
    Peak best_valid, best_wide, best_narrow;
    int n_valid = 0, n_wide = 0, n_narrow = 0;
    double second = 0.0;  // strongest competitor other than best_valid
    Peak peaks[kMaxRuns];
    for (int k = 0; k < count; ++k) {
      const size_t idx = static_cast<size_t>(s) * kMaxRuns + k;
      peaks[k] = smoothed ? MeasurePeak(dv, s, runs.begin[idx], runs.end[idx], limit)
                          : MeasurePeak(v, s, runs.begin[idx], runs.end[idx], limit);
    }
    // A run whose half-maximum span holds a stronger run's peak is that peak's shoulder
    // (noise splitting a wide profile where it crosses the threshold), not a peak.
    bool shoulder[kMaxRuns] = {};
    for (int k = 0; k < count; ++k) {
      for (int k2 = 0; k2 < count && !shoulder[k]; ++k2) {
        const bool stronger =
            peaks[k2].value > peaks[k].value || (peaks[k2].value == peaks[k].value && k2 < k);
        shoulder[k] =
            k2 != k && stronger && peaks[k2].m >= peaks[k].lo && peaks[k2].m <= peaks[k].hi;
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
    res.num_peaks[s] = n_valid + n_wide;
    if (n_valid == 0) {
      const Peak& shown = n_wide > 0 ? best_wide : best_narrow;
      res.status[s] =
          static_cast<std::uint8_t>(n_wide > 0 ? StripeStatus::kTooWide : StripeStatus::kTooNarrow);
      res.intensity[s] = shown.value;
      res.width[s] = shown.width;
      continue;
    }
    for (int k = 0; k < count; ++k) {
      const Peak& pk = peaks[k];
      const bool competitor = pk.width >= o.min_width && !shoulder[k];
      const bool is_best = pk.b == best_valid.b;
      if (competitor && !is_best) second = std::max(second, pk.value);
    }
    res.intensity[s] = best_valid.value;
    res.width[s] = best_valid.width;
    if (res.num_peaks[s] > 1 && !(o.dominance >= 1.0 && best_valid.value >= o.dominance * second)) {
      res.status[s] = static_cast<std::uint8_t>(StripeStatus::kMultiple);
      continue;
    }
    Centre c;
    switch (o.method) {
      case StripeMethod::kCentroid:
        c = CentroidCentre(v, s, best_valid, res.threshold, res.noise);
        break;
      case StripeMethod::kGaussian:
        c = GaussianCentre(v, s, best_valid, res.noise);
        break;
      case StripeMethod::kSteger:
        c = StegerCentre(v, s, best_valid, kernels, res.noise);
        break;
    }
    if (!c.ok) {
      res.status[s] = static_cast<std::uint8_t>(StripeStatus::kFitFailed);
      continue;
    }
    res.status[s] = static_cast<std::uint8_t>(StripeStatus::kFound);
    res.centre[s] = c.centre;
    res.sigma[s] = c.sigma;
    res.residual[s] = Asymmetry(v, s, c.centre, best_valid.width, best_valid.value);
  }
  return res;
}

template <typename T>
void AssessStripe(const ImageView<T>& image, const ImageView<T>& on, const ImageView<T>& off,
                  StripeDirection direction, const StripeQualityOptions& o, StripeResult* res) {
  RequireImage(image, "the image");
  for (const ImageView<T>* other : {&on, &off}) {
    if (other->data != nullptr && (other->rows != image.rows || other->cols != image.cols)) {
      std::ostringstream msg;
      msg << "the laser-" << (other == &on ? "on" : "off") << " image is " << other->cols << " x "
          << other->rows << " pixels but the stripe's image is " << image.cols << " x "
          << image.rows;
      throw std::invalid_argument(msg.str());
    }
  }
  if (!std::isfinite(o.albedo_step) || !(o.hump >= 0.0 && o.hump <= 1.0) ||
      !(o.dip > 0.0 && o.dip <= 1.0) ||
      !(o.albedo_offset >= 0.0 && std::isfinite(o.albedo_offset))) {
    std::ostringstream msg;
    msg << "quality options must satisfy albedo_step finite, 0 <= hump <= 1, 0 < dip <= 1, "
           "albedo_offset finite and >= 0; got "
        << o.albedo_step << ", " << o.hump << ", " << o.dip << ", " << o.albedo_offset;
    throw std::invalid_argument(msg.str());
  }
  const ScanView<T> v = MakeScanView(image, direction);
  const int n = v.n_scan;
  if (res == nullptr || res->centre.size() != n || res->status.size() != n ||
      res->width.size() != n) {
    std::ostringstream msg;
    msg << "the stripe result does not belong to this image: it has "
        << (res == nullptr ? 0 : res->status.size()) << " scan lines, the image " << n;
    throw std::invalid_argument(msg.str());
  }
  const ScanView<T> von = MakeScanView(on.data != nullptr ? on : image, direction);
  const bool with_off = off.data != nullptr && o.albedo_step > 1.0;
  const ScanView<T> voff = MakeScanView(with_off ? off : image, direction);
  const double tmax = static_cast<double>(std::numeric_limits<T>::max());
  const double thr = res->threshold;
  std::vector<double> y;
  for (int s = 0; s < n; ++s) {
    if (res->status[s] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    const double c = res->centre[s], w = res->width[s];
    auto set = [&](StripeStatus st) { res->status[s] = static_cast<std::uint8_t>(st); };
    if (c - w < -0.5 || c + w > v.n_prof - 0.5) {
      set(StripeStatus::kClipped);
      continue;
    }
    const int lo = std::max(0, static_cast<int>(std::ceil(c - 0.5 * w)));
    const int hi = std::min(v.n_prof - 1, static_cast<int>(std::floor(c + 0.5 * w)));
    bool saturated = false;
    for (int p = lo; p <= hi && !saturated; ++p) saturated = von.at(s, p) >= tmax;
    if (saturated) {
      set(StripeStatus::kSaturated);
      continue;
    }
    if (o.hump > 0.0) {
      // the run above threshold around the centre, smoothed at FWHM / 6 (speckle)
      const int m = std::clamp(static_cast<int>(std::lround(c)), 0, v.n_prof - 1);
      int b = m, e = m;
      while (b > 0 && v.at(s, b - 1) > thr) --b;
      while (e < v.n_prof - 1 && v.at(s, e + 1) > thr) ++e;
      const double sg = std::max(0.5, w / 6.0);
      const int r = static_cast<int>(std::ceil(2.5 * sg));
      y.assign(static_cast<size_t>(e - b + 1), 0.0);
      for (int p = b; p <= e; ++p) {
        double acc = 0.0, wsum = 0.0;
        for (int k = -r; k <= r; ++k) {
          const int q = std::clamp(p + k, b, e);
          const double g = std::exp(-0.5 * k * k / (sg * sg));
          acc += g * v.at(s, q);
          wsum += g;
        }
        y[p - b] = acc / wsum;
      }
      int top = std::clamp(m, b, e) - b;
      const int reach = std::max(1, static_cast<int>(std::ceil(0.5 * w)));
      for (int q = std::max(0, top - reach); q <= std::min(e - b, top + reach); ++q) {
        if (y[q] > y[top]) top = q;
      }
      bool twin = false;
      for (int dir = -1; dir <= 1 && !twin; dir += 2) {
        double dip = y[top];
        for (int q = top + dir; q >= 0 && q <= e - b && !twin; q += dir) {
          dip = std::min(dip, y[q]);
          twin = y[q] >= o.hump * y[top] && dip < o.dip * y[q];
        }
      }
      if (twin) {
        set(StripeStatus::kDoublePeak);
        continue;
      }
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
        set(StripeStatus::kAlbedoEdge);
      }
    }
  }
}

void RefineStripeCentres(const ImageView<float>& image, StripeDirection direction,
                         const Eigen::VectorXd& noise, const StripeRefineOptions& o,
                         StripeResult* res) {
  RequireImage(image, "the image");
  if (!(o.speckle >= 0.0 && std::isfinite(o.speckle)) ||
      !(o.noise_floor >= 0.0 && std::isfinite(o.noise_floor)) || o.max_iterations < 1 ||
      !(o.tolerance > 0.0)) {
    std::ostringstream msg;
    msg << "refine options must satisfy speckle >= 0, noise_floor >= 0, max_iterations >= 1, "
           "tolerance > 0; got "
        << o.speckle << ", " << o.noise_floor << ", " << o.max_iterations << ", " << o.tolerance;
    throw std::invalid_argument(msg.str());
  }
  const ScanView<float> v = MakeScanView(image, direction);
  const int n = v.n_scan;
  if (res == nullptr || res->centre.size() != n || res->status.size() != n ||
      res->width.size() != n || noise.size() != n) {
    std::ostringstream msg;
    msg << "the stripe result and the noise must have one entry per scan line of the image (" << n
        << "), got " << (res == nullptr ? 0 : res->status.size()) << " and " << noise.size();
    throw std::invalid_argument(msg.str());
  }
  if (res->sigma.size() != n) res->sigma = Eigen::VectorXd::Constant(n, kNaN);
  const double k2 = o.speckle * o.speckle;
  for (int s = 0; s < n; ++s) {
    if (res->status[s] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    const double c0 = res->centre[s];
    const double sp = std::max(0.5, res->width[s] / (2.0 * std::sqrt(2.0 * std::log(2.0))));
    if (!std::isfinite(noise[s]) || noise[s] < 0.0 || !std::isfinite(c0) || !std::isfinite(sp)) {
      continue;
    }
    const int hw = static_cast<int>(std::ceil(4.0 * sp));
    if (c0 - hw - 1.0 < 0.0 || c0 + hw + 1.0 > v.n_prof - 1.0) continue;
    // the profile's peak: the largest sample within one profile sigma of the centre
    double peak = 0.0;
    for (int p = static_cast<int>(std::ceil(c0 - sp)); p <= static_cast<int>(std::floor(c0 + sp));
         ++p) {
      peak = std::max(peak, v.at(s, p));
    }
    const double add = std::max(noise[s], o.noise_floor * peak);
    const double a2 = add * add;
    auto set_failed = [&] {
      res->status[s] = static_cast<std::uint8_t>(StripeStatus::kFitFailed);
      res->centre[s] = kNaN;
      res->sigma[s] = kNaN;
    };
    if (!(peak > 0.0) || !(a2 > 0.0 || k2 > 0.0)) {
      set_failed();
      continue;
    }
    const double inv_s2 = 1.0 / (sp * sp);
    double c = c0, f_sum = 0.0, df_sum = 0.0, var_sum = 0.0;
    bool converged = false;
    for (int it = 0; it < o.max_iterations; ++it) {
      const int m = static_cast<int>(std::lround(c));
      if (m - hw < 0 || m + hw > v.n_prof - 1) break;
      f_sum = df_sum = var_sum = 0.0;
      for (int p = m - hw; p <= m + hw; ++p) {
        const double x = p - c;
        const double pp = peak * std::exp(-0.5 * x * x * inv_s2);  // P(x)
        const double dp = -x * inv_s2 * pp;                        // P'(x)
        const double ddp = (x * x * inv_s2 - 1.0) * inv_s2 * pp;   // P''(x)
        const double den = a2 + k2 * pp * pp;
        const double w = dp / den;
        const double dw = (ddp * den - dp * 2.0 * k2 * pp * dp) / (den * den);
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
      continue;
    }
    res->centre[s] = c;
    res->sigma[s] = std::sqrt(var_sum) / std::abs(df_sum);
  }
}

template void DifferenceImage<std::uint8_t>(const ImageView<std::uint8_t>&,
                                            const ImageView<std::uint8_t>&, std::uint8_t*,
                                            const DifferenceOptions&);
template void DifferenceImage<std::uint16_t>(const ImageView<std::uint16_t>&,
                                             const ImageView<std::uint16_t>&, std::uint16_t*,
                                             const DifferenceOptions&);
template StripeResult ExtractStripe<std::uint8_t>(const ImageView<std::uint8_t>&,
                                                  const StripeOptions&);
template StripeResult ExtractStripe<std::uint16_t>(const ImageView<std::uint16_t>&,
                                                   const StripeOptions&);
template void AssessStripe<std::uint8_t>(const ImageView<std::uint8_t>&,
                                         const ImageView<std::uint8_t>&,
                                         const ImageView<std::uint8_t>&, StripeDirection,
                                         const StripeQualityOptions&, StripeResult*);
template void AssessStripe<std::uint16_t>(const ImageView<std::uint16_t>&,
                                          const ImageView<std::uint16_t>&,
                                          const ImageView<std::uint16_t>&, StripeDirection,
                                          const StripeQualityOptions&, StripeResult*);
template ColumnPeaks FindColumnPeaks<std::uint8_t>(const ImageView<std::uint8_t>&, int);
template ColumnPeaks FindColumnPeaks<std::uint16_t>(const ImageView<std::uint16_t>&, int);

double SmoothingNoiseGain(double sigma) {
  if (!(sigma >= 0.5 && sigma <= 40.0)) {
    std::ostringstream msg;
    msg << "the smoothing scale must lie in [0.5, 40] px, got " << sigma;
    throw std::invalid_argument(msg.str());
  }
  return std::sqrt(MakeKernels(sigma).sum_sq0);
}

template double EstimateDifferenceNoise<std::uint8_t>(const ImageView<std::uint8_t>&, int);
template double EstimateDifferenceNoise<std::uint16_t>(const ImageView<std::uint16_t>&, int);

}  // namespace hmlvs
