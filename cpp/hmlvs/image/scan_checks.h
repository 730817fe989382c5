// What follows a found scan line: AssessStripe's quality checks and RefineStripeCentres'
// noise-weighted centre. Internal (see scan_lines.h).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "hmlvs/image/image.h"
#include "hmlvs/image/scan_view.h"

namespace hmlvs::scan {

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

// RefineLine's state on one scan line: its setup (RefineStart) and the iteration's centre c
// and sums.
struct RefineState {
  double c0 = 0.0, sp = 0.0, inv_s2 = 0.0, peak = 0.0, a2 = 0.0, k2 = 0.0, shrink = 0.0;
  int hw = 0;
  double c = 0.0, f_sum = 0.0, df_sum = 0.0, var_sum = 0.0;
  bool converged = false;
};

inline void SetRefineFailed(int s, StripeResult* res) {
  res->status[s] = static_cast<std::uint8_t>(StripeStatus::kFitFailed);
  res->centre[s] = kNaN;
  res->sigma[s] = kNaN;
}

// RefineLine's setup of scan line s: false when the scan line keeps its centre (no noise, or
// the window leaves the image) or failed (kFitFailed: no peak or no weights).
template <class V>
bool RefineStart(const V& v, int s, double noise, const StripeRefineOptions& o, StripeResult* res,
                 RefineState* st) {
  st->k2 = o.speckle * o.speckle;
  const double c0 = res->centre[s];
  const double sp = std::max(0.5, res->width[s] / (2.0 * std::sqrt(2.0 * std::log(2.0))));
  if (!std::isfinite(noise) || noise < 0.0 || !std::isfinite(c0) || !std::isfinite(sp))
    return false;
  const int hw = static_cast<int>(std::ceil(4.0 * sp));
  if (c0 - hw - 1.0 < 0.0 || c0 + hw + 1.0 > v.n_prof - 1.0) return false;
  // the profile's peak: the largest sample within one profile sigma of the centre
  double peak = 0.0;
  for (int p = static_cast<int>(std::ceil(c0 - sp)); p <= static_cast<int>(std::floor(c0 + sp));
       ++p) {
    peak = std::max(peak, v.at(s, p));
  }
  const double add = std::max(noise, o.noise_floor * peak);
  st->a2 = add * add;
  if (!(peak > 0.0) || !(st->a2 > 0.0 || st->k2 > 0.0)) {
    SetRefineFailed(s, res);
    return false;
  }
  st->c0 = st->c = c0;
  st->sp = sp;
  st->hw = hw;
  st->peak = peak;
  st->inv_s2 = 1.0 / (sp * sp);
  // P(x) = peak exp(-x^2 / (2 sp^2)) at x = p - c, by the recurrence exp(-(x + 1)^2 / 2 s2)
  // = exp(-x^2 / 2 s2) exp(-(2 x + 1) / 2 s2), whose factor shrinks by exp(-1 / s2) a step
  st->shrink = std::exp(-st->inv_s2);
  return true;
}

// An iteration's window about m = round(c) and the recurrence's start at its first pixel
// (P there, and its first factor); false when the window leaves the image.
inline bool RefineWindow(const RefineState& st, int n_prof, int* m, double* g, double* ratio) {
  *m = static_cast<int>(std::lround(st.c));
  if (*m - st.hw < 0 || *m + st.hw > n_prof - 1) return false;
  const double x0 = (*m - st.hw) - st.c;
  *g = st.peak * std::exp(-0.5 * x0 * x0 * st.inv_s2);
  *ratio = std::exp(-0.5 * (2.0 * x0 + 1.0) * st.inv_s2);
  return true;
}

// An iteration's step from its sums: false when the iteration ends (converged, or no step).
inline bool RefineStep(RefineState* st, const StripeRefineOptions& o) {
  if (!(st->df_sum < 0.0 || st->df_sum > 0.0) || !std::isfinite(st->f_sum)) return false;
  const double step = std::clamp(-st->f_sum / st->df_sum, -0.5, 0.5);
  st->c += step;
  if (std::abs(step) < o.tolerance) {
    st->converged = true;
    return false;
  }
  return true;
}

// The refined centre and its sigma, or kFitFailed (no convergence, or more than half a
// profile sigma from the start).
inline void RefineFinish(const RefineState& st, int s, StripeResult* res) {
  if (!st.converged || !(std::abs(st.c - st.c0) <= 0.5 * st.sp)) {
    SetRefineFailed(s, res);
    return;
  }
  res->centre[s] = st.c;
  res->sigma[s] = std::sqrt(st.var_sum) / std::abs(st.df_sum);
}

// The weight w of a profile sample at offset x from the centre (P(x) = pp) in the centre's
// fit, dw, its derivative in the centre, and den, the sample's variance factor: for one scan line
// (double) or several at once (RefineVector, one lane per line), the same operations in the same
// order, so the same values.
template <typename V, typename C>
inline void ProfileWeight(const V& x, const V& pp, const C& inv_s2, const C& a2, const C& k2, V* w,
                          V* dw, V* den) {
  const V dp = -x * inv_s2 * pp;                       // P'(x)
  const V ddp = (x * x * inv_s2 - 1.0) * inv_s2 * pp;  // P''(x)
  *den = a2 + k2 * pp * pp;
  const V inv = 1.0 / *den;
  *w = dp * inv;
  *dw = (ddp - dp * 2.0 * k2 * pp * dp * inv) * inv;
}

// RefineStripeCentres on scan line s (kFound, additive noise `noise`): updates the centre,
// sigma and status of `res` at s. `v` holds the image as floats.
template <class V>
void RefineLine(const V& v, int s, double noise, const StripeRefineOptions& o, StripeResult* res) {
  RefineState st;
  if (!RefineStart(v, s, noise, o, res, &st)) return;
  const double inv_s2 = st.inv_s2, a2 = st.a2, k2 = st.k2, shrink = st.shrink;
  for (int it = 0; it < o.max_iterations; ++it) {
    int m = 0;
    double g = 0.0, ratio = 0.0;
    if (!RefineWindow(st, v.n_prof, &m, &g, &ratio)) break;
    double f_sum = 0.0, df_sum = 0.0, var_sum = 0.0;
    const double cc = st.c;
    for (int p = m - st.hw; p <= m + st.hw; ++p, g *= ratio, ratio *= shrink) {
      const double x = p - cc;
      double w, dw, den;
      ProfileWeight(x, g, inv_s2, a2, k2, &w, &dw, &den);
      const double y = v.at(s, p);
      f_sum += w * y;
      df_sum -= dw * y;  // d/dc of w(p - c) y
      var_sum += w * w * den;
    }
    st.f_sum = f_sum;
    st.df_sum = df_sum;
    st.var_sum = var_sum;
    if (!RefineStep(&st, o)) break;
  }
  RefineFinish(st, s, res);
}

}  // namespace hmlvs::scan
