// EstimateBackground (frames.h): the laser-on frame opened along its columns.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/frames.h"

namespace hmlvs {

namespace {

// The extreme (`op`: min or max) over rows r - h .. r + h of every row r of an image of
// `rows` x `cols` whose row i is `src(i)` (rows beyond it replicated), into dst (contiguous):
// van Herk / Gil-Werman, each row a vector of columns: over the rows extended by h replicated
// ones either side (index i is image row i - h), per block of k = 2 h + 1 of them the running
// extreme from the block's start (g) and to its end (e); the extreme over image rows
// r - h .. r + h (indices r .. r + 2h) is that of e at r and g at r + 2h. The blocks are
// computed in turn and used at once: g of two blocks and e of one (`buffer`, 3 k rows) stay
// in the cache. Inlined with its steps into the callers (Opening::Run and RunAvx2): each
// compiled for its caller's target.
template <typename T, class Op, class Src>
__attribute__((always_inline)) inline void LinePass(Src src, int rows, int cols, int h, Op op,
                                                    T* buffer, T* dst) {
  const int k = 2 * h + 1, n = rows + 2 * h;
  const size_t block = static_cast<size_t>(k) * cols;
  T* gs[2] = {buffer, buffer + block};
  T* e = buffer + 2 * block;
  auto at = [cols](T* v, int i) { return v + static_cast<size_t>(i) * cols; };
  auto ext = [&](int i) { return src(std::clamp(i - h, 0, rows - 1)); };
  // g of indices b0 .. b1 - 1
  auto forward = [&](int b0, int b1, T* g) __attribute__((always_inline)) {
    std::copy(ext(b0), ext(b0) + cols, g);
    for (int i = b0 + 1; i < b1; ++i) {
      const T* x = ext(i);
#if defined(__SSE2__)
      const char* ahead = reinterpret_cast<const char*>(ext(i + 4));  // on its way from memory
      for (size_t c = 0; c < cols * sizeof(T); c += 64) _mm_prefetch(ahead + c, _MM_HINT_T0);
#endif
      const T* pg = at(g, i - 1 - b0);
      T* cg = at(g, i - b0);
      for (int c = 0; c < cols; ++c) cg[c] = op(pg[c], x[c]);
    }
  };
  // e of indices b0 .. b1 - 1
  auto backward = [&](int b0, int b1) __attribute__((always_inline)) {
    std::copy(ext(b1 - 1), ext(b1 - 1) + cols, at(e, b1 - 1 - b0));
    for (int i = b1 - 2; i >= b0; --i) {
      const T* x = ext(i);
      const T* ne = at(e, i + 1 - b0);
      T* ce = at(e, i - b0);
      for (int c = 0; c < cols; ++c) ce[c] = op(ne[c], x[c]);
    }
  };
  // the output rows r of block j (r < rows): e of block j at r, g of block j or j + 1 at r + 2h
  auto emit = [&](int j) __attribute__((always_inline)) {
    const int b0 = j * k;
    for (int r = b0; r < std::min(rows, b0 + k); ++r) {
      const int i = r + 2 * h;
      const T* a = at(e, r - b0);
      const T* b = i < b0 + k ? at(gs[j & 1], i - b0) : at(gs[(j + 1) & 1], i - b0 - k);
      T* d = dst + static_cast<size_t>(r) * cols;
      for (int c = 0; c < cols; ++c) d[c] = op(a[c], b[c]);
    }
  };
  const int blocks = (n + k - 1) / k;
  for (int j = 0; j < blocks; ++j) {
    const int b0 = j * k, b1 = std::min(n, b0 + k);
    forward(b0, b1, gs[j & 1]);
    if (j > 0) emit(j - 1);
    backward(b0, b1);
  }
  if (static_cast<long>(blocks - 1) * k < rows) emit(blocks - 1);
}

// The opening (erosion into `eroded`, then dilation into `out`) of the image whose row r
// starts at base + r * rs.
template <typename T>
struct Opening {
  // The body, inlined into each of the entry points below (compiled for their targets).
  __attribute__((always_inline)) static inline void Body(const T* base, std::ptrdiff_t rs, int rows,
                                                         int cols, int h, T* buffer, T* eroded,
                                                         T* out) {
    auto lower = [](T a, T b) { return std::min(a, b); };
    auto upper = [](T a, T b) { return std::max(a, b); };
    LinePass<T>([&](int r) { return base + r * rs; }, rows, cols, h, lower, buffer, eroded);
    LinePass<T>([&](int r) { return eroded + static_cast<size_t>(r) * cols; }, rows, cols, h, upper,
                buffer, out);
  }
  static void Run(const T* base, std::ptrdiff_t rs, int rows, int cols, int h, T* buffer, T* eroded,
                  T* out) {
    Body(base, rs, rows, cols, h, buffer, eroded, out);
  }
#if defined(HMLVS_AVX2)
  // the same integer operations 32 bytes at a time, on CPUs with AVX2
  __attribute__((target("avx2"))) static void RunAvx2(const T* base, std::ptrdiff_t rs, int rows,
                                                      int cols, int h, T* buffer, T* eroded,
                                                      T* out) {
    Body(base, rs, rows, cols, h, buffer, eroded, out);
  }
#endif
};

}  // namespace

template <typename T>
void EstimateBackground(const ImageView<T>& on, double width, T* out) {
  scan::RequireImage(on, "the laser-on image");
  if (!std::isfinite(width)) {
    std::ostringstream msg;
    msg << "the stripe width must be a finite number, got " << width;
    throw std::invalid_argument(msg.str());
  }
  const int rows = on.rows, cols = on.cols;
  const int k = std::max(9, 2 * static_cast<int>(std::ceil(1.5 * width)) + 1);
  const int h = k / 2;
  scan::Workspace& ws = scan::ThreadWorkspace();
  T* buffer = ws.Of<T>().opening[0].Get(3 * static_cast<size_t>(2 * h + 1) * cols);
  T* eroded = ws.Of<T>().opening[1].Get(static_cast<size_t>(rows) * cols);
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
#if defined(HMLVS_AVX2)
  if (scan::UseAvx2()) {
    Opening<T>::RunAvx2(base, rs, rows, cols, h, buffer, eroded, out);
    return;
  }
#endif
  Opening<T>::Run(base, rs, rows, cols, h, buffer, eroded, out);
}

template void EstimateBackground<std::uint8_t>(const ImageView<std::uint8_t>&, double,
                                               std::uint8_t*);
template void EstimateBackground<std::uint16_t>(const ImageView<std::uint16_t>&, double,
                                                std::uint16_t*);

}  // namespace hmlvs
