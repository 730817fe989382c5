// WeightedCentres (frame_refine.h).
#include "hmlvs/image/frame_refine.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "hmlvs/image/frame_albedo.h"
#include "hmlvs/image/refine_batch.h"
#include "hmlvs/image/scan_checks.h"

namespace hmlvs::scan {

namespace {

// The refinement's image: the difference against the laser-off frame denoised by a bilateral
// filter, normalised, corrected at albedo steps and smoothed along the stripe, as
// session._weighted_centres builds it on the band of rows [lo, hi) around the stripe (zero
// elsewhere).

template <typename T>
class RefineImage {
 public:
  using Pixel = float;
  struct Setup {
    bool normalize;
    double offset, mean, blur_var, frame_noise, sigma_along;
    int lo, hi;
  };
  RefineImage(const Frames<T>& f, const Setup& o, Plane* bg, Plane* fp, Plane* ft)
      : n_scan(f.cols), n_prof(f.rows), f_(f), o_(o), bg_(bg), fp_(fp), ft_(ft) {
    bg_->Reset(f.rows, f.cols);
    fp_->Reset(f.rows, f.cols);
    ft_->Reset(f.rows, f.cols);
    // cv2.bilateralFilter(off, 7, 4 x noise, 3): the pixels within 3 px, weighted by
    // exp(-r^2 / (2 3^2)) exp(-dv^2 / (2 sigma_colour^2)) (OpenCV interpolates the second
    // from a table over the band's range; here it is exact for whole-number differences)
    const double sc = 4.0 * o.frame_noise;
    const double space_coeff = -0.5 / 9.0, colour_coeff = -0.5 / (sc * sc);
    for (int i = -3; i <= 3; ++i) {
      for (int j = -3; j <= 3; ++j) {
        const double r = std::sqrt(static_cast<double>(i * i + j * j));
        if (r > 3.0) continue;
        taps_.push_back({i, j, static_cast<float>(std::exp(r * r * space_coeff))});
      }
    }
    const int tmax = std::numeric_limits<T>::max();
    colour_.assign(static_cast<size_t>(tmax) + 1, 0.0f);
    for (int dv = 0; dv <= tmax; ++dv) {
      colour_[dv] = static_cast<float>(std::exp(dv * static_cast<double>(dv) * colour_coeff));
      if (colour_[dv] == 0.0f) break;
    }
    // the first 16 weights' bytes, plane by plane (least significant first)
    for (int dv = 0; dv < 16; ++dv) {
      std::uint32_t bits;
      std::memcpy(&bits, &colour_[dv], 4);
      for (int j = 0; j < 4; ++j) planes_[16 * j + dv] = static_cast<std::uint8_t>(bits >> (8 * j));
    }
    level_floor_ = static_cast<float>(std::max(1.0, 0.1 * o.mean));
    offset_f_ = static_cast<float>(o.offset);
    gain_num_ = static_cast<float>(o.mean + o.offset);
    blur_ = static_cast<float>(o.blur_var);
    with_blur_ = o.normalize && o.blur_var > 0.0;
    // the smoothing along: cv2.getGaussianKernel(2 r + 1, sigma_along) in single precision
    radius_ = static_cast<int>(std::ceil(4.0 * o.sigma_along));
    along_ = GaussianKernel(2 * radius_ + 1, o.sigma_along);
    pad_ = std::max(radius_, 3) + 1;
    for (int c = -pad_; c < n_scan + pad_; ++c) col_.push_back(Reflect101(c, n_scan));
    for (int p = o.lo - 4; p < o.hi + 4; ++p)
      band_.push_back(o.lo + Reflect101(p - o.lo, o.hi - o.lo));
    line_.resize(static_cast<size_t>(kSb + 2 * radius_));
  }
  // the value refine_centres reads: the image smoothed along the stripe (cv2.sepFilter2D,
  // borders mirrored)
  double at(int s, int p) const {
    if (p < o_.lo || p >= o_.hi) return 0.0;
    const int b = s / kSb;
    if (!ft_->Has(p, b)) ComputeSmoothed(p, b);
    return ft_->Row(p)[s];
  }
  double clamped(int s, int p) const {
    return at(std::clamp(s, 0, n_scan - 1), std::clamp(p, 0, n_prof - 1));
  }
  // the gain at (row p, column s), for the scan line's noise
  float Gain(int s, int p) const {
    return o_.normalize ? gain_num_ / Level(Background(p, s)) : 1.0f;
  }
  // Computes ahead, row by row, the values scan line s will read over rows windows[s] (first,
  // last; first > last: none): the smoothing along there, the image before it over the
  // kernel's reach, and the denoised laser-off frame under that.
  void Prepare(const std::vector<std::pair<int, int>>& windows, Marks* smoothed,
               Marks* unsmoothed) const {
    const int blocks = (n_scan + kSb - 1) / kSb;
    smoothed->Reset(n_prof, blocks);
    unsmoothed->Reset(n_prof, blocks);
    for (int s = 0; s < n_scan; ++s) {
      const auto [first, last] = windows[s];
      if (first > last) continue;
      const int r0 = std::max(first, o_.lo), r1 = std::min(last, o_.hi - 1);
      smoothed->Mark(r0, r1, s / kSb, s / kSb);
      // the smoothing's reach, and the gradient's pixel either side with the blur correction
      const int e = with_blur_ ? 1 : 0;
      unsmoothed->Mark(r0 - e, r1 + e, (s - radius_ - e) / kSb - (s - radius_ - e < 0),
                       (s + radius_ + e) / kSb);
    }
    unsmoothed->ForEach([this](int p, int b) {
      if (p >= o_.lo && p < o_.hi && !bg_->Has(p, b)) ComputeBackground(p, b);
    });
    unsmoothed->ForEach([this](int p, int b) {
      if (p >= o_.lo && p < o_.hi && !fp_->Has(p, b)) ComputeF(p, b);
    });
    smoothed->ForEach([this](int p, int b) {
      if (!ft_->Has(p, b)) ComputeSmoothed(p, b);
    });
  }
  int n_scan, n_prof;

 private:
  struct Tap {
    int di, dj;
    float w;
  };
  float Level(float bg) const { return std::max(bg + offset_f_, level_floor_); }
  float Background(int p, int c) const {
    const int b = c / kSb;
    if (!bg_->Has(p, b)) ComputeBackground(p, b);
    return bg_->Row(p)[c];
  }
  // the bilateral filter of the laser-off frame on the band (rows mirrored at its edges,
  // columns at the image's), for a block of a row: per pixel the taps' sums in OpenCV's order
  void ComputeBackground(int p, int b) const {
    const int x0 = b * kSb, x1 = std::min(n_scan, x0 + kSb), n = x1 - x0;
    const T* rows[7];
    for (int di = -3; di <= 3; ++di) {
      rows[di + 3] = f_.off + band_[p + di - (o_.lo - 4)] * f_.off_rs;
    }
    float* out = bg_->Row(p) + x0;
    if (x0 >= 3 && x1 + 3 <= n_scan && n == kSb) {
      BilateralBlock(rows, x0, out);
    } else {
      const T* centre = rows[3] + x0;
      for (int i = 0; i < n; ++i) {
        float sum = 0.0f, wsum = 0.0f;
        for (const Tap& t : taps_) {
          const T v = rows[t.di + 3][col_[pad_ + x0 + i + t.dj]];
          const float w = t.w * colour_[v > centre[i] ? v - centre[i] : centre[i] - v];
          sum += static_cast<float>(v) * w;
          wsum += w;
        }
        out[i] = sum / wsum;
      }
    }
    bg_->Mark(p, b);
  }
#if defined(HMLVS_AVX2)
  // The colour weights of 16 differences `idx` (bytes): with all below 16 from the table's
  // first 16 entries held in four byte planes (a byte shuffle each), else gathered.
  __attribute__((target("avx2"))) void ColourWeights(__m128i idx, __m256* k0, __m256* k1) const {
    const __m128i fifteen = _mm_set1_epi8(15);
    if (_mm_movemask_epi8(_mm_cmpeq_epi8(_mm_max_epu8(idx, fifteen), fifteen)) == 0xffff) {
      const __m128i* planes = reinterpret_cast<const __m128i*>(planes_);
      const __m128i b0 = _mm_shuffle_epi8(_mm_load_si128(planes), idx);
      const __m128i b1 = _mm_shuffle_epi8(_mm_load_si128(planes + 1), idx);
      const __m128i b2 = _mm_shuffle_epi8(_mm_load_si128(planes + 2), idx);
      const __m128i b3 = _mm_shuffle_epi8(_mm_load_si128(planes + 3), idx);
      const __m128i lo01 = _mm_unpacklo_epi8(b0, b1), hi01 = _mm_unpackhi_epi8(b0, b1);
      const __m128i lo23 = _mm_unpacklo_epi8(b2, b3), hi23 = _mm_unpackhi_epi8(b2, b3);
      *k0 = _mm256_castsi256_ps(
          _mm256_set_m128i(_mm_unpackhi_epi16(lo01, lo23), _mm_unpacklo_epi16(lo01, lo23)));
      *k1 = _mm256_castsi256_ps(
          _mm256_set_m128i(_mm_unpackhi_epi16(hi01, hi23), _mm_unpacklo_epi16(hi01, hi23)));
      return;
    }
    const float* colour = colour_.data();
    *k0 = _mm256_i32gather_ps(colour, _mm256_cvtepu8_epi32(idx), 4);
    *k1 = _mm256_i32gather_ps(colour, _mm256_cvtepu8_epi32(_mm_srli_si128(idx, 8)), 4);
  }
  // BilateralBlock eight at a time, on CPUs with AVX2 (the same operations on each pixel, so
  // the same values: no fused multiply-add)
  __attribute__((target("avx2"))) void BilateralBlockAvx2(const T* const* rows, int x0,
                                                          float* out) const {
    const __m128i cc = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[3] + x0));
    __m256 s0 = _mm256_setzero_ps(), s1 = s0, w0 = s0, w1 = s0;
    for (const Tap& t : taps_) {
      const __m128i vv =
          _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[t.di + 3] + x0 + t.dj));
      const __m256i v0 = _mm256_cvtepu8_epi32(vv), v1 = _mm256_cvtepu8_epi32(_mm_srli_si128(vv, 8));
      const __m256 space = _mm256_set1_ps(t.w);
      __m256 g0, g1;  // |v - centre| as bytes: the colour weights' indices
      ColourWeights(_mm_or_si128(_mm_subs_epu8(vv, cc), _mm_subs_epu8(cc, vv)), &g0, &g1);
      const __m256 k0 = _mm256_mul_ps(space, g0), k1 = _mm256_mul_ps(space, g1);
      s0 = _mm256_add_ps(s0, _mm256_mul_ps(_mm256_cvtepi32_ps(v0), k0));
      s1 = _mm256_add_ps(s1, _mm256_mul_ps(_mm256_cvtepi32_ps(v1), k1));
      w0 = _mm256_add_ps(w0, k0);
      w1 = _mm256_add_ps(w1, k1);
    }
    _mm256_storeu_ps(out, _mm256_div_ps(s0, w0));
    _mm256_storeu_ps(out + 8, _mm256_div_ps(s1, w1));
  }
#endif
  // kSb pixels from column x0 on, inside the image, the same operations four at a time
  void BilateralBlock(const T* const* rows, int x0, float* out) const {
#if defined(HMLVS_AVX2)
    if constexpr (sizeof(T) == 1) {
      if (UseAvx2()) {
        BilateralBlockAvx2(rows, x0, out);
        return;
      }
    }
#endif
#if defined(__SSE2__)
    if constexpr (sizeof(T) == 1) {
      const __m128i zero = _mm_setzero_si128();
      const __m128i cc = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[3] + x0));
      __m128 s[4], w[4];
      for (int q = 0; q < 4; ++q) s[q] = w[q] = _mm_setzero_ps();
      alignas(16) std::uint8_t idx[16];
      const float* colour = colour_.data();
      for (const Tap& t : taps_) {
        const __m128i vv =
            _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[t.di + 3] + x0 + t.dj));
        _mm_store_si128(reinterpret_cast<__m128i*>(idx),
                        _mm_or_si128(_mm_subs_epu8(vv, cc), _mm_subs_epu8(cc, vv)));
        const __m128 space = _mm_set1_ps(t.w);
        const __m128i lo = _mm_unpacklo_epi8(vv, zero), hi = _mm_unpackhi_epi8(vv, zero);
        const __m128 v[4] = {_mm_cvtepi32_ps(_mm_unpacklo_epi16(lo, zero)),
                             _mm_cvtepi32_ps(_mm_unpackhi_epi16(lo, zero)),
                             _mm_cvtepi32_ps(_mm_unpacklo_epi16(hi, zero)),
                             _mm_cvtepi32_ps(_mm_unpackhi_epi16(hi, zero))};
        for (int q = 0; q < 4; ++q) {
          const std::uint8_t* k = idx + 4 * q;
          const __m128 wq = _mm_mul_ps(
              space, _mm_setr_ps(colour[k[0]], colour[k[1]], colour[k[2]], colour[k[3]]));
          s[q] = _mm_add_ps(s[q], _mm_mul_ps(v[q], wq));
          w[q] = _mm_add_ps(w[q], wq);
        }
      }
      for (int q = 0; q < 4; ++q) _mm_storeu_ps(out + 4 * q, _mm_div_ps(s[q], w[q]));
      return;
    }
#endif
    const T* centre = rows[3] + x0;
    float sum[kSb] = {}, wsum[kSb] = {};
    for (const Tap& t : taps_) {
      const T* v = rows[t.di + 3] + x0 + t.dj;
      for (int i = 0; i < kSb; ++i) {
        const float w = t.w * colour_[v[i] > centre[i] ? v[i] - centre[i] : centre[i] - v[i]];
        sum[i] += static_cast<float>(v[i]) * w;
        wsum[i] += w;
      }
    }
    for (int i = 0; i < kSb; ++i) out[i] = sum[i] / wsum[i];
  }
  // the difference against the denoised frame, normalised, at (p, c)
  float P(int p, int c) const {
    const float bg = Background(p, c);
    const float diff = std::max(static_cast<float>(f_.On(p, c)) - bg, 0.0f);
    return o_.normalize ? diff * (gain_num_ / Level(bg)) : diff;
  }
  float LogLevel(int p, int c) const { return std::log(Level(Background(p, c))); }
  // np.gradient along the rows (of the band) and the columns
  template <class G>
  float GradRow(int p, int c, G g) const {
    if (p == o_.lo) return g(p + 1, c) - g(p, c);
    if (p == o_.hi - 1) return g(p, c) - g(p - 1, c);
    return (g(p + 1, c) - g(p - 1, c)) / 2.0f;
  }
  template <class G>
  float GradCol(int p, int c, G g) const {
    if (c == 0) return g(p, 1) - g(p, 0);
    if (c == n_scan - 1) return g(p, c) - g(p, c - 1);
    return (g(p, c + 1) - g(p, c - 1)) / 2.0f;
  }
  // the smoothing along for a block of a row in the band, from the row's values around it
  void ComputeSmoothed(int p, int b) const {
    const int x0 = b * kSb, x1 = std::min(n_scan, x0 + kSb), r = radius_;
    for (int k = std::max(0, x0 - r) / kSb; k <= std::min(n_scan - 1, x1 - 1 + r) / kSb; ++k) {
      if (!fp_->Has(p, k)) ComputeF(p, k);
    }
    const float* row = fp_->Row(p);
    if (x0 - r >= 0 && x1 + r <= n_scan) {
      std::copy(row + x0 - r, row + x1 + r, line_.begin());
    } else {
      for (int i = 0; i < x1 - x0 + 2 * r; ++i) line_[i] = row[col_[pad_ + x0 - r + i]];
    }
    SumShifted(line_.data(), along_.data(), 2 * r + 1, x1 - x0, ft_->Row(p) + x0);
    ft_->Mark(p, b);
  }
  // the refinement's image before the smoothing along, for a block of a row in the band
  void ComputeF(int p, int b) const {
    const int x0 = b * kSb, x1 = std::min(n_scan, x0 + kSb);
    float* out = fp_->Row(p);
    if (!with_blur_) {
      // P(p, x) over the block, the denoised frame's block computed first (vectorises)
      if (!bg_->Has(p, b)) ComputeBackground(p, b);
      const float* bg = bg_->Row(p);
      const T* on = f_.on + p * f_.on_rs;
      const bool normalize = o_.normalize;
      const float offset = offset_f_, floor = level_floor_, num = gain_num_;
      for (int x = x0; x < x1; ++x) {
        const float diff = std::max(static_cast<float>(on[x]) - bg[x], 0.0f);
        out[x] = normalize ? diff * (num / std::max(bg[x] + offset, floor)) : diff;
      }
    } else {
      // to first order in the blur's variance s2 the normalised profile is
      // P + s2 grad(P) . grad(log albedo): subtracted
      auto pf = [this](int pp, int cc) { return P(pp, cc); };
      auto lf = [this](int pp, int cc) { return LogLevel(pp, cc); };
      for (int x = x0; x < x1; ++x) {
        const float t =
            GradRow(p, x, pf) * GradRow(p, x, lf) + GradCol(p, x, pf) * GradCol(p, x, lf);
        out[x] = P(p, x) - blur_ * t;
      }
    }
    fp_->Mark(p, b);
  }
  const Frames<T>& f_;
  Setup o_;
  Plane* bg_;
  Plane* fp_;
  Plane* ft_;
  std::vector<Tap> taps_;
  std::vector<float> colour_, along_;
  alignas(16) std::uint8_t planes_[64] = {};
  std::vector<int> col_, band_;
  int radius_ = 0, pad_ = 0;
  bool with_blur_ = false;
  float level_floor_ = 1.0f, offset_f_ = 0.0f, gain_num_ = 1.0f, blur_ = 0.0f;
  mutable std::vector<float> line_;
};

// Whether scan line s of `st` holds a found centre of finite width.
bool FoundLine(const StripeResult& st, int s) {
  return st.status[s] == static_cast<std::uint8_t>(StripeStatus::kFound) &&
         std::isfinite(st.centre[s]) && std::isfinite(st.width[s]);
}

// The band of rows [lo, hi) the refinement's image is built on: every found scan line's
// window (Steger's centre +- 4.5 profile sigmas plus a pixel), and the filter's 3 px more.
// False when no scan line was found.
bool RefineBand(const StripeResult& st, int n_prof, int* lo, int* hi) {
  double lo_c = std::numeric_limits<double>::infinity(), hi_c = -lo_c;
  bool any = false;
  for (int s = 0; s < st.status.size(); ++s) {
    if (!FoundLine(st, s)) continue;
    const double c = st.centre[s], w = st.width[s];
    const double reach = 4.5 * std::max(0.5, w / 2.3548) + 2.0;
    lo_c = std::min(lo_c, c - reach);
    hi_c = std::max(hi_c, c + reach);
    any = true;
  }
  *lo = static_cast<int>(std::max(0.0, std::floor(lo_c) - 4));
  *hi = static_cast<int>(std::min(static_cast<double>(n_prof), std::ceil(hi_c) + 5));
  return any;
}

// The rows each scan line's refinement reads (first, last; first > last: none): the window
// centre +- 4 profile sigmas about the rounded centre, which may move half a profile sigma
// (RefineLine); none within `edge` scan lines of the image's ends.
std::vector<std::pair<int, int>> RefineWindows(const StripeResult& st, int edge) {
  const int n = static_cast<int>(st.status.size());
  std::vector<std::pair<int, int>> windows(static_cast<size_t>(n), {0, -1});
  for (int s = edge; s < n - edge; ++s) {
    if (!FoundLine(st, s)) continue;
    const double c = st.centre[s], w = st.width[s];
    const double sp = std::max(0.5, w / (2.0 * std::sqrt(2.0 * std::log(2.0))));
    const double reach = std::ceil(4.0 * sp) + 0.5 * sp + 1.0;
    windows[s] = {static_cast<int>(std::floor(c - reach)), static_cast<int>(std::ceil(c + reach))};
  }
  return windows;
}

}  // namespace

// session._weighted_centres: Steger's found centres refined (RefineStripeCentres) on the
// RefineImage.
template <typename T>
bool WeightedCentres(const Frames<T>& f, bool normalize, double offset, double mean, double noise,
                     double sigma_along, double blur_var, StripeResult* st) {
  typename RefineImage<T>::Setup o;
  if (!RefineBand(*st, f.rows, &o.lo, &o.hi)) return false;
  o.normalize = normalize;
  o.offset = offset;
  o.mean = mean;
  o.blur_var = blur_var;
  o.frame_noise = noise / std::sqrt(2.0);  // one frame's noise, of the difference of two
  o.sigma_along = sigma_along;
  Workspace& ws = ThreadWorkspace();
  const RefineImage<T> image(f, o, &ws.a, &ws.b, &ws.c);
  // each scan line's additive noise: one frame's, times the gain at its centre (in single
  // precision, as NumPy multiplies a float by a float32 array); none within 3 sigma_along of
  // the image's ends, where the smoothing along reaches past them
  const int n = f.cols, edge = static_cast<int>(std::ceil(3.0 * sigma_along));
  const double factor = std::sqrt(1.0 / std::max(1.0, 2.0 * std::sqrt(M_PI) * sigma_along));
  const StripeRefineOptions ro;
  const std::vector<std::pair<int, int>> windows = RefineWindows(*st, edge);
  image.Prepare(windows, &ws.marks, &ws.marks2);
  RefineLines<RefineImage<T>> lines(image, ro, st);
  std::vector<int> refined;
  for (int s = edge; s < n - edge; ++s) {
    if (st->status[s] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    double line_noise = o.frame_noise;
    if (normalize) {
      const double rc = std::isfinite(st->centre[s]) ? std::nearbyint(st->centre[s]) : 0.0;
      const int pos =
          static_cast<int>(std::clamp(rc - o.lo, 0.0, static_cast<double>(o.hi - o.lo - 1)));
      line_noise =
          static_cast<double>(static_cast<float>(o.frame_noise) * image.Gain(s, pos + o.lo));
    }
    lines.Add(s, line_noise, windows[s]);
    refined.push_back(s);
  }
  lines.Flush();
  for (const int s : refined) st->sigma[s] = st->sigma[s] * factor;
  return true;
}

template bool WeightedCentres<std::uint8_t>(const Frames<std::uint8_t>&, bool, double, double,
                                            double, double, double, StripeResult*);
template bool WeightedCentres<std::uint16_t>(const Frames<std::uint16_t>&, bool, double, double,
                                             double, double, double, StripeResult*);

}  // namespace hmlvs::scan
