// The frame pipeline's buffers (StripeFromFrames, frames.cpp): values computed per row and
// block of kSb columns on first read (Plane), the blocks to compute ahead (Marks), the runs
// above a threshold streamed over the rows (Detector), the memory kept between one thread's
// calls (Workspace), and the frames in the working orientation (Frames). Internal.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <utility>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define HMLVS_AVX2 1
#endif

#include "hmlvs/image/image.h"
#include "hmlvs/image/scan_view.h"

namespace hmlvs::scan {

constexpr int kSb = 16;  // columns of a block: the unit of the bounds and of the planes

#if defined(HMLVS_AVX2)
// Whether to take the AVX2 loops: on CPUs that have it, unless the environment variable
// HMLVS_NO_AVX2 is set (the tests compare both ways: the same values on every x86-64 CPU).
inline bool UseAvx2() {
  static const bool use = __builtin_cpu_supports("avx2") && std::getenv("HMLVS_NO_AVX2") == nullptr;
  return use;
}
#endif

// OpenCV's BORDER_REFLECT_101: index i mirrored into 0 .. n - 1 (gfedcb|abcdefgh|gfedcba)
inline int Reflect101(int i, int n) {
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
// frames lie in memory, not scattered by the order scan lines read them. Neighbouring scan
// lines mark nearly the same rows: per block, the rows of the range marked last are not
// marked again.
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
    last_.assign(static_cast<size_t>(blocks), {0, -1});
    lo_ = rows;
    hi_ = -1;
  }
  // rows r0 .. r1 and blocks b0 .. b1 (both inclusive, clipped)
  void Mark(int r0, int r1, int b0, int b1) {
    r0 = std::max(r0, 0);
    r1 = std::min(r1, rows_ - 1);
    b0 = std::max(b0, 0);
    b1 = std::min(b1, blocks_ - 1);
    if (r0 > r1) return;
    for (int b = b0; b <= b1; ++b) {
      auto& [lo, hi] = last_[static_cast<size_t>(b)];
      if (lo <= hi && r0 <= hi + 1 && r1 >= lo - 1) {  // meets the last range: its new rows
        Set(r0, std::min(r1, lo - 1), b);
        Set(std::max(r0, hi + 1), r1, b);
        lo = std::min(lo, r0);
        hi = std::max(hi, r1);
      } else {
        Set(r0, r1, b);
        lo = r0;
        hi = r1;
      }
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
  void Set(int r0, int r1, int b) {
    std::uint8_t* at = bits_.data() + static_cast<std::ptrdiff_t>(r0) * blocks_ + b;
    for (int r = r0; r <= r1; ++r, at += blocks_) *at = 1;
  }
  std::vector<std::uint8_t> bits_;
  std::vector<std::pair<int, int>> last_;  // per block: the range of rows marked last
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
  // laser-on frame alone, EstimateBackground's buffers, and the columns of a laser-on frame
  // alone its stripe's first width is measured on (and their opening)
  template <typename T>
  struct Buffers {
    Scratch<T> frames, background, opening, sample[2];
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

inline Workspace& ThreadWorkspace() {
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

}  // namespace hmlvs::scan
