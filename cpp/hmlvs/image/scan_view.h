// The scan line view of an image and what every scan line's work shares: the checks of the
// frames, Steger's derivative kernels, the runs above a threshold, and the two helpers of
// image.cpp the frame pipeline also calls. Internal (see scan_lines.h).
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

// The noise standard deviation of EstimateDifferenceNoise from the histogram of the sampled
// pixels (n of them).
double NoiseFromHistogram(const std::vector<std::uint64_t>& hist, std::uint64_t n);

// One output line: acc = sum_k w[k] line[s + k], the inner loop over contiguous floats.
void SumShifted(const float* __restrict line, const float* __restrict w, int taps, int n,
                float* __restrict acc);

}  // namespace hmlvs::scan
