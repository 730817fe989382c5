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

#include "hmlvs/image/scan_lines.h"

namespace hmlvs {

using scan::Kernels;
using scan::kNaN;
using scan::MakeKernels;
using scan::MakeScanView;
using scan::RequireImage;
using scan::Runs;
using scan::ScanView;

namespace {

constexpr int kBlock = 32;  // scan lines tested together for "nothing above threshold"

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

// Throws std::invalid_argument for a scale, floor or offset of DifferenceOptions out of range.
void CheckDifferenceOptions(const DifferenceOptions& o) {
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
}

// DifferenceImage without normalisation: max(on - off, 0).
template <typename T>
void PlainDifference(const ImageView<T>& on, const ImageView<T>& off, T* out) {
  // Loop bounds and strides in locals: writes through a uint8_t pointer may alias anything,
  // so struct members read in the loop would be reloaded every pixel and block vectorising.
  const int rows = on.rows, cols = on.cols;
  const std::ptrdiff_t on_rs = on.row_stride, on_cs = on.col_stride;
  const std::ptrdiff_t off_rs = off.row_stride, off_cs = off.col_stride;
  const bool contiguous = on_cs == 1 && off_cs == 1;
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
}

}  // namespace

template <typename T>
void DifferenceImage(const ImageView<T>& on, const ImageView<T>& off, T* out,
                     const DifferenceOptions& o) {
  RequireImage(on, "the laser-on image");
  RequireImage(off, "the laser-off image");
  scan::RequireSameSize(on, off);
  CheckDifferenceOptions(o);
  // Loop bounds and strides in locals: writes through a uint8_t pointer may alias anything,
  // so struct members read in the loop would be reloaded every pixel and block vectorising.
  const int rows = on.rows, cols = on.cols;
  const std::ptrdiff_t on_rs = on.row_stride, on_cs = on.col_stride;
  const std::ptrdiff_t off_rs = off.row_stride, off_cs = off.col_stride;
  if (!o.normalize) {
    PlainDifference(on, off, out);
    return;
  }
  std::uint64_t sum = 0;
  for (int r = 0; r < rows; ++r) {
    const T* b = off.data + r * off_rs;
    std::uint64_t row = 0;
    for (int c = 0; c < cols; ++c) row += b[c * off_cs];
    sum += row;
  }
  const scan::DifferenceRule<T> rule(o,
                                     static_cast<double>(sum) / (static_cast<double>(rows) * cols));
  if (rule.offset_rule) {
    // double precision per pixel, the same value as NumPy's formula (DifferenceOptions)
    if constexpr (sizeof(T) == 1) {
      // 8-bit: the value of every (laser-off, laser-on) pair once, then one table look-up
      // per pixel
      std::vector<T> table;
      rule.Table(&table);
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
        for (int c = 0; c < cols; ++c) dst[c] = rule.At(a[c * on_cs], b[c * off_cs]);
      }
    }
    return;
  }
  // the plain normalisation: a gain per laser-off value, one multiplication per pixel
  using Acc = typename scan::DifferenceRule<T>::Acc;
  const Acc tmax = static_cast<Acc>(std::numeric_limits<T>::max());
  const Acc* g = rule.gain.data();
  for (int r = 0; r < rows; ++r) {
    const T* a = on.data + r * on_rs;
    const T* b = off.data + r * off_rs;
    T* dst = out + static_cast<std::ptrdiff_t>(r) * cols;
    for (int c = 0; c < cols; ++c) {
      const T x = a[c * on_cs], y = b[c * off_cs];
      // branch-free (vectorises): max(0, x - y) is 0 where x <= y, and d >= 0.5 so
      // truncating rounds; the value of DifferenceRule
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
  return scan::NoiseFromHistogram(hist, n);
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
    scan::SumShifted(line.data(), w.data(), 2 * r + 1, n,
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
  scan::ValidateOptions(o);
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

  scan::ResetResult(v.n_scan, &res);
  const scan::StegerKernels kernels = scan::StegerKernelsOf(o);
  for (int s = 0; s < v.n_scan; ++s) {
    const size_t at = static_cast<size_t>(s) * scan::kMaxRuns;
    if (smoothed) {
      scan::ScanLine(v, dv, s, &runs.begin[at], &runs.end[at], runs.count[s], o, kernels, &res);
    } else {
      scan::ScanLine(v, v, s, &runs.begin[at], &runs.end[at], runs.count[s], o, kernels, &res);
    }
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
  scan::ValidateQualityOptions(o);
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
  std::vector<double> y;
  for (int s = 0; s < n; ++s) {
    if (res->status[s] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    res->status[s] = static_cast<std::uint8_t>(scan::AssessLine(
        v, von, voff, with_off, o, s, res->centre[s], res->width[s], res->threshold, &y));
  }
}

void RefineStripeCentres(const ImageView<float>& image, StripeDirection direction,
                         const Eigen::VectorXd& noise, const StripeRefineOptions& o,
                         StripeResult* res) {
  RequireImage(image, "the image");
  scan::ValidateRefineOptions(o);
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
  for (int s = 0; s < n; ++s) {
    if (res->status[s] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    scan::RefineLine(v, s, noise[s], o, res);
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
