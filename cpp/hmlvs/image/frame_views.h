// Views of the difference image of two frames computed where a scan line reads them: the
// (albedo-normalised) difference itself (DView) and its smoothing along the stripe (SView).
// Internal.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "hmlvs/image/difference_rule.h"
#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/scan_view.h"

namespace hmlvs::scan {

// The difference image (DifferenceRule) as scan lines s (columns) and profile p (rows).
template <typename T>
class DView {
 public:
  using Pixel = T;
  DView(const Frames<T>& f, const DifferenceRule<T>& rule)
      : n_scan(f.cols), n_prof(f.rows), f_(f), rule_(rule) {
    if constexpr (sizeof(T) == 1) rule.Table(&table_);
  }
  T Value(int s, int p) const {
    const T x = f_.On(p, s), y = f_.Off(p, s);
    if constexpr (sizeof(T) == 1) {
      return table_[(y << 8) | x];
    } else {
      return rule_.At(x, y);
    }
  }
  // the values of row p over columns c0 .. c1 - 1 (clamped to the image) as floats
  void Line(int p, int c0, int c1, float* out) const {
    const int a = std::clamp(c0, 0, n_scan), z = std::clamp(c1, a, n_scan);
    for (int c = c0; c < a; ++c)
      *out++ = static_cast<float>(Value(std::clamp(c, 0, n_scan - 1), p));
    if constexpr (sizeof(T) == 1) {
      const T* x = f_.on + p * f_.on_rs;
      const T* y = f_.off + p * f_.off_rs;
      const T* t = table_.data();
      for (int c = a; c < z; ++c) *out++ = static_cast<float>(t[(y[c] << 8) | x[c]]);
    } else {
      for (int c = a; c < z; ++c) *out++ = static_cast<float>(Value(c, p));
    }
    for (int c = z; c < c1; ++c)
      *out++ = static_cast<float>(Value(std::clamp(c, 0, n_scan - 1), p));
  }
  double at(int s, int p) const { return static_cast<double>(Value(s, p)); }
  double clamped(int s, int p) const {
    return at(std::clamp(s, 0, n_scan - 1), std::clamp(p, 0, n_prof - 1));
  }
  // Steger's derivatives as sums over the scan lines of the sums along each profile, which
  // neighbouring scan lines share (memoised per scan line and row); the same values as
  // scan::SmoothedDerivatives up to rounding.
  Derivatives Deriv(const Kernels& ks, const Kernels& kp, int s, int p) const {
    if (&kp != memo_kernels_) {
      memo_kernels_ = &kp;
      memo_.assign(static_cast<size_t>(n_scan) * kWays, Slot());
    }
    Derivatives d{0, 0, 0, 0, 0};
    const int rs = ks.radius;
    for (int ds = -rs; ds <= rs; ++ds) {
      const Slot& v = Along(kp, std::clamp(s + ds, 0, n_scan - 1), p);
      d.gs += ks.g1[ds + rs] * v.v0;
      d.gp += ks.g0[ds + rs] * v.v1;
      d.gss += ks.g2[ds + rs] * v.v0;
      d.gpp += ks.g0[ds + rs] * v.v2;
      d.gsp += ks.g1[ds + rs] * v.v1;
    }
    return d;
  }
  int n_scan, n_prof;

 private:
  static constexpr int kWays = 8;
  struct Slot {
    int p = std::numeric_limits<int>::min();
    double v0 = 0, v1 = 0, v2 = 0;
  };
  const Slot& Along(const Kernels& kp, int t, int p) const {
    Slot& slot = memo_[static_cast<size_t>(t) * kWays + (static_cast<unsigned>(p) % kWays)];
    if (slot.p != p) {
      slot.p = p;
      slot.v0 = slot.v1 = slot.v2 = 0.0;
      const int rp = kp.radius;
      for (int dp = -rp; dp <= rp; ++dp) {
        const double x = at(t, std::clamp(p + dp, 0, n_prof - 1));
        slot.v0 += kp.g0[dp + rp] * x;
        slot.v1 += kp.g1[dp + rp] * x;
        slot.v2 += kp.g2[dp + rp] * x;
      }
    }
    return slot;
  }
  const Frames<T>& f_;
  const DifferenceRule<T>& rule_;
  std::vector<T> table_;
  mutable const Kernels* memo_kernels_ = nullptr;
  mutable std::vector<Slot> memo_;
};

// The difference smoothed along the stripe (across the columns, edges replicated) with the
// kernel of ExtractStripe's detect_sigma_along, in its single precision and order of sums.
template <typename T>
class SView {
 public:
  using Pixel = float;
  SView(const DView<T>& d, const Kernels& g, Plane* plane)
      : n_scan(d.n_scan), n_prof(d.n_prof), d_(d), w_(g.g0.begin(), g.g0.end()), plane_(plane) {
    r_ = g.radius;
    line_.resize(static_cast<size_t>(n_scan + kSb + 2 * r_));
    plane_->Reset(n_prof, n_scan);
  }
  double at(int s, int p) const { return Value(s, p); }
  double clamped(int s, int p) const {
    return at(std::clamp(s, 0, n_scan - 1), std::clamp(p, 0, n_prof - 1));
  }
  float Value(int s, int p) const {
    const int b = s / kSb;
    if (!plane_->Has(p, b)) Compute(p, b, b);
    return plane_->Row(p)[s];
  }
  // the block's values (computed if not yet) from column b * kSb on
  const float* Block(int p, int b) const {
    if (!plane_->Has(p, b)) Compute(p, b, b);
    return plane_->Row(p) + b * kSb;
  }
  // blocks b0 .. b1 of row p computed (those not yet), each run of consecutive ones at once:
  // the difference read once per column of the run, not once per block it reaches
  void Span(int p, int b0, int b1) const {
    for (int b = b0; b <= b1;) {
      if (plane_->Has(p, b)) {
        ++b;
        continue;
      }
      int e = b;
      while (e < b1 && !plane_->Has(p, e + 1)) ++e;
      Compute(p, b, e);
      b = e + 1;
    }
  }
  int radius() const { return r_; }
  int n_scan, n_prof;

 private:
  // blocks b0 .. b1 of row p: per value the same sums as a block alone
  void Compute(int p, int b0, int b1) const {
    const int c0 = b0 * kSb, c1 = std::min((b1 + 1) * kSb, n_scan);
    d_.Line(p, c0 - r_, c1 + r_, line_.data());
    SumShifted(line_.data(), w_.data(), 2 * r_ + 1, c1 - c0, plane_->Row(p) + c0);
    for (int b = b0; b <= b1; ++b) plane_->Mark(p, b);
  }
  const DView<T>& d_;
  std::vector<float> w_;
  Plane* plane_;
  int r_ = 0;
  mutable std::vector<float> line_;
};

}  // namespace hmlvs::scan
