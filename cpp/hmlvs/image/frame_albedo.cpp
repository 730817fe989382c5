// The albedo offset's fit (frame_albedo.h) and FitAlbedoOffset (frames.h).
#include "hmlvs/image/frame_albedo.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "hmlvs/image/frames.h"

namespace hmlvs::scan {

namespace {

// Median as NumPy takes it of float32 values (the mean of the middle two in single precision).
float MedianF(std::vector<float> v) {
  const size_t n = v.size(), h = n / 2;
  std::nth_element(v.begin(), v.begin() + h, v.end());
  const float upper = v[h];
  if (n % 2 == 1) return upper;
  const float lower = *std::max_element(v.begin(), v.begin() + h);
  return (lower + upper) / 2.0f;
}

// The offset a of the peaks' fit as proportional to level + a; NaN when the peaks do not lie
// on two clearly different levels.
double AffineOffset(const std::vector<float>& peak, const std::vector<float>& level) {
  const size_t n = level.size();
  if (n < 20) return kNaN;
  std::vector<float> sorted = level;  // partially: the k-th smallest where read
  auto kth = [&](std::uint64_t k) {
    const auto at = sorted.begin() + static_cast<std::ptrdiff_t>(k);
    std::nth_element(sorted.begin(), at, sorted.end());
    return static_cast<double>(*at);
  };
  const double p2 = Percentile(n, 0.02, kth), p98 = Percentile(n, 0.98, kth);
  if (!(p98 > 2.0 * std::max(p2, 1.0))) return kNaN;
  const double split = std::sqrt(std::max(p2, 1.0) * p98);
  std::vector<float> pd, pl, od, ol;
  for (size_t i = 0; i < n; ++i) {
    const bool dark = static_cast<double>(level[i]) < split;
    (dark ? pd : pl).push_back(peak[i]);
    (dark ? od : ol).push_back(level[i]);
  }
  if (pd.size() < 10 || pl.size() < 10) return kNaN;
  const double mpd = MedianF(pd), mpl = MedianF(pl), mod = MedianF(od), mol = MedianF(ol);
  if (mpl <= mpd) return std::numeric_limits<double>::infinity();
  return std::max((mpd * mol - mpl * mod) / (mpl - mpd), -0.5 * mod);
}

}  // namespace

// cv2.getGaussianKernel(n, sigma) in single precision (its sums in double; OpenCV's own are
// in software double precision, which may differ in the last bit).
std::vector<float> GaussianKernel(int n, double sigma) {
  const double scale = -0.125 / (sigma * sigma);
  const int half = (n - 1) / 2;
  std::vector<double> t(static_cast<size_t>(half));
  double sum = 0.0;
  for (int i = 0, x = 1 - n; i < half; ++i, x += 2) {
    t[i] = std::exp(static_cast<double>(x * x) * scale);
    sum += t[i];
  }
  sum = sum * 2.0 + 1.0;
  const double mul = 1.0 / sum;
  std::vector<float> out(static_cast<size_t>(n));
  for (int i = 0; i < half; ++i) out[i] = out[n - 1 - i] = static_cast<float>(t[i] * mul);
  out[half] = static_cast<float>(mul);
  return out;
}

template <typename T>
double FitOffset(const Frames<T>& f, const Stats<T>& st, double noise) {
  const int rows = f.rows, cols = f.cols;
  const double top = static_cast<double>(std::numeric_limits<T>::max());
  const float min_peak = static_cast<float>(std::max(5.0 * noise / std::sqrt(5.0), 3.0));
  // the scan lines whose peak is high enough and not saturated
  std::vector<int> cand;
  for (int c = 0; c < cols; ++c) {
    const int m = st.peak_row[c];
    const int lo = std::max(0, m - 2), hi = std::min(rows - 1, m + 2);
    if (static_cast<float>(st.peak_sum[c] * 0.2) > min_peak && f.On(lo, c) < top &&
        f.On(m, c) < top && f.On(hi, c) < top) {
      cand.push_back(c);
    }
  }
  // the laser-off frame blurred at sigma 1 (GaussianBlur: rows, then columns, as OpenCV's
  // separable filter sums them, borders mirrored) over 7 x 7 pixels around their peaks: g, from
  // the row pass h over 4 rows more; computed ahead, row by row
  Workspace& ws = ThreadWorkspace();
  Plane& h = ws.a;
  Plane& g = ws.b;
  h.Reset(rows, cols);
  g.Reset(rows, cols);
  const int blocks = (cols + kSb - 1) / kSb;
  Marks& gm = ws.marks;
  Marks& hm = ws.marks2;
  gm.Reset(rows, blocks);
  hm.Reset(rows, blocks);
  for (const int c : cand) {
    const int m = st.peak_row[c];
    gm.Mark(m - 3, m + 3, (c - 3) / kSb - (c < 3), (c + 3) / kSb);
    hm.Mark(m - 7, m + 7, (c - 3) / kSb - (c < 3), (c + 3) / kSb);
  }
  const std::vector<float> k = GaussianKernel(9, 1.0);
  std::vector<float> line(kSb + 8);
  hm.ForEach([&](int r, int b) {
    const int x0 = b * kSb, n = std::min(cols, x0 + kSb) - x0;
    const T* row = f.off + r * f.off_rs;
    if (x0 >= 4 && x0 + n + 4 <= cols) {
      for (int i = 0; i < n + 8; ++i) line[i] = static_cast<float>(row[x0 - 4 + i]);
    } else {
      for (int i = 0; i < n + 8; ++i)
        line[i] = static_cast<float>(row[Reflect101(x0 - 4 + i, cols)]);
    }
    SumShifted(line.data(), k.data(), 9, n, h.Row(r) + x0);
    h.Mark(r, b);
  });
  gm.ForEach([&](int r, int b) {
    const int x0 = b * kSb, n = std::min(cols, x0 + kSb) - x0;
    const float* hr[9];
    for (int j = -4; j <= 4; ++j) hr[j + 4] = h.Row(Reflect101(r + j, rows)) + x0;
    float* out = g.Row(r) + x0;
    for (int i = 0; i < n; ++i) out[i] = k[4] * hr[4][i];
    for (int j = 1; j <= 4; ++j) {
      const float kj = k[4 + j];
      const float* up = hr[4 + j];
      const float* down = hr[4 - j];
      for (int i = 0; i < n; ++i) out[i] += kj * (up[i] + down[i]);
    }
    g.Mark(r, b);
  });
  std::vector<float> peaks, levels;
  for (const int c : cand) {
    const int m = st.peak_row[c];
    // flat: the largest blurred value within 3 px at most 1.2 x the smallest (at least 1)
    float mx = -std::numeric_limits<float>::infinity(), mn = -mx;
    for (int r = std::max(0, m - 3); r <= std::min(rows - 1, m + 3); ++r) {
      const float* row = g.Row(r);
      for (int x = std::max(0, c - 3); x <= std::min(cols - 1, c + 3); ++x) {
        mx = std::max(mx, row[x]);
        mn = std::min(mn, row[x]);
      }
    }
    if (!(mx <= 1.2f * std::max(mn, 1.0f))) continue;
    peaks.push_back(static_cast<float>(st.peak_sum[c] * 0.2));
    levels.push_back(g.Row(m)[c]);
  }
  return AffineOffset(peaks, levels);
}

template double FitOffset<std::uint8_t>(const Frames<std::uint8_t>&, const Stats<std::uint8_t>&,
                                        double);
template double FitOffset<std::uint16_t>(const Frames<std::uint16_t>&, const Stats<std::uint16_t>&,
                                         double);

}  // namespace hmlvs::scan

namespace hmlvs {

template <typename T>
double FitAlbedoOffset(const ImageView<T>& on, const ImageView<T>& off, StripeDirection direction,
                       double* noise) {
  scan::RequireImage(on, "the laser-on image");
  scan::RequireImage(off, "the laser-off image");
  scan::RequireSameSize(on, off);
  const bool transpose = direction == StripeDirection::kRows;
  std::vector<T> buffer(2 * static_cast<size_t>(on.rows) * on.cols);
  scan::Frames<T> f;
  f.rows = transpose ? on.cols : on.rows;
  f.cols = transpose ? on.rows : on.cols;
  f.on = scan::Working(on, transpose, buffer.data(), &f.on_rs);
  f.off = scan::Working(off, transpose, buffer.data() + buffer.size() / 2, &f.off_rs);
  scan::Stats<T> st;
  scan::CollectStats(f, &st);  // not transposed here: every 4th row of the (transposed) frames
  const double plain = scan::NoiseFromHistogram(st.diff_hist, st.diff_n);
  if (noise != nullptr) *noise = plain;
  return scan::FitOffset(f, st, plain);
}

template double FitAlbedoOffset<std::uint8_t>(const ImageView<std::uint8_t>&,
                                              const ImageView<std::uint8_t>&, StripeDirection,
                                              double*);
template double FitAlbedoOffset<std::uint16_t>(const ImageView<std::uint16_t>&,
                                               const ImageView<std::uint16_t>&, StripeDirection,
                                               double*);

}  // namespace hmlvs
