// CollectStats and DifferenceStats (frame_stats.h): one pass over the rows of the frames, in
// the pixel type.
#include "hmlvs/image/frame_stats.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <type_traits>
#include <vector>

namespace hmlvs::scan {

namespace {

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

#if defined(HMLVS_AVX2)
// Row8 eight blocks at a time, on CPUs with AVX2 (the same integers): Reduce4 in each 128-bit
// lane reduces blocks k, k + 2, k + 4, k + 6 in the low lane and k + 1, ..., k + 7 in the high
// one, interleaved at the end
__attribute__((target("avx2"))) std::uint64_t Row8Avx2(const std::uint8_t* a, const std::uint8_t* b,
                                                       int blocks, std::uint8_t* d,
                                                       std::uint8_t* mxd, std::uint8_t* mno) {
  const __m256i zero = _mm256_setzero_si256();
  __m256i sum = zero;
  int k = 0;
  for (; k + 8 <= blocks; k += 8) {
    __m256i vd[4], vb[4];
    for (int q = 0; q < 4; ++q) {
      const int at = (k + 2 * q) * kSb;
      const __m256i va = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a + at));
      vb[q] = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + at));
      vd[q] = _mm256_subs_epu8(va, vb[q]);  // max(a - b, 0)
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(d + at), vd[q]);
      sum = _mm256_add_epi64(sum, _mm256_sad_epu8(vb[q], zero));
    }
    __m256i x =
        _mm256_max_epu8(_mm256_unpacklo_epi8(vd[0], vd[1]), _mm256_unpackhi_epi8(vd[0], vd[1]));
    __m256i y =
        _mm256_max_epu8(_mm256_unpacklo_epi8(vd[2], vd[3]), _mm256_unpackhi_epi8(vd[2], vd[3]));
    __m256i mx = _mm256_max_epu8(_mm256_unpacklo_epi16(x, y), _mm256_unpackhi_epi16(x, y));
    mx = _mm256_max_epu8(mx, _mm256_srli_si256(mx, 8));
    mx = _mm256_max_epu8(mx, _mm256_srli_si256(mx, 4));
    x = _mm256_min_epu8(_mm256_unpacklo_epi8(vb[0], vb[1]), _mm256_unpackhi_epi8(vb[0], vb[1]));
    y = _mm256_min_epu8(_mm256_unpacklo_epi8(vb[2], vb[3]), _mm256_unpackhi_epi8(vb[2], vb[3]));
    __m256i mn = _mm256_min_epu8(_mm256_unpacklo_epi16(x, y), _mm256_unpackhi_epi16(x, y));
    mn = _mm256_min_epu8(mn, _mm256_srli_si256(mn, 8));
    mn = _mm256_min_epu8(mn, _mm256_srli_si256(mn, 4));
    _mm_storel_epi64(
        reinterpret_cast<__m128i*>(mxd + k),
        _mm_unpacklo_epi8(_mm256_castsi256_si128(mx), _mm256_extracti128_si256(mx, 1)));
    _mm_storel_epi64(
        reinterpret_cast<__m128i*>(mno + k),
        _mm_unpacklo_epi8(_mm256_castsi256_si128(mn), _mm256_extracti128_si256(mn, 1)));
  }
  alignas(32) std::uint64_t parts[4];
  _mm256_store_si256(reinterpret_cast<__m256i*>(parts), sum);
  const std::uint64_t rest =
      k < blocks ? Row8(a + k * kSb, b + k * kSb, blocks - k, d + k * kSb, mxd + k, mno + k) : 0;
  return parts[0] + parts[1] + parts[2] + parts[3] + rest;
}
#endif
// FindColumnPeaks (half width 2) of the plain difference of 8-bit frames over the whole blocks
// of columns, given every row's block maxima `mxd` (rows x blocks): per block first the row
// where the block and its neighbours reach their largest difference, then, in row order, only
// the rows where a 5-column sum could reach the smallest of the block's maxima so far (ties:
// the first row). best / arg: per column the largest sum and its row.
class Peaks8 {
 public:
  Peaks8(const std::uint8_t* on, std::ptrdiff_t on_rs, const std::uint8_t* off,
         std::ptrdiff_t off_rs, int rows, int cols)
      : on_(on), off_(off), on_rs_(on_rs), off_rs_(off_rs), rows_(rows), cols_(cols) {}
  void Run(const std::uint8_t* mxd, int blocks, std::uint16_t* best, std::uint16_t* arg) {
    best_ = best;
    arg_ = arg;
    const int full = cols_ / kSb;
    std::vector<int> at(static_cast<size_t>(full), 0);
    NearMaxima(mxd, blocks, &at);
    // per block: the smallest of its columns' largest sums so far (below 2^15)
    std::vector<std::int16_t> floor(static_cast<size_t>(full) + 8);
    for (int k = 0; k < full; ++k) {
      // row 0 with zero sums (np.argmax of an all-zero column), then the block's peak row
      std::fill_n(best + k * kSb, kSb, 0);
      std::fill_n(arg + k * kSb, kSb, 0);
      floor[k] = static_cast<std::int16_t>(Update(at[k], k));
    }
    const __m128i zero = _mm_setzero_si128();
    for (int r = 0; r < rows_; ++r) {
      const std::uint8_t* n = near_.data() + static_cast<size_t>(r) * full;
      int k = 0;
      for (; k + 8 <= full; k += 8) {  // eight blocks at a time: those where 5 n >= floor
        const __m128i n16 =
            _mm_unpacklo_epi8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(n + k)), zero);
        const __m128i five = _mm_add_epi16(_mm_slli_epi16(n16, 2), n16);
        const __m128i fl = _mm_loadu_si128(reinterpret_cast<const __m128i*>(floor.data() + k));
        unsigned due =
            ~static_cast<unsigned>(_mm_movemask_epi8(_mm_cmplt_epi16(five, fl))) & 0xffff;
        while (due != 0) {
          const int j = k + __builtin_ctz(due) / 2;
          due &= due - 1;
          due &= due - 1;
          floor[j] = static_cast<std::int16_t>(Update(r, j));
        }
      }
      for (; k < full; ++k) {
        if (5 * n[k] >= floor[k]) floor[k] = static_cast<std::int16_t>(Update(r, k));
      }
    }
  }

 private:
  // the largest difference over each block and its neighbours (the columns its sums read),
  // and per block the first row where it is largest
  void NearMaxima(const std::uint8_t* mxd, int blocks, std::vector<int>* at) {
    const int full_blocks = cols_ / kSb;
    near_.resize(static_cast<size_t>(rows_) * full_blocks);
    std::vector<std::uint8_t> top(static_cast<size_t>(full_blocks), 0);
    std::vector<std::uint8_t> padded(static_cast<size_t>(blocks) + 2);
    for (int r = 0; r < rows_; ++r) {
      const std::uint8_t* m = mxd + static_cast<size_t>(r) * blocks;
      std::uint8_t* n = near_.data() + static_cast<size_t>(r) * full_blocks;
      std::copy(m, m + blocks, padded.begin() + 1);
      padded[0] = m[0];
      padded[blocks + 1] = m[blocks - 1];
      const std::uint8_t* mp = padded.data() + 1;
      for (int k = 0; k < full_blocks; ++k) n[k] = std::max(std::max(mp[k - 1], mp[k]), mp[k + 1]);
      for (int k = 0; k < full_blocks; ++k) {
        const bool gt = n[k] > top[k];
        top[k] = gt ? n[k] : top[k];
        (*at)[k] = gt ? r : (*at)[k];
      }
    }
  }
  // the plain difference over columns 16 k - 2 .. 16 k + 17 of row r (mirrored at the ends)
  void Segment(int r, int k) {
    const std::uint8_t* a = on_ + r * on_rs_;
    const std::uint8_t* b = off_ + r * off_rs_;
    const int c0 = k * kSb - 2;
    if (c0 >= 0 && c0 + 32 <= cols_) {
      for (int h = 0; h < 2; ++h) {
        const __m128i va = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a + c0 + 16 * h));
        const __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + c0 + 16 * h));
        _mm_store_si128(reinterpret_cast<__m128i*>(seg_ + 16 * h), _mm_subs_epu8(va, vb));
      }
    } else {
      for (int i = 0; i < kSb + 4; ++i) {
        const int c = Reflect101(c0 + i, cols_);
        seg_[i] = static_cast<std::uint8_t>(std::max(a[c], b[c]) - b[c]);
      }
    }
  }
  // the 5-column sums of row r over block k taken where larger; returns the block's smallest
  // maximum
  int Update(int r, int k) {
    Segment(r, k);
    const __m128i zero = _mm_setzero_si128();
    const __m128i flip = _mm_set1_epi16(static_cast<short>(0x8000));  // unsigned compares
    const __m128i vr = _mm_set1_epi16(static_cast<short>(r));
    __m128i low = _mm_set1_epi16(-1);
    for (int h = 0; h < 2; ++h) {
      __m128i s5 = zero;
      for (int j = 0; j < 5; ++j) {
        s5 = _mm_add_epi16(
            s5, _mm_unpacklo_epi8(
                    _mm_loadl_epi64(reinterpret_cast<const __m128i*>(seg_ + 8 * h + j)), zero));
      }
      __m128i* pb = reinterpret_cast<__m128i*>(best_ + k * kSb + 8 * h);
      __m128i* pa = reinterpret_cast<__m128i*>(arg_ + k * kSb + 8 * h);
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
  }
  const std::uint8_t* on_;
  const std::uint8_t* off_;
  std::ptrdiff_t on_rs_, off_rs_;
  int rows_, cols_;
  std::uint16_t* best_ = nullptr;
  std::uint16_t* arg_ = nullptr;
  std::vector<std::uint8_t> near_;
  alignas(16) std::uint8_t seg_[32];
};
#endif

// CollectStats' pass over the rows: per row the plain difference, the laser-off values' sum,
// the blocks' bounds and the column peaks (Row), on the rows sampled the histograms (Sample).
template <typename T>
class StatsPass {
 public:
  using Sum = std::conditional_t<sizeof(T) == 1, std::uint16_t, std::uint32_t>;
  static constexpr int kSmall = Stats<T>::kSmall;

  StatsPass(const Frames<T>& f, Stats<T>* st)
      : f_(f),
        st_(st),
        joint_(sizeof(T) == 1 ? 256 * kSmall : 1),
        keys_(sizeof(T) == 1 ? static_cast<size_t>(f.cols) : 0),
        src_(static_cast<size_t>(f.cols) + 4),
        pad_(static_cast<size_t>(f.cols) + 4 + 16),
        best_(static_cast<size_t>(f.cols), 0),
        arg_(static_cast<size_t>(f.cols), 0) {
    const int cols = f.cols;
    const size_t bins = static_cast<size_t>(std::numeric_limits<T>::max()) + 1;
    st->blocks = (cols + kSb - 1) / kSb;
    st->max_diff.resize(static_cast<size_t>(f.rows) * st->blocks);
    st->min_off.resize(st->max_diff.size());
    st->off_hist.assign(bins, 0);
    st->diff_hist.assign(bins, 0);
    st->large.clear();
    if (f.transposed) st->albedo_hist.assign(bins, 0);
    // the 5-column box: padded index i reads column reflect101(i - 2) (OpenCV's
    // BORDER_REFLECT_101)
    for (size_t i = 0; i < src_.size(); ++i) {
      int p = static_cast<int>(i) - 2;
      while (cols > 1 && (p < 0 || p >= cols)) p = p < 0 ? -p : 2 * (cols - 1) - p;
      src_[i] = cols > 1 ? p : 0;
    }
    d_ = pad_.data() + 2;
    full_ = cols / kSb;
#if defined(__SSE2__)
    // 8-bit: sixteen columns at a time (the same values); the box sums' rows in 16 bits
    simd_ = sizeof(T) == 1 && f.rows <= 65535;
    if (simd_) boxed_ = full_ * kSb;
#endif
  }
  void Row(int r) {
    const int cols = f_.cols;
    const T* a = f_.on + r * f_.on_rs;
    const T* b = f_.off + r * f_.off_rs;
    T* mxd = st_->max_diff.data() + static_cast<size_t>(r) * st_->blocks;
    T* mno = st_->min_off.data() + static_cast<size_t>(r) * st_->blocks;
    int done = 0;  // columns whose difference, sum and blocks are done
#if defined(__SSE2__)
    if (r + 4 < f_.rows) {  // the rows ahead on their way from memory
      const char* na = reinterpret_cast<const char*>(a + 4 * f_.on_rs);
      const char* nb = reinterpret_cast<const char*>(b + 4 * f_.off_rs);
      for (int c = 0; c < static_cast<int>(cols * sizeof(T)); c += 64) {
        _mm_prefetch(na + c, _MM_HINT_T0);
        _mm_prefetch(nb + c, _MM_HINT_T0);
      }
    }
    if constexpr (sizeof(T) == 1) {
      if (simd_) {
#if defined(HMLVS_AVX2)
        total_ += UseAvx2() ? Row8Avx2(a, b, full_, d_, mxd, mno) : Row8(a, b, full_, d_, mxd, mno);
#else
        total_ += Row8(a, b, full_, d_, mxd, mno);
#endif
        done = full_ * kSb;
      }
    }
#endif
    T* d = d_;
    std::conditional_t<sizeof(T) == 1, std::uint32_t, std::uint64_t> row_sum = 0;
    for (int c = done; c < cols; ++c) {
      d[c] = static_cast<T>(std::max(a[c], b[c]) - b[c]);
      row_sum += b[c];
    }
    total_ += row_sum;
    Blocks(b, done / kSb, mxd, mno);
    for (int i : {0, 1, cols + 2, cols + 3}) pad_[i] = d[src_[i]];
    // the column peaks (with SSE2, those of the whole blocks after this pass: Peaks8)
    const T* pad = pad_.data();
    Sum* bst = best_.data();
    std::uint32_t* ag = arg_.data();
    for (int c = boxed_; c < cols; ++c) {
      const Sum s5 =
          static_cast<Sum>(Sum(pad[c]) + pad[c + 1] + pad[c + 2] + pad[c + 3] + pad[c + 4]);
      const bool gt = s5 > bst[c];  // strictly: a tie keeps the first row (np.argmax)
      bst[c] = gt ? s5 : bst[c];
      ag[c] = gt ? static_cast<std::uint32_t>(r) : ag[c];
    }
  }
  void Sample(int r) {
    const int cols = f_.cols;
    const T* b = f_.off + r * f_.off_rs;
    const T* d = d_;
    // the caller's every 4th row: here every 4th row, or every 4th column when transposed
    const int step = f_.transposed ? 4 : 1;
    if (f_.transposed || r % 4 == 0) {
      if constexpr (sizeof(T) == 1) {
        Joint(b, step);
      } else {
        std::uint64_t* dh = st_->diff_hist.data();
        for (int c = 0; c < cols; c += step) ++dh[d[c]];
      }
      st_->diff_n += static_cast<std::uint64_t>((cols + step - 1) / step);
    }
    if (f_.transposed && r % 4 == 0) {
      for (int c = 0; c < cols; ++c) ++st_->albedo_hist[d[c]];
      st_->albedo_n += static_cast<std::uint64_t>(cols);
    }
    if (r % 4 == 0) {
      if constexpr (sizeof(T) == 1) {
        // four interleaved histograms (a background of a few values: see Counter)
        std::uint32_t* h = off_parts_.data();
        int c = 0;
        for (; c + 12 < cols; c += 16) {
          ++h[b[c]];
          ++h[256 + b[c + 4]];
          ++h[512 + b[c + 8]];
          ++h[768 + b[c + 12]];
        }
        for (; c < cols; c += 4) ++h[b[c]];
      } else {
        for (int c = 0; c < cols; c += 4) ++st_->off_hist[b[c]];
      }
      st_->off_n += static_cast<std::uint64_t>((cols + 3) / 4);
    }
  }
  void Finish() {
    Stats<T>* st = st_;
    if constexpr (sizeof(T) == 1) {
      for (int y = 0; y < 256; ++y) {
        st->off_hist[y] = std::uint64_t{off_parts_[y]} + off_parts_[256 + y] + off_parts_[512 + y] +
                          off_parts_[768 + y];
      }
      std::uint64_t* dh = st->diff_hist.data();
      st->joint = joint_.Total();
      for (int y = 0; y < 256; ++y) {
        for (int x = 0; x < kSmall - 1; ++x) dh[x] += st->joint[y * kSmall + x];
      }
      for (const std::uint16_t k : st->large) ++dh[k & 0xff];
    }
    if (!f_.transposed) {
      st->albedo_hist = st->diff_hist;
      st->albedo_n = st->diff_n;
    }
    st->off_mean = static_cast<double>(total_) / (static_cast<double>(f_.rows) * f_.cols);
#if defined(__SSE2__)
    if constexpr (sizeof(T) == 1) {
      if (simd_ && full_ > 0) {
        std::vector<std::uint16_t> b16(static_cast<size_t>(boxed_)), a16(b16.size());
        Peaks8(f_.on, f_.on_rs, f_.off, f_.off_rs, f_.rows, f_.cols)
            .Run(st->max_diff.data(), st->blocks, b16.data(), a16.data());
        std::copy(b16.begin(), b16.end(), best_.begin());
        std::copy(a16.begin(), a16.end(), arg_.begin());
      }
    }
#endif
    st->peak_row.assign(arg_.begin(), arg_.end());
    st->peak_sum.assign(best_.begin(), best_.end());
  }

 private:
  // the largest difference and the smallest laser-off value of the blocks from `first` on
  void Blocks(const T* b, int first, T* mxd, T* mno) const {
    const T* d = d_;
    for (int k = first; k < full_; ++k) {
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
    if (full_ < st_->blocks) {
      T mx = 0, mn = std::numeric_limits<T>::max();
      for (int c = full_ * kSb; c < f_.cols; ++c) {
        mx = std::max(mx, d[c]);
        mn = std::min(mn, b[c]);
      }
      mxd[full_] = mx;
      mno[full_] = mn;
    }
  }
  // 8-bit: the joint counts of (laser-off value, small difference) of every `step`-th column,
  // the larger differences listed
  void Joint(const T* b, int step) {
    const int cols = f_.cols;
    const T* d = d_;
    std::uint16_t* keys = keys_.data();
    std::vector<std::uint16_t>& large = st_->large;
    joint_.Reserve((cols + 4 * step - 1) / (4 * step));
    static_assert(kSmall == 8, "the keys below shift by 3");
    int c = 0;
#if defined(__SSE2__)
    if (step == 1) {  // the keys sixteen at a time, the large differences from a mask
      const __m128i zero = _mm_setzero_si128(), seven = _mm_set1_epi8(kSmall - 1);
      for (; c + 16 <= cols; c += 16) {
        const __m128i vd = _mm_loadu_si128(reinterpret_cast<const __m128i*>(d + c));
        const __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b + c));
        const __m128i small = _mm_min_epu8(vd, seven);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(keys + c),
                         _mm_or_si128(_mm_slli_epi16(_mm_unpacklo_epi8(vb, zero), 3),
                                      _mm_unpacklo_epi8(small, zero)));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(keys + c + 8),
                         _mm_or_si128(_mm_slli_epi16(_mm_unpackhi_epi8(vb, zero), 3),
                                      _mm_unpackhi_epi8(small, zero)));
        if (_mm_movemask_epi8(_mm_cmpeq_epi8(small, seven)) != 0) {
          for (int i = c; i < c + 16; ++i) {
            if (d[i] >= kSmall - 1) large.push_back(static_cast<std::uint16_t>((b[i] << 8) | d[i]));
          }
        }
      }
    }
#endif
    for (int i = c; i < cols; i += step) {
      keys[i] = static_cast<std::uint16_t>(b[i] * kSmall + std::min<int>(d[i], kSmall - 1));
      if (d[i] >= kSmall - 1) large.push_back(static_cast<std::uint16_t>((b[i] << 8) | d[i]));
    }
    std::uint16_t* p0 = joint_.Part(0);
    std::uint16_t* p1 = joint_.Part(1);
    std::uint16_t* p2 = joint_.Part(2);
    std::uint16_t* p3 = joint_.Part(3);
    int i = 0;
    for (; i + 3 * step < cols; i += 4 * step) {
      ++p0[keys[i]];
      ++p1[keys[i + step]];
      ++p2[keys[i + 2 * step]];
      ++p3[keys[i + 3 * step]];
    }
    for (; i < cols; i += step) ++p0[keys[i]];
  }

  const Frames<T>& f_;
  Stats<T>* st_;
  Counter joint_;
  std::vector<std::uint16_t> keys_;
  std::vector<int> src_;
  std::vector<T> pad_;
  std::vector<Sum> best_;
  std::vector<std::uint32_t> arg_;
  std::vector<std::uint32_t> off_parts_ = std::vector<std::uint32_t>(sizeof(T) == 1 ? 4 * 256 : 0);
  T* d_ = nullptr;
  std::uint64_t total_ = 0;
  int full_ = 0;
  int boxed_ = 0;  // columns whose peaks the row loop leaves to Peaks8
  bool simd_ = false;
};

}  // namespace

template <typename T>
class StatsCollector<T>::Pass : public StatsPass<T> {
 public:
  using StatsPass<T>::StatsPass;
};

template <typename T>
StatsCollector<T>::StatsCollector(const Frames<T>& f, Stats<T>* st)
    : pass_(std::make_unique<Pass>(f, st)) {}

template <typename T>
StatsCollector<T>::~StatsCollector() = default;

template <typename T>
void StatsCollector<T>::Rows(int r0, int r1) {
  for (int r = r0; r < r1; ++r) {
    pass_->Row(r);
    pass_->Sample(r);
  }
}

template <typename T>
void StatsCollector<T>::Finish() {
  pass_->Finish();
}

// The statistics of the normalised difference over the caller's every 4th row: its noise
// (EstimateDifferenceNoise) and its maximum.
template <typename T>
void DifferenceStats(const Frames<T>& f, const Stats<T>& st, const DifferenceRule<T>& rule,
                     double* noise, double* maximum) {
  if (!rule.normalize) {
    *noise = NoiseFromHistogram(st.diff_hist, st.diff_n);
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
  *noise = NoiseFromHistogram(hist, st.diff_n);
  size_t top = hist.size() - 1;
  while (top > 0 && hist[top] == 0) --top;
  *maximum = static_cast<double>(top);
}

template class StatsCollector<std::uint8_t>;
template class StatsCollector<std::uint16_t>;
template void DifferenceStats<std::uint8_t>(const Frames<std::uint8_t>&, const Stats<std::uint8_t>&,
                                            const DifferenceRule<std::uint8_t>&, double*, double*);
template void DifferenceStats<std::uint16_t>(const Frames<std::uint16_t>&,
                                             const Stats<std::uint16_t>&,
                                             const DifferenceRule<std::uint16_t>&, double*,
                                             double*);

}  // namespace hmlvs::scan
