// StripeFromFrames: the session pipeline's stripe of one frame (see frames.h).
//
// The frames are worked on with scan lines as columns and rows contiguous (a kRows stripe is
// transposed first). One pass over the rows gathers what needs every pixel, in the pixel type:
// the laser-off frame's mean, histograms (the plain difference's noise, the normalised
// difference's noise and maximum, the gain's percentile), the column peaks the albedo fit
// starts from, and per row and 16 columns the largest plain difference and the smallest
// laser-off value. From those, a bound on the normalised difference (and on its smoothing along
// the stripe) per 16 columns of a row decides where a value could clear a threshold; only
// there, and where a scan line's peak, centre, refinement or check reads, are values computed,
// each once per call (Plane).
#include "hmlvs/image/frames.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define HMLVS_AVX2 1
#endif

#include "hmlvs/image/scan_lines.h"

namespace hmlvs {

namespace {

using scan::Derivatives;
using scan::DifferenceRule;
using scan::Kernels;
using scan::kNaN;
using scan::Runs;

constexpr int kSb = 16;  // columns of a block: the unit of the bounds and of the planes

#if defined(HMLVS_AVX2)
// Whether to take the AVX2 loops: on CPUs that have it, unless the environment variable
// HMLVS_NO_AVX2 is set (the tests compare both ways: the same values on every x86-64 CPU).
bool UseAvx2() {
  static const bool use = __builtin_cpu_supports("avx2") && std::getenv("HMLVS_NO_AVX2") == nullptr;
  return use;
}
#endif

// OpenCV's BORDER_REFLECT_101: index i mirrored into 0 .. n - 1 (gfedcb|abcdefgh|gfedcba)
int Reflect101(int i, int n) {
  if (n == 1) return 0;
  while (i < 0 || i >= n) i = i < 0 ? -i : 2 * (n - 1) - i;
  return i;
}

// ------------------------------------------------------------------------------------------
// Workspace

// A float image computed per (row, block of kSb columns) on first read.
// Memory that grows, never shrinks and is never cleared: only the pages a call writes are
// ever touched (the planes below are written around the stripe only).
template <typename T>
class Scratch {
 public:
  T* Get(size_t n) {
    if (n > size_) {
      data_.reset(new T[n]);  // default-initialised: not written until used
      size_ = n;
    }
    return data_.get();
  }

 private:
  std::unique_ptr<T[]> data_;
  size_t size_ = 0;
};

struct Plane {
  Scratch<float> memory;
  float* data = nullptr;
  std::vector<std::uint32_t> stamp;  // per (row, block): == epoch once computed
  std::uint32_t epoch = 0;
  int rows = 0, cols = 0, blocks = 0;
  void Reset(int r, int c) {
    rows = r;
    cols = c;
    blocks = (c + kSb - 1) / kSb;
    const size_t n = static_cast<size_t>(r) * c, nb = static_cast<size_t>(r) * blocks;
    data = memory.Get(n);
    if (stamp.size() < nb) stamp.resize(nb, 0);
    if (++epoch == 0) {
      std::fill(stamp.begin(), stamp.end(), 0);
      epoch = 1;
    }
  }
  bool Has(int r, int b) const { return stamp[static_cast<size_t>(r) * blocks + b] == epoch; }
  void Mark(int r, int b) { stamp[static_cast<size_t>(r) * blocks + b] = epoch; }
  float* Row(int r) { return data + static_cast<size_t>(r) * cols; }
};

// (row, block) pairs to compute ahead, visited row by row: values computed in the order the
// frames lie in memory, not scattered by the order scan lines read them.
class Marks {
 public:
  void Reset(int rows, int blocks) {
    if (rows != rows_ || blocks != blocks_) {
      rows_ = rows;
      blocks_ = blocks;
      bits_.assign(static_cast<size_t>(rows) * blocks, 0);
    } else if (lo_ <= hi_) {  // the rows marked last time
      std::fill(bits_.begin() + static_cast<std::ptrdiff_t>(lo_) * blocks,
                bits_.begin() + static_cast<std::ptrdiff_t>(hi_ + 1) * blocks, 0);
    }
    lo_ = rows;
    hi_ = -1;
  }
  // rows r0 .. r1 and blocks b0 .. b1 (both inclusive, clipped)
  void Mark(int r0, int r1, int b0, int b1) {
    r0 = std::max(r0, 0);
    r1 = std::min(r1, rows_ - 1);
    b0 = std::max(b0, 0);
    b1 = std::min(b1, blocks_ - 1);
    for (int r = r0; r <= r1; ++r) {
      std::uint8_t* row = bits_.data() + static_cast<std::ptrdiff_t>(r) * blocks_;
      for (int b = b0; b <= b1; ++b) row[b] = 1;
    }
    lo_ = std::min(lo_, r0);
    hi_ = std::max(hi_, r1);
  }
  template <class F>
  void ForEach(F f) const {
    for (int r = lo_; r <= hi_; ++r) {
      const std::uint8_t* row = bits_.data() + static_cast<size_t>(r) * blocks_;
      for (int b = 0; b < blocks_; ++b) {
        if (row[b]) f(r, b);
      }
    }
  }

 private:
  std::vector<std::uint8_t> bits_;
  int rows_ = 0, blocks_ = 0, lo_ = 0, hi_ = -1;
};

// Runs above a threshold, a scan line (column) at a time, fed row by row.
struct Detector {
  bool smoothed = false;
  double threshold = 0.0;
  Runs runs;
  std::vector<int> start;           // per column: the open run's first row
  std::vector<std::uint16_t> open;  // per block: a bit per column with an open run
  int open_total = 0;
  void Init(int cols, int blocks) {
    // the runs' storage kept from call to call (only the counts need clearing)
    runs.begin.resize(static_cast<size_t>(cols) * scan::kMaxRuns);
    runs.end.resize(runs.begin.size());
    runs.count.assign(static_cast<size_t>(cols), 0);
    open_total = 0;
    start.assign(static_cast<size_t>(cols), -1);
    open.assign(static_cast<size_t>(blocks), 0);
  }
  // row r of block b: a bit per column above the threshold
  void Row(int r, int b, std::uint16_t above) {
    unsigned change = above ^ open[b];
    while (change != 0) {
      const int i = __builtin_ctz(change);
      change &= change - 1;
      const int c = b * kSb + i;
      if (above & (1u << i)) {
        start[c] = r;
        ++open_total;
      } else {
        runs.Add(c, start[c], r);
        --open_total;
      }
    }
    open[b] = above;
  }
  void Finish(int rows) {
    for (size_t b = 0; b < open.size(); ++b) Row(rows, static_cast<int>(b), 0);
  }
};

// Buffers kept between the calls of one thread: no page faults per frame.
struct Workspace {
  Plane a, b, c;
  Marks marks, marks2;
  Detector detectors[2];
  // per pixel type: the frames in the working orientation, the background estimated for a
  // laser-on frame alone, and EstimateBackground's buffers
  template <typename T>
  struct Buffers {
    Scratch<T> frames, background, opening[3];
  };
  Buffers<std::uint8_t> u8;
  Buffers<std::uint16_t> u16;
  template <typename T>
  Buffers<T>& Of() {
    if constexpr (sizeof(T) == 1) {
      return u8;
    } else {
      return u16;
    }
  }
};

Workspace& ThreadWorkspace() {
  thread_local Workspace w;
  return w;
}

// ------------------------------------------------------------------------------------------
// Frames in the working orientation

template <typename T>
struct Frames {
  const T* on = nullptr;
  const T* off = nullptr;
  int rows = 0, cols = 0;
  std::ptrdiff_t on_rs = 0, off_rs = 0;
  // the statistics the caller's frames take from every 4th row are every 4th column here
  // (a kRows stripe, transposed)
  bool transposed = false;
  T On(int r, int c) const { return on[r * on_rs + c]; }
  T Off(int r, int c) const { return off[r * off_rs + c]; }
};

// `src` with scan lines as columns and rows contiguous, copied into `buffer` when needed.
template <typename T>
const T* Working(const ImageView<T>& src, bool transpose, T* buffer, std::ptrdiff_t* row_stride) {
  if (!transpose && src.col_stride == 1) {
    *row_stride = src.row_stride;
    return src.data;
  }
  const int rows = transpose ? src.cols : src.rows, cols = transpose ? src.rows : src.cols;
  for (int r = 0; r < rows; ++r) {
    T* dst = buffer + static_cast<std::ptrdiff_t>(r) * cols;
    for (int c = 0; c < cols; ++c) dst[c] = transpose ? src(c, r) : src(r, c);
  }
  *row_stride = cols;
  return buffer;
}

// ------------------------------------------------------------------------------------------
// The pass over every pixel

template <typename T>
struct Stats {
  double off_mean = 0.0;
  // the plain difference's histogram over the pixels the caller's every 4th row holds, and
  // (transposed frames) over the working frames' every 4th row
  std::vector<std::uint64_t> diff_hist, albedo_hist;
  std::uint64_t diff_n = 0, albedo_n = 0;
  // 8-bit, over the pixels of diff_hist: the counts of (laser-off value, plain difference)
  // for differences below kSmall (at joint[off * kSmall + diff]), and the pixels with larger
  // differences listed (off << 8 | diff)
  static constexpr int kSmall = 8;
  std::vector<std::uint32_t> joint;
  std::vector<std::uint16_t> large;
  // the laser-off frame's every 4th row and column
  std::vector<std::uint64_t> off_hist;
  std::uint64_t off_n = 0;
  // per column: the row of the largest sum of the plain difference over 5 columns
  // (FindColumnPeaks, half width 2) and that sum
  std::vector<int> peak_row;
  std::vector<double> peak_sum;
  // per (row, block): the largest plain difference and the smallest laser-off value
  std::vector<T> max_diff, min_off;
  int blocks = 0;
};

// Counts in four interleaved 16-bit histograms (a background of a few values increments the
// same bins over and over: one histogram would wait on each increment's store), added into
// 32-bit ones before they could overflow.
class Counter {
 public:
  explicit Counter(size_t bins) : bins_(bins), part_(4 * bins, 0), total_(bins, 0) {}
  // before adding at most n counts to any one bin of a part
  void Reserve(int n) {
    if (since_ + n > 65535) Flush();
    since_ += n;
  }
  std::uint16_t* Part(int k) { return part_.data() + k * bins_; }
  const std::vector<std::uint32_t>& Total() {
    Flush();
    return total_;
  }

 private:
  void Flush() {
    for (size_t i = 0; i < bins_; ++i) {
      total_[i] +=
          std::uint32_t{part_[i]} + part_[bins_ + i] + part_[2 * bins_ + i] + part_[3 * bins_ + i];
    }
    std::fill(part_.begin(), part_.end(), 0);
    since_ = 0;
  }
  size_t bins_;
  std::vector<std::uint16_t> part_;
  std::vector<std::uint32_t> total_;
  int since_ = 0;
};

#if defined(__SSE2__)
// The largest (Max) or smallest (Min) byte of each of four vectors, in the bytes of the result:
// each step halves the bytes per vector, the vectors' partial results interleaved.
template <class Op>
std::uint32_t Reduce4(__m128i v0, __m128i v1, __m128i v2, __m128i v3, Op op) {
  const __m128i a = op(_mm_unpacklo_epi8(v0, v1), _mm_unpackhi_epi8(v0, v1));
  const __m128i b = op(_mm_unpacklo_epi8(v2, v3), _mm_unpackhi_epi8(v2, v3));
  __m128i c = op(_mm_unpacklo_epi16(a, b), _mm_unpackhi_epi16(a, b));
  c = op(c, _mm_srli_si128(c, 8));
  c = op(c, _mm_srli_si128(c, 4));
  return static_cast<std::uint32_t>(_mm_cvtsi128_si32(c));
}
// CollectStats on the first `blocks` blocks of a row of 8-bit frames: the plain difference
// into d, each block's largest difference and smallest laser-off value; returns the laser-off
// values' sum.
inline std::uint64_t Row8(const std::uint8_t* a, const std::uint8_t* b, int blocks, std::uint8_t* d,
                          std::uint8_t* mxd, std::uint8_t* mno) {
  const __m128i zero = _mm_setzero_si128();
  const auto upper = [](__m128i x, __m128i y) { return _mm_max_epu8(x, y); };
  const auto lower = [](__m128i x, __m128i y) { return _mm_min_epu8(x, y); };
  __m128i sum = zero;
  __m128i vd[4], vb[4];
  for (int k = 0; k < blocks; ++k) {
    const int q = k & 3;
    const __m128i va = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a + k * kSb));
    vb[q] = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k * kSb));
    vd[q] = _mm_subs_epu8(va, vb[q]);  // max(a - b, 0)
    _mm_storeu_si128(reinterpret_cast<__m128i*>(d + k * kSb), vd[q]);
    sum = _mm_add_epi64(sum, _mm_sad_epu8(vb[q], zero));
    if (q == 3) {
      const std::uint32_t mx = Reduce4(vd[0], vd[1], vd[2], vd[3], upper);
      const std::uint32_t mn = Reduce4(vb[0], vb[1], vb[2], vb[3], lower);
      std::memcpy(mxd + k - 3, &mx, 4);
      std::memcpy(mno + k - 3, &mn, 4);
    }
  }
  for (int k = blocks & ~3; k < blocks; ++k) {  // the last blocks, fewer than four
    const int q = k & 3;
    const std::uint32_t mx = Reduce4(vd[q], vd[q], vd[q], vd[q], upper);
    const std::uint32_t mn = Reduce4(vb[q], vb[q], vb[q], vb[q], lower);
    mxd[k] = static_cast<std::uint8_t>(mx);
    mno[k] = static_cast<std::uint8_t>(mn);
  }
  alignas(16) std::uint64_t parts[2];
  _mm_store_si128(reinterpret_cast<__m128i*>(parts), sum);
  return parts[0] + parts[1];
}
// FindColumnPeaks (half width 2) of the plain difference of 8-bit frames over the whole blocks
// of columns, given every row's block maxima `mxd` (rows x blocks): per block first the row
// where the block and its neighbours reach their largest difference, then, in row order, only
// the rows where a 5-column sum could reach the smallest of the block's maxima so far (ties:
// the first row). best / arg: per column the largest sum and its row.
inline void Peaks8(const std::uint8_t* on, std::ptrdiff_t on_rs, const std::uint8_t* off,
                   std::ptrdiff_t off_rs, int rows, int cols, const std::uint8_t* mxd, int blocks,
                   std::uint16_t* best, std::uint16_t* arg) {
  // the largest difference over each block and its neighbours (the columns its sums read),
  // and per block the first row where it is largest
  const int full_blocks = cols / kSb;
  std::vector<std::uint8_t> near(static_cast<size_t>(rows) * full_blocks);
  std::vector<std::uint8_t> top(static_cast<size_t>(full_blocks), 0);
  std::vector<int> at(static_cast<size_t>(full_blocks), 0);
  std::vector<std::uint8_t> padded(static_cast<size_t>(blocks) + 2);
  for (int r = 0; r < rows; ++r) {
    const std::uint8_t* m = mxd + static_cast<size_t>(r) * blocks;
    std::uint8_t* n = near.data() + static_cast<size_t>(r) * full_blocks;
    std::copy(m, m + blocks, padded.begin() + 1);
    padded[0] = m[0];
    padded[blocks + 1] = m[blocks - 1];
    const std::uint8_t* mp = padded.data() + 1;
    for (int k = 0; k < full_blocks; ++k) n[k] = std::max(std::max(mp[k - 1], mp[k]), mp[k + 1]);
    for (int k = 0; k < full_blocks; ++k) {
      const bool gt = n[k] > top[k];
      top[k] = gt ? n[k] : top[k];
      at[k] = gt ? r : at[k];
    }
  }
  const int full = cols / kSb;
  const __m128i zero = _mm_setzero_si128();
  const __m128i flip = _mm_set1_epi16(static_cast<short>(0x8000));  // unsigned compares
  alignas(16) std::uint8_t seg[32];
  // the plain difference over columns 16 k - 2 .. 16 k + 17 of row r (mirrored at the ends)
  auto segment = [&](int r, int k) {
    const std::uint8_t* a = on + r * on_rs;
    const std::uint8_t* b = off + r * off_rs;
    const int c0 = k * kSb - 2;
    if (c0 >= 0 && c0 + 32 <= cols) {
      for (int h = 0; h < 2; ++h) {
        const __m128i va = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a + c0 + 16 * h));
        const __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + c0 + 16 * h));
        _mm_store_si128(reinterpret_cast<__m128i*>(seg + 16 * h), _mm_subs_epu8(va, vb));
      }
    } else {
      for (int i = 0; i < kSb + 4; ++i) {
        const int c = Reflect101(c0 + i, cols);
        seg[i] = static_cast<std::uint8_t>(std::max(a[c], b[c]) - b[c]);
      }
    }
  };
  auto update = [&](int r, int k) {  // returns the block's smallest maximum
    segment(r, k);
    const __m128i vr = _mm_set1_epi16(static_cast<short>(r));
    __m128i low = _mm_set1_epi16(-1);
    for (int h = 0; h < 2; ++h) {
      __m128i s5 = zero;
      for (int j = 0; j < 5; ++j) {
        s5 = _mm_add_epi16(
            s5, _mm_unpacklo_epi8(
                    _mm_loadl_epi64(reinterpret_cast<const __m128i*>(seg + 8 * h + j)), zero));
      }
      __m128i* pb = reinterpret_cast<__m128i*>(best + k * kSb + 8 * h);
      __m128i* pa = reinterpret_cast<__m128i*>(arg + k * kSb + 8 * h);
      const __m128i vb = _mm_loadu_si128(pb), va = _mm_loadu_si128(pa);
      // sums below 2^15: signed compares; rows unsigned
      const __m128i earlier = _mm_cmplt_epi16(_mm_xor_si128(vr, flip), _mm_xor_si128(va, flip));
      const __m128i take =
          _mm_or_si128(_mm_cmpgt_epi16(s5, vb), _mm_and_si128(_mm_cmpeq_epi16(s5, vb), earlier));
      const __m128i nb = _mm_or_si128(_mm_and_si128(take, s5), _mm_andnot_si128(take, vb));
      _mm_storeu_si128(pb, nb);
      _mm_storeu_si128(pa, _mm_or_si128(_mm_and_si128(take, vr), _mm_andnot_si128(take, va)));
      low = _mm_min_epi16(low, _mm_xor_si128(nb, flip));
    }
    low = _mm_min_epi16(low, _mm_srli_si128(low, 8));
    low = _mm_min_epi16(low, _mm_srli_si128(low, 4));
    low = _mm_min_epi16(low, _mm_srli_si128(low, 2));
    return static_cast<int>(static_cast<std::uint16_t>(_mm_cvtsi128_si32(low) ^ 0x8000));
  };
  std::vector<int> floor(static_cast<size_t>(full));
  for (int k = 0; k < full; ++k) {
    // row 0 with zero sums (np.argmax of an all-zero column), then the block's peak row
    std::fill_n(best + k * kSb, kSb, 0);
    std::fill_n(arg + k * kSb, kSb, 0);
    floor[k] = update(at[k], k);
  }
  for (int r = 0; r < rows; ++r) {
    const std::uint8_t* n = near.data() + static_cast<size_t>(r) * full;
    for (int k = 0; k < full; ++k) {
      if (5 * n[k] >= floor[k]) floor[k] = update(r, k);
    }
  }
}
#endif

template <typename T>
void CollectStats(const Frames<T>& f, Stats<T>* st) {
  const int rows = f.rows, cols = f.cols;
  const size_t bins = static_cast<size_t>(std::numeric_limits<T>::max()) + 1;
  using Sum = std::conditional_t<sizeof(T) == 1, std::uint16_t, std::uint32_t>;
  constexpr int kSmall = Stats<T>::kSmall;
  st->blocks = (cols + kSb - 1) / kSb;
  st->max_diff.resize(static_cast<size_t>(rows) * st->blocks);
  st->min_off.resize(st->max_diff.size());
  st->off_hist.assign(bins, 0);
  st->diff_hist.assign(bins, 0);
  st->large.clear();
  if (f.transposed) st->albedo_hist.assign(bins, 0);
  Counter joint(sizeof(T) == 1 ? 256 * kSmall : 1);
  std::vector<std::uint16_t> keys(sizeof(T) == 1 ? static_cast<size_t>(cols) : 0);
  // the 5-column box: padded index i reads column reflect101(i - 2) (OpenCV's BORDER_REFLECT_101)
  std::vector<int> src(static_cast<size_t>(cols) + 4);
  for (size_t i = 0; i < src.size(); ++i) {
    int p = static_cast<int>(i) - 2;
    while (cols > 1 && (p < 0 || p >= cols)) p = p < 0 ? -p : 2 * (cols - 1) - p;
    src[i] = cols > 1 ? p : 0;
  }
  std::vector<T> pad(static_cast<size_t>(cols) + 4 + 16);
  std::vector<Sum> best(static_cast<size_t>(cols), 0);
  std::vector<std::uint32_t> arg(static_cast<size_t>(cols), 0);
  std::uint64_t total = 0;
  T* d = pad.data() + 2;
  Sum* bst = best.data();
  std::uint32_t* ag = arg.data();
  std::uint64_t* dh = st->diff_hist.data();
  const int full = cols / kSb;
  int boxed = 0;  // columns whose peaks the row loop leaves to Peaks8
#if defined(__SSE2__)
  // 8-bit: sixteen columns at a time (the same values); the box sums' rows in 16 bits
  const bool simd = sizeof(T) == 1 && rows <= 65535;
  if (simd) boxed = full * kSb;
#endif
  for (int r = 0; r < rows; ++r) {
    const T* a = f.on + r * f.on_rs;
    const T* b = f.off + r * f.off_rs;
    T* mxd = st->max_diff.data() + static_cast<size_t>(r) * st->blocks;
    T* mno = st->min_off.data() + static_cast<size_t>(r) * st->blocks;
    int done = 0;  // columns whose difference, sum and blocks are done
#if defined(__SSE2__)
    if constexpr (sizeof(T) == 1) {
      if (simd) {
        total += Row8(a, b, full, d, mxd, mno);
        done = full * kSb;
      }
    }
#endif
    std::conditional_t<sizeof(T) == 1, std::uint32_t, std::uint64_t> row_sum = 0;
    for (int c = done; c < cols; ++c) {
      d[c] = static_cast<T>(std::max(a[c], b[c]) - b[c]);
      row_sum += b[c];
    }
    total += row_sum;
    for (int k = done / kSb; k < full; ++k) {
      const T* dd = d + k * kSb;
      const T* bb = b + k * kSb;
      T mx = dd[0], mn = bb[0];
      for (int j = 1; j < kSb; ++j) {
        mx = std::max(mx, dd[j]);
        mn = std::min(mn, bb[j]);
      }
      mxd[k] = mx;
      mno[k] = mn;
    }
    if (full < st->blocks) {
      T mx = 0, mn = std::numeric_limits<T>::max();
      for (int c = full * kSb; c < cols; ++c) {
        mx = std::max(mx, d[c]);
        mn = std::min(mn, b[c]);
      }
      mxd[full] = mx;
      mno[full] = mn;
    }
    for (int i : {0, 1, cols + 2, cols + 3}) pad[i] = d[src[i]];
    // the column peaks (with SSE2, those of the whole blocks after this pass: Peaks8)
    for (int c = boxed; c < cols; ++c) {
      const Sum s5 =
          static_cast<Sum>(Sum(pad[c]) + pad[c + 1] + pad[c + 2] + pad[c + 3] + pad[c + 4]);
      const bool gt = s5 > bst[c];  // strictly: a tie keeps the first row (np.argmax)
      bst[c] = gt ? s5 : bst[c];
      ag[c] = gt ? static_cast<std::uint32_t>(r) : ag[c];
    }
    // the caller's every 4th row: here every 4th row, or every 4th column when transposed
    const int step = f.transposed ? 4 : 1;
    if (f.transposed || r % 4 == 0) {
      if constexpr (sizeof(T) == 1) {
        joint.Reserve((cols + 4 * step - 1) / (4 * step));
        std::uint16_t* p0 = joint.Part(0);
        std::uint16_t* p1 = joint.Part(1);
        std::uint16_t* p2 = joint.Part(2);
        std::uint16_t* p3 = joint.Part(3);
        static_assert(kSmall == 8, "the keys below shift by 3");
        int c = 0;
#if defined(__SSE2__)
        if (step == 1) {  // the keys sixteen at a time, the large differences from a mask
          const __m128i zero = _mm_setzero_si128(), seven = _mm_set1_epi8(kSmall - 1);
          for (; c + 16 <= cols; c += 16) {
            const __m128i vd = _mm_loadu_si128(reinterpret_cast<const __m128i*>(d + c));
            const __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + c));
            const __m128i small = _mm_min_epu8(vd, seven);
            _mm_storeu_si128(reinterpret_cast<__m128i*>(keys.data() + c),
                             _mm_or_si128(_mm_slli_epi16(_mm_unpacklo_epi8(vb, zero), 3),
                                          _mm_unpacklo_epi8(small, zero)));
            _mm_storeu_si128(reinterpret_cast<__m128i*>(keys.data() + c + 8),
                             _mm_or_si128(_mm_slli_epi16(_mm_unpackhi_epi8(vb, zero), 3),
                                          _mm_unpackhi_epi8(small, zero)));
            if (_mm_movemask_epi8(_mm_cmpeq_epi8(small, seven)) != 0) {
              for (int i = c; i < c + 16; ++i) {
                if (d[i] >= kSmall - 1)
                  st->large.push_back(static_cast<std::uint16_t>((b[i] << 8) | d[i]));
              }
            }
          }
        }
#endif
        for (int i = c; i < cols; i += step) {
          keys[i] = static_cast<std::uint16_t>(b[i] * kSmall + std::min<int>(d[i], kSmall - 1));
          if (d[i] >= kSmall - 1)
            st->large.push_back(static_cast<std::uint16_t>((b[i] << 8) | d[i]));
        }
        int i = 0;
        for (; i + 3 * step < cols; i += 4 * step) {
          ++p0[keys[i]];
          ++p1[keys[i + step]];
          ++p2[keys[i + 2 * step]];
          ++p3[keys[i + 3 * step]];
        }
        for (; i < cols; i += step) ++p0[keys[i]];
      } else {
        for (int c = 0; c < cols; c += step) ++dh[d[c]];
      }
      st->diff_n += static_cast<std::uint64_t>((cols + step - 1) / step);
    }
    if (f.transposed && r % 4 == 0) {
      for (int c = 0; c < cols; ++c) ++st->albedo_hist[d[c]];
      st->albedo_n += static_cast<std::uint64_t>(cols);
    }
    if (r % 4 == 0) {
      for (int c = 0; c < cols; c += 4) ++st->off_hist[b[c]];
      st->off_n += static_cast<std::uint64_t>((cols + 3) / 4);
    }
  }
  if constexpr (sizeof(T) == 1) {
    st->joint = joint.Total();
    for (int y = 0; y < 256; ++y) {
      for (int x = 0; x < kSmall - 1; ++x) dh[x] += st->joint[y * kSmall + x];
    }
    for (const std::uint16_t k : st->large) ++dh[k & 0xff];
  }
  if (!f.transposed) {
    st->albedo_hist = st->diff_hist;
    st->albedo_n = st->diff_n;
  }
  st->off_mean = static_cast<double>(total) / (static_cast<double>(rows) * cols);
#if defined(__SSE2__)
  if constexpr (sizeof(T) == 1) {
    if (simd && full > 0) {
      std::vector<std::uint16_t> b16(static_cast<size_t>(boxed)), a16(static_cast<size_t>(boxed));
      Peaks8(f.on, f.on_rs, f.off, f.off_rs, rows, cols, st->max_diff.data(), st->blocks,
             b16.data(), a16.data());
      std::copy(b16.begin(), b16.end(), best.begin());
      std::copy(a16.begin(), a16.end(), arg.begin());
    }
  }
#endif
  st->peak_row.assign(arg.begin(), arg.end());
  st->peak_sum.assign(best.begin(), best.end());
}

// The statistics of the normalised difference over the caller's every 4th row: its noise
// (EstimateDifferenceNoise) and its maximum.
template <typename T>
void DifferenceStats(const Frames<T>& f, const Stats<T>& st, const DifferenceRule<T>& rule,
                     double* noise, double* maximum) {
  if (!rule.normalize) {
    *noise = scan::NoiseFromHistogram(st.diff_hist, st.diff_n);
    size_t top = st.diff_hist.size() - 1;
    while (top > 0 && st.diff_hist[top] == 0) --top;
    *maximum = static_cast<double>(top);
    return;
  }
  std::vector<std::uint64_t> hist(st.diff_hist.size(), 0);
  if constexpr (sizeof(T) == 1) {
    constexpr int kSmall = Stats<T>::kSmall;
    for (int y = 0; y < 256; ++y) {
      for (int x = 0; x < kSmall - 1; ++x) {
        const std::uint32_t n = st.joint[y * kSmall + x];
        if (n != 0) hist[rule(x, static_cast<T>(y))] += n;
      }
    }
    for (const std::uint16_t k : st.large) ++hist[rule(k & 0xff, static_cast<T>(k >> 8))];
  } else {
    const int step = f.transposed ? 4 : 1;
    for (int r = 0; r < f.rows; ++r) {
      if (!f.transposed && r % 4 != 0) continue;
      for (int c = 0; c < f.cols; c += step) ++hist[rule.At(f.On(r, c), f.Off(r, c))];
    }
  }
  *noise = scan::NoiseFromHistogram(hist, st.diff_n);
  size_t top = hist.size() - 1;
  while (top > 0 && hist[top] == 0) --top;
  *maximum = static_cast<double>(top);
}

// The value of NumPy's percentile (method "linear") of sorted values at q in [0, 1], the
// k-th smallest value given by `kth(k)`.
template <class F>
double Percentile(std::uint64_t n, double q, F kth) {
  const double virtual_index = static_cast<double>(n - 1) * q;
  if (virtual_index >= static_cast<double>(n - 1)) return kth(n - 1);
  const double previous = std::floor(virtual_index);
  const auto i = static_cast<std::uint64_t>(previous);
  const double gamma = virtual_index - previous;
  const double a = kth(i), b = kth(i + 1);
  const double diff = b - a;
  return gamma >= 0.5 ? b - diff * (1.0 - gamma) : a + diff * gamma;
}

// ------------------------------------------------------------------------------------------
// The albedo offset (hmlvs.image.stripe.albedo_offset)

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
  std::vector<float> sorted = level;
  std::sort(sorted.begin(), sorted.end());
  auto kth = [&](std::uint64_t k) { return static_cast<double>(sorted[k]); };
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
    scan::SumShifted(line.data(), k.data(), 9, n, h.Row(r) + x0);
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

// ------------------------------------------------------------------------------------------
// Views of the difference image computed where read

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
    line_.resize(static_cast<size_t>(kSb + 2 * r_));
    plane_->Reset(n_prof, n_scan);
  }
  double at(int s, int p) const { return Value(s, p); }
  double clamped(int s, int p) const {
    return at(std::clamp(s, 0, n_scan - 1), std::clamp(p, 0, n_prof - 1));
  }
  float Value(int s, int p) const {
    const int b = s / kSb;
    if (!plane_->Has(p, b)) Compute(p, b);
    return plane_->Row(p)[s];
  }
  // the block's values (computed if not yet) from column b * kSb on
  const float* Block(int p, int b) const {
    if (!plane_->Has(p, b)) Compute(p, b);
    return plane_->Row(p) + b * kSb;
  }
  int radius() const { return r_; }
  int n_scan, n_prof;

 private:
  void Compute(int p, int b) const {
    const int c0 = b * kSb, c1 = std::min(c0 + kSb, n_scan);
    const int n = c1 - c0 + 2 * r_;
    for (int i = 0; i < n; ++i) {
      line_[i] = static_cast<float>(d_.Value(std::clamp(c0 - r_ + i, 0, n_scan - 1), p));
    }
    scan::SumShifted(line_.data(), w_.data(), 2 * r_ + 1, c1 - c0, plane_->Row(p) + c0);
    plane_->Mark(p, b);
  }
  const DView<T>& d_;
  std::vector<float> w_;
  Plane* plane_;
  int r_ = 0;
  mutable std::vector<float> line_;
};

// ------------------------------------------------------------------------------------------
// Runs above a threshold, streamed over the rows, values computed only where a bound allows

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
               StripeResult* res) {
  scan::ResetResult(v.n_scan, res);
  const scan::StegerKernels kernels = scan::StegerKernelsOf(o);
  for (int s = 0; s < v.n_scan; ++s) {
    const size_t at = static_cast<size_t>(s) * scan::kMaxRuns;
    scan::ScanLine(v, dv, s, &runs.begin[at], &runs.end[at], runs.count[s], o, kernels, res);
  }
}

// ------------------------------------------------------------------------------------------
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
  // BilateralBlock eight at a time, on CPUs with AVX2 (the same operations on each pixel, so
  // the same values: no fused multiply-add)
  __attribute__((target("avx2"))) void BilateralBlockAvx2(const T* const* rows, int x0,
                                                          float* out) const {
    const __m128i cc = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[3] + x0));
    const __m256i c0 = _mm256_cvtepu8_epi32(cc), c1 = _mm256_cvtepu8_epi32(_mm_srli_si128(cc, 8));
    __m256 s0 = _mm256_setzero_ps(), s1 = s0, w0 = s0, w1 = s0;
    const float* colour = colour_.data();
    for (const Tap& t : taps_) {
      const __m128i vv =
          _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[t.di + 3] + x0 + t.dj));
      const __m256i v0 = _mm256_cvtepu8_epi32(vv), v1 = _mm256_cvtepu8_epi32(_mm_srli_si128(vv, 8));
      const __m256 space = _mm256_set1_ps(t.w);
      const __m256 k0 = _mm256_mul_ps(
          space, _mm256_i32gather_ps(colour, _mm256_abs_epi32(_mm256_sub_epi32(v0, c0)), 4));
      const __m256 k1 = _mm256_mul_ps(
          space, _mm256_i32gather_ps(colour, _mm256_abs_epi32(_mm256_sub_epi32(v1, c1)), 4));
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
    scan::SumShifted(line_.data(), along_.data(), 2 * r + 1, x1 - x0, ft_->Row(p) + x0);
    ft_->Mark(p, b);
  }
  // the refinement's image before the smoothing along, for a block of a row in the band
  void ComputeF(int p, int b) const {
    const int x0 = b * kSb, x1 = std::min(n_scan, x0 + kSb);
    float* out = fp_->Row(p);
    if (!with_blur_) {
      for (int x = x0; x < x1; ++x) out[x] = P(p, x);
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
  std::vector<int> col_, band_;
  int radius_ = 0, pad_ = 0;
  bool with_blur_ = false;
  float level_floor_ = 1.0f, offset_f_ = 0.0f, gain_num_ = 1.0f, blur_ = 0.0f;
  mutable std::vector<float> line_;
};

// session._weighted_centres: Steger's found centres refined (RefineStripeCentres) on the
// RefineImage.
template <typename T>
bool WeightedCentres(const Frames<T>& f, bool normalize, double offset, double mean, double noise,
                     double sigma_along, double blur_var, StripeResult* st) {
  const int n = f.cols, n_prof = f.rows;
  // the band of rows each scan line's window reaches (Steger's centre +- 4.5 profile sigmas
  // plus a pixel), and the filter's 3 px more
  double lo_c = std::numeric_limits<double>::infinity(), hi_c = -lo_c;
  bool any = false;
  for (int s = 0; s < n; ++s) {
    const double c = st->centre[s], w = st->width[s];
    if (st->status[s] != static_cast<std::uint8_t>(StripeStatus::kFound) || !std::isfinite(c) ||
        !std::isfinite(w)) {
      continue;
    }
    const double reach = 4.5 * std::max(0.5, w / 2.3548) + 2.0;
    lo_c = std::min(lo_c, c - reach);
    hi_c = std::max(hi_c, c + reach);
    any = true;
  }
  if (!any) return false;
  typename RefineImage<T>::Setup o;
  o.normalize = normalize;
  o.offset = offset;
  o.mean = mean;
  o.blur_var = blur_var;
  o.frame_noise = noise / std::sqrt(2.0);  // one frame's noise, of the difference of two
  o.sigma_along = sigma_along;
  o.lo = static_cast<int>(std::max(0.0, std::floor(lo_c) - 4));
  o.hi = static_cast<int>(std::min(static_cast<double>(n_prof), std::ceil(hi_c) + 5));
  Workspace& ws = ThreadWorkspace();
  const RefineImage<T> image(f, o, &ws.a, &ws.b, &ws.c);
  // each scan line's additive noise: one frame's, times the gain at its centre (in single
  // precision, as NumPy multiplies a float by a float32 array); none within 3 sigma_along of
  // the image's ends, where the smoothing along reaches past them
  const int edge = static_cast<int>(std::ceil(3.0 * sigma_along));
  const double factor = std::sqrt(1.0 / std::max(1.0, 2.0 * std::sqrt(M_PI) * sigma_along));
  const StripeRefineOptions ro;
  // the rows each scan line's refinement reads: the window centre +- 4 profile sigmas about
  // the rounded centre, which may move half a profile sigma (RefineLine)
  std::vector<std::pair<int, int>> windows(static_cast<size_t>(n), {0, -1});
  for (int s = edge; s < n - edge; ++s) {
    const double c = st->centre[s], w = st->width[s];
    if (st->status[s] != static_cast<std::uint8_t>(StripeStatus::kFound) || !std::isfinite(c) ||
        !std::isfinite(w)) {
      continue;
    }
    const double sp = std::max(0.5, w / (2.0 * std::sqrt(2.0 * std::log(2.0))));
    const double reach = std::ceil(4.0 * sp) + 0.5 * sp + 1.0;
    windows[s] = {static_cast<int>(std::floor(c - reach)), static_cast<int>(std::ceil(c + reach))};
  }
  image.Prepare(windows, &ws.marks, &ws.marks2);
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
    scan::RefineLine(image, s, line_noise, ro, st);
    st->sigma[s] = st->sigma[s] * factor;
  }
  return true;
}

// ------------------------------------------------------------------------------------------
// The pipeline

// The thresholds of a normalised difference (session._normalized_threshold): 5 x the plain
// difference's noise x the 95th percentile of the gain over the laser-off frame's every 4th
// row and column, lowered by the smoothing's gain for `along` > 0, and at least 0.15 x the
// difference's maximum over every 4th row.
template <typename T>
double NormalisedThreshold(const Stats<T>& st, double offset, double noise, double d_max,
                           double along) {
  const double mean = st.off_mean;
  const double floor = std::max(1.0, 0.1 * mean);
  // the gain falls with the laser-off value: its k-th smallest value is that of the k-th
  // largest laser-off value
  auto kth = [&](std::uint64_t k) {
    std::uint64_t want = st.off_n - 1 - k, cum = 0;
    size_t y = 0;
    for (; y < st.off_hist.size(); ++y) {
      cum += st.off_hist[y];
      if (cum > want) break;
    }
    return (mean + offset) / std::max(static_cast<double>(y) + offset, floor);
  };
  const double p95 = Percentile(st.off_n, 0.95, kth);
  const double noise_term = 5.0 * noise * p95;
  const double top = 0.15 * d_max;
  return std::max(noise_term * (along > 0.0 ? SmoothingNoiseGain(along) : 1.0), top);
}

template <typename T>
FrameStripe PairStripe(const Frames<T>& f, const FrameStripeOptions& o) {
  FrameStripe out;
  Stats<T> st;
  CollectStats(f, &st);
  const double plain_noise = scan::NoiseFromHistogram(st.diff_hist, st.diff_n);
  bool normalize = o.normalize;
  double offset = 0.0;
  if (normalize) {
    if (std::isnan(o.albedo_offset)) {
      const double albedo_noise =
          f.transposed ? scan::NoiseFromHistogram(st.albedo_hist, st.albedo_n) : plain_noise;
      out.albedo_offset = FitOffset(f, st, albedo_noise);
      out.offset_fitted = true;
      offset = std::isnan(out.albedo_offset) ? 0.0 : out.albedo_offset;
    } else {
      offset = o.albedo_offset;
    }
    normalize = !std::isinf(offset);
  }
  DifferenceOptions dopt;
  dopt.normalize = normalize;
  dopt.offset = normalize ? offset : 0.0;
  const DifferenceRule<T> rule(dopt, st.off_mean);
  double d_noise = 0.0, d_max = 0.0;
  DifferenceStats(f, st, rule, &d_noise, &d_max);
  const DView<T> d(f, rule);

  StripeOptions second = o.stripe;
  second.direction = StripeDirection::kColumns;
  StripeOptions first = second;
  const bool automatic = second.threshold < 0.0;
  if (normalize && automatic) {
    // peaks found on the difference smoothed along the stripe, with a noise-aware threshold
    // (normalising raises the noise on dark squares); the width estimate's pass on the image
    if (!o.detect_sigma_along_given) second.detect_sigma_along = FrameStripeOptions::kDetectAlong;
    second.threshold =
        NormalisedThreshold(st, offset, plain_noise, d_max, second.detect_sigma_along);
    first.threshold = NormalisedThreshold(st, offset, plain_noise, d_max, 0.0);
    first.detect_sigma_along = 0.0;
  }
  const bool weighted = !o.method_given;
  if (weighted) first.method = StripeMethod::kCentroid;
  scan::ValidateOptions(second);
  scan::ValidateOptions(first);
  // noise and automatic thresholds as ExtractStripe takes them
  Workspace& ws = ThreadWorkspace();
  std::vector<StripeOptions*> passes = {&first, &second};
  const bool need_first = weighted && !o.steger_sigma_given;
  std::unique_ptr<SView<T>> smooth;
  std::unique_ptr<Kernels> smooth_kernel;
  for (StripeOptions* p : passes) {
    if (p->detect_sigma_along > 0.0 && !smooth_kernel) {
      smooth_kernel = std::make_unique<Kernels>(scan::MakeKernels(p->detect_sigma_along));
      smooth = std::make_unique<SView<T>>(d, *smooth_kernel, &ws.a);
    }
  }
  auto auto_threshold = [&](const StripeOptions& p, double noise) {
    if (p.threshold >= 0.0) return p.threshold;
    double mx = d_max, gain = 1.0;
    if (p.detect_sigma_along > 0.0) {
      // every 4th value of the smoothed image in memory order (ExtractStripe's rule)
      gain = std::sqrt(smooth_kernel->sum_sq0);
      mx = 0.0;
      const size_t total = static_cast<size_t>(d.n_prof) * d.n_scan;
      for (size_t i = 0; i < total; i += 4) {
        const int p_ = static_cast<int>(i / d.n_scan), s_ = static_cast<int>(i % d.n_scan);
        mx = std::max(mx, static_cast<double>(smooth->Value(s_, p_)));
      }
    }
    return std::max(5.0 * noise * gain, 0.15 * mx);
  };
  for (StripeOptions* p : passes) {
    const double noise = p->noise >= 0.0 ? p->noise : d_noise;
    p->threshold = auto_threshold(*p, noise);
  }
  Detector& det_plain = ws.detectors[0];
  Detector& det_smooth = ws.detectors[1];
  det_plain.threshold = det_smooth.threshold = -1.0;
  for (StripeOptions* p : passes) {
    if (p == &first && !need_first) continue;
    Detector& det = p->detect_sigma_along > 0.0 ? det_smooth : det_plain;
    // (the passes share a detection image only with the same threshold: the first pass is
    // the second's copy unless it alone is on the unsmoothed image)
    det.threshold = p->threshold;
  }
  DetectRuns(st, rule, d, smooth.get(), det_plain.threshold >= 0.0 ? &det_plain : nullptr,
             det_smooth.threshold >= 0.0 ? &det_smooth : nullptr);
  auto extract = [&](const StripeOptions& p, StripeResult* res) {
    res->threshold = p.threshold;
    res->noise = p.noise >= 0.0 ? p.noise : d_noise;
    if (p.detect_sigma_along > 0.0) {
      ScanLines(d, *smooth, det_smooth.runs, p, res);
    } else {
      ScanLines(d, d, det_plain.runs, p, res);
    }
  };
  if (weighted) {
    second.method = StripeMethod::kSteger;
    if (need_first) {
      StripeResult r1;
      extract(first, &r1);
      std::vector<double> w;
      for (int s = 0; s < r1.status.size(); ++s) {
        if (r1.status[s] == static_cast<std::uint8_t>(StripeStatus::kFound)) {
          w.push_back(r1.width[s]);
        }
      }
      double sigma = 3.0;
      if (!w.empty()) {
        std::sort(w.begin(), w.end());
        const size_t h = w.size() / 2;
        const double median = w.size() % 2 == 1 ? w[h] : (w[h - 1] + w[h]) / 2.0;
        sigma = std::clamp(0.5 * median, 3.0, 20.0);
      }
      second.steger_sigma = sigma;
    }
    if (!o.steger_sigma_along_given && o.smooth_along != 1.0) {
      second.steger_sigma_along = std::min(o.smooth_along * second.steger_sigma, 40.0);
    }
    scan::ValidateOptions(second);
  }
  StripeResult& res = out.stripe;
  extract(second, &res);
  if (automatic && !(res.status.array() == 0).any()) {
    // the image's maximum: over the blocks whose bound could hold it
    double mx = 0.0;
    for (int r = 0; r < f.rows; ++r) {
      for (int b = 0; b < st.blocks; ++b) {
        const size_t k = static_cast<size_t>(r) * st.blocks + b;
        if (rule.Bound(st.max_diff[k], st.min_off[k]) <= mx) continue;
        for (int c = b * kSb; c < std::min(f.cols, (b + 1) * kSb); ++c) {
          mx = std::max(mx, d.at(c, r));
        }
      }
    }
    if (res.threshold >= mx) {
      out.no_pixel = true;
      out.image_max = mx;
      return out;
    }
  }
  if (weighted) {
    const double along =
        second.steger_sigma_along > 0.0 ? second.steger_sigma_along : second.steger_sigma;
    out.refined =
        WeightedCentres(f, normalize, offset, st.off_mean, plain_noise, along, o.blur_var, &res);
  }
  if (o.assess) {
    StripeQualityOptions q;
    q.albedo_step = std::isnan(o.albedo_step) ? (normalize ? 0.0 : 1.5) : o.albedo_step;
    q.albedo_offset = normalize ? std::max(offset, 0.0) : 0.0;
    scan::ValidateQualityOptions(q);
    const scan::ScanView<T> von{f.on, f.cols, f.rows, 1, f.on_rs};
    const scan::ScanView<T> voff{f.off, f.cols, f.rows, 1, f.off_rs};
    const bool with_off = q.albedo_step > 1.0;
    std::vector<double> y;
    for (int s = 0; s < res.status.size(); ++s) {
      if (res.status[s] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
      res.status[s] = static_cast<std::uint8_t>(scan::AssessLine(
          d, von, voff, with_off, q, s, res.centre[s], res.width[s], res.threshold, &y));
    }
  }
  return out;
}

template <typename T>
void Require(const ImageView<T>& im, const char* name) {
  scan::RequireImage(im, name);
}

}  // namespace

template <typename T>
FrameStripe StripeFromFrames(const ImageView<T>& on, const ImageView<T>& off,
                             const FrameStripeOptions& o, T* background) {
  Require(on, "the laser-on image");
  const bool alone = off.data == nullptr;
  if (!alone) {
    Require(off, "the laser-off image");
    scan::RequireSameSize(on, off);
  }
  scan::ValidateOptions(o.stripe);
  if (!(o.smooth_along >= 1.0 && o.smooth_along <= 10.0) ||
      !(o.blur_var >= 0.0 && std::isfinite(o.blur_var))) {
    std::ostringstream msg;
    msg << "smooth_along must lie in [1, 10] and blur_var be a finite number >= 0, got "
        << o.smooth_along << " and " << o.blur_var;
    throw std::invalid_argument(msg.str());
  }
  const bool transpose = o.stripe.direction == StripeDirection::kRows;
  if (alone && transpose) {
    throw std::invalid_argument(
        "a laser-on image without a laser-off frame needs a roughly horizontal stripe "
        "(direction='columns')");
  }
  Workspace& ws = ThreadWorkspace();
  const size_t n = static_cast<size_t>(on.rows) * on.cols;
  T* buffer = ws.Of<T>().frames.Get(2 * n);
  Frames<T> f;
  f.rows = transpose ? on.cols : on.rows;
  f.cols = transpose ? on.rows : on.cols;
  f.transposed = transpose;
  f.on = Working(on, transpose, buffer, &f.on_rs);
  if (!alone) {
    f.off = Working(off, transpose, buffer + n, &f.off_rs);
    return PairStripe(f, o);
  }
  // the laser-on frame alone: against its background, estimated at a generous width, then
  // at the stripe's median FWHM
  FrameStripeOptions oa = o;
  if (!o.dominance_given) oa.stripe.dominance = FrameStripeOptions::kAloneDominance;
  T* bg = ws.Of<T>().background.Get(n);
  const ImageView<T> on_w{f.on, f.rows, f.cols, f.on_rs, 1};
  EstimateBackground(on_w, FrameStripeOptions::kAloneFirstWidth, bg);
  f.off = bg;
  f.off_rs = f.cols;
  FrameStripe first = PairStripe(f, oa);
  if (first.no_pixel) return first;
  std::vector<double> w;
  for (int s = 0; s < first.stripe.status.size(); ++s) {
    if (first.stripe.status[s] == static_cast<std::uint8_t>(StripeStatus::kFound)) {
      w.push_back(first.stripe.width[s]);
    }
  }
  FrameStripe out = std::move(first);
  if (!w.empty()) {
    std::sort(w.begin(), w.end());
    const size_t h = w.size() / 2;
    const double median = w.size() % 2 == 1 ? w[h] : (w[h - 1] + w[h]) / 2.0;
    EstimateBackground(on_w, median, bg);
    out = PairStripe(f, oa);
    if (out.no_pixel) return out;
  }
  out.offset_fitted = false;
  out.albedo_offset = kNaN;
  DropJumps(&out.stripe);
  if (background != nullptr) std::copy(bg, bg + n, background);
  return out;
}

template <typename T>
void EstimateBackground(const ImageView<T>& on, double width, T* out) {
  Require(on, "the laser-on image");
  if (!std::isfinite(width)) {
    std::ostringstream msg;
    msg << "the stripe width must be a finite number, got " << width;
    throw std::invalid_argument(msg.str());
  }
  const int rows = on.rows, cols = on.cols;
  const int k = std::max(9, 2 * static_cast<int>(std::ceil(1.5 * width)) + 1);
  const int h = k / 2;
  // van Herk / Gil-Werman, each row a vector of columns: over the rows extended by h replicated
  // ones either side (index i is image row i - h), per block of k of them the running extreme
  // from the block's start (g) and to its end (e); the extreme over image rows r - h .. r + h
  // (indices r .. r + 2h) is that of e at r and g at r + 2h.
  const int n = rows + 2 * h;
  const size_t size = static_cast<size_t>(n) * cols;
  Workspace& ws = ThreadWorkspace();
  T* g = ws.Of<T>().opening[0].Get(size);
  T* e = ws.Of<T>().opening[1].Get(size);
  T* eroded = ws.Of<T>().opening[2].Get(static_cast<size_t>(rows) * cols);
  auto at = [cols](T* v, int i) { return v + static_cast<size_t>(i) * cols; };
  auto pass = [&](auto pick, auto src_row, T* dst) {
    auto ext = [&](int i) { return src_row(std::clamp(i - h, 0, rows - 1)); };
    for (int b0 = 0; b0 < n; b0 += k) {
      const int b1 = std::min(n, b0 + k);
      std::copy(ext(b0), ext(b0) + cols, at(g, b0));
      for (int i = b0 + 1; i < b1; ++i) {
        const T* x = ext(i);
        const T* pg = at(g, i - 1);
        T* cg = at(g, i);
        for (int c = 0; c < cols; ++c) cg[c] = pick(pg[c], x[c]);
      }
      std::copy(ext(b1 - 1), ext(b1 - 1) + cols, at(e, b1 - 1));
      for (int i = b1 - 2; i >= b0; --i) {
        const T* x = ext(i);
        const T* ne = at(e, i + 1);
        T* ce = at(e, i);
        for (int c = 0; c < cols; ++c) ce[c] = pick(ne[c], x[c]);
      }
    }
    for (int r = 0; r < rows; ++r) {
      const T* a = at(e, r);
      const T* b = at(g, r + 2 * h);
      T* d = dst + static_cast<size_t>(r) * cols;
      for (int c = 0; c < cols; ++c) d[c] = pick(a[c], b[c]);
    }
  };
  auto lower = [](T a, T b) { return std::min(a, b); };
  auto upper = [](T a, T b) { return std::max(a, b); };
  std::vector<T> contiguous;
  const T* base = on.data;
  std::ptrdiff_t rs = on.row_stride;
  if (on.col_stride != 1) {
    contiguous.resize(static_cast<size_t>(rows) * cols);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) contiguous[static_cast<size_t>(r) * cols + c] = on(r, c);
    }
    base = contiguous.data();
    rs = cols;
  }
  pass(lower, [&](int r) { return base + r * rs; }, eroded);
  pass(upper, [&](int r) { return eroded + static_cast<size_t>(r) * cols; }, out);
}

template <typename T>
double FitAlbedoOffset(const ImageView<T>& on, const ImageView<T>& off, StripeDirection direction,
                       double* noise) {
  Require(on, "the laser-on image");
  Require(off, "the laser-off image");
  scan::RequireSameSize(on, off);
  const bool transpose = direction == StripeDirection::kRows;
  std::vector<T> buffer(2 * static_cast<size_t>(on.rows) * on.cols);
  Frames<T> f;
  f.rows = transpose ? on.cols : on.rows;
  f.cols = transpose ? on.rows : on.cols;
  f.on = Working(on, transpose, buffer.data(), &f.on_rs);
  f.off = Working(off, transpose, buffer.data() + buffer.size() / 2, &f.off_rs);
  Stats<T> st;
  CollectStats(f, &st);  // not transposed here: every 4th row of the (transposed) frames
  const double plain = scan::NoiseFromHistogram(st.diff_hist, st.diff_n);
  if (noise != nullptr) *noise = plain;
  return FitOffset(f, st, plain);
}

void DropJumps(StripeResult* stripe, int window, double jump) {
  std::vector<int> f;
  for (int s = 0; s < stripe->status.size(); ++s) {
    if (stripe->status[s] == static_cast<std::uint8_t>(StripeStatus::kFound)) f.push_back(s);
  }
  const int n = static_cast<int>(f.size());
  if (n < 5) return;
  // scipy.ndimage.median_filter(centres, size, mode="nearest"), size odd
  const int size = std::min(window, n | 1), half = size / 2;
  std::vector<double> c(static_cast<size_t>(n)), win(static_cast<size_t>(size));
  for (int i = 0; i < n; ++i) c[i] = stripe->centre[f[i]];
  std::vector<int> bad;
  for (int i = 0; i < n; ++i) {
    for (int k = -half; k <= half; ++k) win[k + half] = c[std::clamp(i + k, 0, n - 1)];
    std::nth_element(win.begin(), win.begin() + half, win.end());
    if (std::abs(c[i] - win[half]) > jump) bad.push_back(f[i]);
  }
  for (const int s : bad) stripe->status[s] = static_cast<std::uint8_t>(StripeStatus::kMultiple);
}

template FrameStripe StripeFromFrames<std::uint8_t>(const ImageView<std::uint8_t>&,
                                                    const ImageView<std::uint8_t>&,
                                                    const FrameStripeOptions&, std::uint8_t*);
template FrameStripe StripeFromFrames<std::uint16_t>(const ImageView<std::uint16_t>&,
                                                     const ImageView<std::uint16_t>&,
                                                     const FrameStripeOptions&, std::uint16_t*);
template void EstimateBackground<std::uint8_t>(const ImageView<std::uint8_t>&, double,
                                               std::uint8_t*);
template void EstimateBackground<std::uint16_t>(const ImageView<std::uint16_t>&, double,
                                                std::uint16_t*);
template double FitAlbedoOffset<std::uint8_t>(const ImageView<std::uint8_t>&,
                                              const ImageView<std::uint8_t>&, StripeDirection,
                                              double*);
template double FitAlbedoOffset<std::uint16_t>(const ImageView<std::uint16_t>&,
                                               const ImageView<std::uint16_t>&, StripeDirection,
                                               double*);

}  // namespace hmlvs
