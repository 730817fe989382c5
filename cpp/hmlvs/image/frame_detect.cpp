// DetectRuns and ScanLines (frame_detect.h).
#include "hmlvs/image/frame_detect.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "hmlvs/image/scan_centres.h"

namespace hmlvs::scan {

namespace {

// Per laser-off value y, the largest plain difference x whose bound (DifferenceRule::Bound,
// times `factor`) stays at or below `threshold`: a block whose largest difference is at most
// that for its smallest laser-off value holds no value above the threshold. Computed per value
// on first use.
template <typename T>
class Limits {
 public:
  Limits(const DifferenceRule<T>& rule, double threshold, double factor)
      : rule_(rule),
        threshold_(threshold),
        factor_(factor),
        lim_(static_cast<size_t>(std::numeric_limits<T>::max()) + 1, -2) {
    if constexpr (sizeof(T) == 1) {
      for (int y = 0; y < 256; ++y) Compute(static_cast<T>(y));
    }
  }
  int operator[](T y) const {
    if constexpr (sizeof(T) == 1) {
      return lim_[y];
    } else {
      return Compute(y);
    }
  }

 private:
  int Compute(T y) const {
    int& v = lim_[y];
    if (v == -2) {
      // the bound grows with x: the last x in [-1, max] with Bound(x, y) * factor <= threshold
      int lo = -1, hi = std::numeric_limits<T>::max();
      while (lo < hi) {
        const int mid = lo + (hi - lo + 1) / 2;
        if (rule_.Bound(mid, y) * factor_ <= threshold_) {
          lo = mid;
        } else {
          hi = mid - 1;
        }
      }
      v = lo;
    }
    return v;
  }
  const DifferenceRule<T>& rule_;
  double threshold_, factor_;
  mutable std::vector<int> lim_;
};

// A bit per value of v[0 .. n) above t.
inline unsigned Above(const float* v, int n, float t) {
#if defined(__SSE2__)
  if (n == kSb) {
    const __m128 vt = _mm_set1_ps(t);
    unsigned bits = 0;
    for (int q = 0; q < 4; ++q) {
      bits |= static_cast<unsigned>(_mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(v + 4 * q), vt)))
              << (4 * q);
    }
    return bits;
  }
#endif
  unsigned bits = 0;
  for (int i = 0; i < n; ++i) bits |= static_cast<unsigned>(v[i] > t) << i;
  return bits;
}

}  // namespace

// Runs of the difference (`plain`) and of its smoothing (`smooth`) above their thresholds;
// either may be null.
template <typename T>
void DetectRuns(const Stats<T>& st, const DifferenceRule<T>& rule, const DView<T>& d,
                const SView<T>* s, Detector* plain, Detector* smooth) {
  const int rows = d.n_prof, cols = d.n_scan, blocks = st.blocks;
  const double tmax = static_cast<double>(std::numeric_limits<T>::max());
  // v > threshold  <=>  v > floor(threshold) for whole-number values
  const T tp = plain ? static_cast<T>(std::min(std::floor(plain->threshold), tmax)) : T(0);
  const float ts = smooth ? static_cast<float>(smooth->threshold) : 0.0f;
  if (plain) plain->Init(cols, blocks);
  if (smooth) smooth->Init(cols, blocks);
  // a smoothed value is a weighted mean (weights summing to 1 up to rounding) of the values
  // within the kernel's radius: at most their largest
  const Limits<T> lim_p(rule, tp, 1.0);
  const Limits<T> lim_s(rule, ts, 1.0 + 1e-5);
  const int reach = smooth ? (s->radius() + kSb - 1) / kSb : 0;
  // per block of the row: a plain value may clear (1), a smoothed one (2), a run is open (4)
  std::vector<std::uint8_t> over(static_cast<size_t>(blocks) + 2 * reach, 0), act(blocks, 0);
  std::uint8_t* ov = over.data() + reach;
  for (int r = 0; r < rows; ++r) {
    const T* mxd = st.max_diff.data() + static_cast<size_t>(r) * blocks;
    const T* mno = st.min_off.data() + static_cast<size_t>(r) * blocks;
    bool any = false;
    if (plain) {
      for (int b = 0; b < blocks; ++b) act[b] = mxd[b] > lim_p[mno[b]];
    } else {
      std::fill(act.begin(), act.end(), 0);
    }
    if (smooth) {
      for (int b = 0; b < blocks; ++b) ov[b] = (mxd[b] > lim_s[mno[b]]) << 1;
      for (int j = -reach; j <= reach; ++j) {
        const std::uint8_t* o = ov + j;
        for (int b = 0; b < blocks; ++b) act[b] |= o[b];
      }
    }
    std::uint8_t any_bits = 0;
    for (int b = 0; b < blocks; ++b) any_bits |= act[b];
    any = any_bits != 0;
    if (!any && (plain == nullptr || plain->open_total == 0) &&
        (smooth == nullptr || smooth->open_total == 0)) {
      continue;
    }
    if (smooth) {  // the smoothed values of the row, each run of blocks at once
      for (int b = 0; b < blocks; ++b) {
        if (!(act[b] & 2)) continue;
        int e = b;
        while (e + 1 < blocks && (act[e + 1] & 2)) ++e;
        s->Span(r, b, e);
        b = e;
      }
    }
    for (int b = 0; b < blocks; ++b) {
      const int c0 = b * kSb, n = std::min(c0 + kSb, cols) - c0;
      if (plain && ((act[b] & 1) || plain->open[b] != 0)) {
        unsigned above = 0;
        if (act[b] & 1) {
          for (int i = 0; i < n; ++i) above |= static_cast<unsigned>(d.Value(c0 + i, r) > tp) << i;
        }
        plain->Row(r, b, static_cast<std::uint16_t>(above));
      }
      if (smooth && ((act[b] & 2) || smooth->open[b] != 0)) {
        unsigned above = 0;
        if (act[b] & 2) above = Above(s->Block(r, b), n, ts);
        smooth->Row(r, b, static_cast<std::uint16_t>(above));
      }
    }
  }
  if (plain) plain->Finish(rows);
  if (smooth) smooth->Finish(rows);
}

// ExtractStripe's scan lines from their runs: v the difference, dv the detection view.
template <class V, class DV>
void ScanLines(const V& v, const DV& dv, const Runs& runs, const StripeOptions& o,
               StripeResult* res, bool residual) {
  ResetResult(v.n_scan, res);
  const StegerKernels kernels = StegerKernelsOf(o);
  for (int s = 0; s < v.n_scan; ++s) {
    const size_t at = static_cast<size_t>(s) * kMaxRuns;
    ScanLine(v, dv, s, &runs.begin[at], &runs.end[at], runs.count[s], o, kernels, res, residual);
  }
}

template void DetectRuns<std::uint8_t>(const Stats<std::uint8_t>&,
                                       const DifferenceRule<std::uint8_t>&,
                                       const DView<std::uint8_t>&, const SView<std::uint8_t>*,
                                       Detector*, Detector*);
template void DetectRuns<std::uint16_t>(const Stats<std::uint16_t>&,
                                        const DifferenceRule<std::uint16_t>&,
                                        const DView<std::uint16_t>&, const SView<std::uint16_t>*,
                                        Detector*, Detector*);
template void ScanLines(const DView<std::uint8_t>&, const DView<std::uint8_t>&, const Runs&,
                        const StripeOptions&, StripeResult*, bool);
template void ScanLines(const DView<std::uint8_t>&, const SView<std::uint8_t>&, const Runs&,
                        const StripeOptions&, StripeResult*, bool);
template void ScanLines(const DView<std::uint16_t>&, const DView<std::uint16_t>&, const Runs&,
                        const StripeOptions&, StripeResult*, bool);
template void ScanLines(const DView<std::uint16_t>&, const SView<std::uint16_t>&, const Runs&,
                        const StripeOptions&, StripeResult*, bool);

}  // namespace hmlvs::scan
