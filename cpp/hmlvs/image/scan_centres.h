// One scan line of ExtractStripe: its peaks (position, value, FWHM), the choice of one, and
// its sub-pixel centre by the centroid, the three-point Gaussian or Steger's line detector.
// Internal (see scan_lines.h).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "hmlvs/image/image.h"
#include "hmlvs/image/scan_view.h"

namespace hmlvs::scan {

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

// Throws std::invalid_argument, with a sentence naming the option, for invalid options.
void ValidateOptions(const StripeOptions& o);

// A result of n scan lines with nothing found yet (threshold and noise as given).
void ResetResult(int n, StripeResult* res);

// Scan line s of ExtractStripe: its `count` runs above the threshold [begin[k], end[k]) of
// the detection view dv -> peaks (sized on dv), the choice of one, its status and its centre
// (measured on v). `res` holds threshold and noise and receives scan line s; its residual
// (the profile's asymmetry) unless `residual` is false.
template <class V, class DV>
void ScanLine(const V& v, const DV& dv, int s, const int* begin, const int* end, int count,
              const StripeOptions& o, const StegerKernels& kernels, StripeResult* res,
              bool residual = true) {
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
  if (residual) res->residual[s] = Asymmetry(v, s, c.centre, best_valid.width, best_valid.value);
}

}  // namespace hmlvs::scan
