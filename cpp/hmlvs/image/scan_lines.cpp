// The option checks and helpers of the scan line work that are not templates (scan_lines.h).
#include "hmlvs/image/scan_lines.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "hmlvs/image/frame_buffers.h"

namespace hmlvs {

namespace scan {

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

void ResetResult(int n, StripeResult* res) {
  res->centre.setConstant(n, kNaN);
  res->intensity.setConstant(n, kNaN);
  res->width.setConstant(n, kNaN);
  res->sigma.setConstant(n, kNaN);
  res->residual.setConstant(n, kNaN);
  res->status.setConstant(n, static_cast<std::uint8_t>(StripeStatus::kNone));
  res->num_peaks.setZero(n);
}

void ValidateQualityOptions(const StripeQualityOptions& o) {
  if (!std::isfinite(o.albedo_step) || !(o.hump >= 0.0 && o.hump <= 1.0) ||
      !(o.dip > 0.0 && o.dip <= 1.0) ||
      !(o.albedo_offset >= 0.0 && std::isfinite(o.albedo_offset))) {
    std::ostringstream msg;
    msg << "quality options must satisfy albedo_step finite, 0 <= hump <= 1, 0 < dip <= 1, "
           "albedo_offset finite and >= 0; got "
        << o.albedo_step << ", " << o.hump << ", " << o.dip << ", " << o.albedo_offset;
    throw std::invalid_argument(msg.str());
  }
}

void ValidateRefineOptions(const StripeRefineOptions& o) {
  if (!(o.speckle >= 0.0 && std::isfinite(o.speckle)) ||
      !(o.noise_floor >= 0.0 && std::isfinite(o.noise_floor)) || o.max_iterations < 1 ||
      !(o.tolerance > 0.0)) {
    std::ostringstream msg;
    msg << "refine options must satisfy speckle >= 0, noise_floor >= 0, max_iterations >= 1, "
           "tolerance > 0; got "
        << o.speckle << ", " << o.noise_floor << ", " << o.max_iterations << ", " << o.tolerance;
    throw std::invalid_argument(msg.str());
  }
}

double NoiseFromHistogram(const std::vector<std::uint64_t>& hist, std::uint64_t n) {
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

namespace {

// SumShifted on outputs s0 .. n - 1, one at a time (the same operations in the same order)
void SumShiftedTail(const float* line, const float* w, int taps, int s0, int n, float* acc) {
  for (int s = s0; s < n; ++s) {
    float a = w[0] * line[s];
    for (int k = 1; k < taps; ++k) a += w[k] * line[s + k];
    acc[s] = a;
  }
}

// SumShifted four vectors of kLanes floats at a time, then one, up to the last whole vector;
// returns the first output left for SumShiftedTail. V is a GCC vector type read and written
// unaligned (may_alias, aligned(4): declared here, since a template argument would lose its
// attributes); the body is inlined into each entry point below and compiled for its target:
// 4 lanes in SSE2 registers, 8 in AVX2 ones. Every output is the same products summed in the
// same order as in SumShiftedTail.
template <int kLanes>
__attribute__((always_inline)) inline int SumShiftedVectors(const float* line, const float* w,
                                                            int taps, int n, float* acc) {
  typedef float V __attribute__((vector_size(4 * kLanes), aligned(4), may_alias));
  using In = const V*;  // unaligned loads of kLanes floats
  int s = 0;
  for (; s + 4 * kLanes <= n; s += 4 * kLanes) {
    const float* l = line + s;
    V a0 = w[0] * *In(l), a1 = w[0] * *In(l + kLanes);
    V a2 = w[0] * *In(l + 2 * kLanes), a3 = w[0] * *In(l + 3 * kLanes);
    for (int k = 1; k < taps; ++k) {
      const float* b = l + k;
      a0 += w[k] * *In(b);
      a1 += w[k] * *In(b + kLanes);
      a2 += w[k] * *In(b + 2 * kLanes);
      a3 += w[k] * *In(b + 3 * kLanes);
    }
    *reinterpret_cast<V*>(acc + s) = a0;
    *reinterpret_cast<V*>(acc + s + kLanes) = a1;
    *reinterpret_cast<V*>(acc + s + 2 * kLanes) = a2;
    *reinterpret_cast<V*>(acc + s + 3 * kLanes) = a3;
  }
  for (; s + kLanes <= n; s += kLanes) {
    V a = w[0] * *In(line + s);
    for (int k = 1; k < taps; ++k) a += w[k] * *In(line + s + k);
    *reinterpret_cast<V*>(acc + s) = a;
  }
  return s;
}

#if defined(HMLVS_AVX2)
__attribute__((target("avx2"))) void SumShiftedAvx2(const float* line, const float* w, int taps,
                                                    int n, float* acc) {
  SumShiftedTail(line, w, taps, SumShiftedVectors<8>(line, w, taps, n, acc), n, acc);
}
#endif

}  // namespace

// One output line: acc = sum_k w[k] line[s + k], 16 outputs at a time in registers (SSE2; 32
// with AVX2), each the same sums in the same order.
void SumShifted(const float* __restrict line, const float* __restrict w, int taps, int n,
                float* __restrict acc) {
#if defined(HMLVS_AVX2)
  if (UseAvx2()) {
    SumShiftedAvx2(line, w, taps, n, acc);
    return;
  }
#endif
  SumShiftedTail(line, w, taps, SumShiftedVectors<4>(line, w, taps, n, acc), n, acc);
}

}  // namespace scan

}  // namespace hmlvs
