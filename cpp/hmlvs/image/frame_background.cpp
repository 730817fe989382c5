// EstimateBackground (frames.h) and OpenColumns (frame_background.h): the laser-on frame
// opened along its columns.
#include "hmlvs/image/frame_background.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/frames.h"

namespace hmlvs {

namespace {

// The extreme (`op`: min or max) over rows r - h .. r + h of every row r of an image of
// `rows` x `cols` whose row i is `src(i)` (rows beyond it replicated), into row r at `dst(r)`:
// van Herk / Gil-Werman, each row a vector of columns: over the rows extended by h replicated
// ones either side (index i is image row i - h), per block of k = 2 h + 1 of them the running
// extreme from the block's start (g) and to its end (e); the extreme over image rows
// r - h .. r + h (indices r .. r + 2h) is that of e at r and g at r + 2h. The blocks are
// computed in turn (Step) and used at once: g of two blocks and e of one (`buffer`, 3 k rows)
// stay in the cache, and a second pass can follow this one a block or two behind, reading its
// rows as they come out (Opening). Inlined with its steps into the callers (Opening::Run and
// RunAvx2): each compiled for its caller's target.
template <typename T, class Op, class Src, class Dst>
class LinePass {
 public:
  __attribute__((always_inline)) LinePass(Src src, Dst dst, int rows, int cols, int h, Op op,
                                          T* buffer)
      : src_(src),
        dst_(dst),
        rows_(rows),
        cols_(cols),
        h_(h),
        k_(2 * h + 1),
        n_(rows + 2 * h),
        blocks_((n_ + k_ - 1) / k_),
        op_(op) {
    const size_t block = static_cast<size_t>(k_) * cols;
    gs_[0] = buffer;
    gs_[1] = buffer + block;
    e_ = buffer + 2 * block;
  }
  // the rows written so far: 0 .. emitted() - 1
  int emitted() const { return emitted_; }
  bool done() const { return emitted_ == rows_; }
  // the next block: its g, the rows of the block before it, its e (after the last block, the
  // rows of the last one)
  __attribute__((always_inline)) void Step() {
    const int j = next_++;
    if (j == blocks_) {
      Emit(j - 1);
      return;
    }
    const int b0 = j * k_, b1 = std::min(n_, b0 + k_);
    Forward(b0, b1, gs_[j & 1]);
    if (j > 0) Emit(j - 1);
    Backward(b0, b1);
  }

 private:
  T* At(T* v, int i) const { return v + static_cast<size_t>(i) * cols_; }
  const T* Ext(int i) const { return src_(std::clamp(i - h_, 0, rows_ - 1)); }
  // g of indices b0 .. b1 - 1
  __attribute__((always_inline)) void Forward(int b0, int b1, T* g) {
    const int cols = cols_;
    std::copy(Ext(b0), Ext(b0) + cols, g);
    for (int i = b0 + 1; i < b1; ++i) {
      const T* x = Ext(i);
#if defined(__SSE2__)
      const char* ahead = reinterpret_cast<const char*>(Ext(i + 4));  // on its way from memory
      for (size_t c = 0; c < cols * sizeof(T); c += 64) _mm_prefetch(ahead + c, _MM_HINT_T0);
#endif
      const T* pg = At(g, i - 1 - b0);
      T* cg = At(g, i - b0);
      for (int c = 0; c < cols; ++c) cg[c] = op_(pg[c], x[c]);
    }
  }
  // e of indices b0 .. b1 - 1
  __attribute__((always_inline)) void Backward(int b0, int b1) {
    const int cols = cols_;
    std::copy(Ext(b1 - 1), Ext(b1 - 1) + cols, At(e_, b1 - 1 - b0));
    for (int i = b1 - 2; i >= b0; --i) {
      const T* x = Ext(i);
      const T* ne = At(e_, i + 1 - b0);
      T* ce = At(e_, i - b0);
      for (int c = 0; c < cols; ++c) ce[c] = op_(ne[c], x[c]);
    }
  }
  // the output rows r of block j (r < rows): e of block j at r, g of block j or j + 1 at
  // r + 2h
  __attribute__((always_inline)) void Emit(int j) {
    const int cols = cols_, b0 = j * k_, stop = std::min(rows_, b0 + k_);
    for (int r = b0; r < stop; ++r) {
      const int i = r + 2 * h_;
      const T* a = At(e_, r - b0);
      const T* b = i < b0 + k_ ? At(gs_[j & 1], i - b0) : At(gs_[(j + 1) & 1], i - b0 - k_);
      T* d = dst_(r);
      for (int c = 0; c < cols; ++c) d[c] = op_(a[c], b[c]);
    }
    emitted_ = std::max(emitted_, stop);
  }
  Src src_;
  Dst dst_;
  int rows_, cols_, h_, k_, n_, blocks_;
  Op op_;
  T* gs_[2];
  T* e_;
  int next_ = 0, emitted_ = 0;
};

// The opening (erosion, then dilation into `out`) of the image whose row r starts at
// base + r * rs: the dilation a block behind the erosion, whose rows it reads from a ring of
// three blocks (the eroded image is never written whole).
template <typename T>
struct Opening {
  // The body, inlined into each of the entry points below (compiled for their targets).
  using Rows = std::function<void(int, int)>;
  __attribute__((always_inline)) static inline void Body(const T* base, std::ptrdiff_t rs, int rows,
                                                         int cols, int h, T* buffer, T* out,
                                                         const Rows& done) {
    auto lower = [](T a, T b) { return std::min(a, b); };
    auto upper = [](T a, T b) { return std::max(a, b); };
    const int k = 2 * h + 1;
    const size_t block = static_cast<size_t>(k) * cols;
    T* ring = buffer + 6 * block;  // eroded row r: row r % k of block (r / k) % 3
    auto eroded = [ring, k, cols, block](int r) {
      return ring + ((r / k) % 3) * block + static_cast<size_t>(r % k) * cols;
    };
    auto image = [base, rs](int r) { return base + r * rs; };
    auto output = [out, cols](int r) { return out + static_cast<size_t>(r) * cols; };
    LinePass<T, decltype(lower), decltype(image), decltype(eroded)> erode(image, eroded, rows, cols,
                                                                          h, lower, buffer);
    LinePass<T, decltype(upper), decltype(eroded), decltype(output)> dilate(
        eroded, output, rows, cols, h, upper, buffer + 3 * block);
    for (int j = 0; !dilate.done(); ++j) {
      // the dilation's block j reads the eroded rows up to (j + 1) k - 1 - h (blocks j - 1
      // and j of the ring; the erosion is at most one block ahead)
      const int need = std::min(rows, (j + 1) * k - h);
      while (erode.emitted() < need) erode.Step();
      const int before = dilate.emitted();
      dilate.Step();
      if (done && dilate.emitted() > before) done(before, dilate.emitted());
    }
  }
  static void Run(const T* base, std::ptrdiff_t rs, int rows, int cols, int h, T* buffer, T* out,
                  const Rows& done) {
    Body(base, rs, rows, cols, h, buffer, out, done);
  }
#if defined(HMLVS_AVX2)
  // the same integer operations 32 bytes at a time, on CPUs with AVX2
  __attribute__((target("avx2"))) static void RunAvx2(const T* base, std::ptrdiff_t rs, int rows,
                                                      int cols, int h, T* buffer, T* out,
                                                      const Rows& done) {
    Body(base, rs, rows, cols, h, buffer, out, done);
  }
#endif
};

}  // namespace

namespace scan {

template <typename T>
void OpenColumns(const ImageView<T>& on, double width, T* out,
                 const std::function<void(int, int)>& done) {
  RequireImage(on, "the laser-on image");
  if (!std::isfinite(width)) {
    std::ostringstream msg;
    msg << "the stripe width must be a finite number, got " << width;
    throw std::invalid_argument(msg.str());
  }
  const int rows = on.rows, cols = on.cols;
  const int k = std::max(9, 2 * static_cast<int>(std::ceil(1.5 * width)) + 1);
  const int h = k / 2;
  Workspace& ws = ThreadWorkspace();
  T* buffer = ws.Of<T>().opening.Get(9 * static_cast<size_t>(2 * h + 1) * cols);
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
  if (UseAvx2()) {
    Opening<T>::RunAvx2(base, rs, rows, cols, h, buffer, out, done);
    return;
  }
#endif
  Opening<T>::Run(base, rs, rows, cols, h, buffer, out, done);
}

template void OpenColumns<std::uint8_t>(const ImageView<std::uint8_t>&, double, std::uint8_t*,
                                        const std::function<void(int, int)>&);
template void OpenColumns<std::uint16_t>(const ImageView<std::uint16_t>&, double, std::uint16_t*,
                                         const std::function<void(int, int)>&);

}  // namespace scan

template <typename T>
void EstimateBackground(const ImageView<T>& on, double width, T* out) {
  scan::OpenColumns(on, width, out, {});
}

template void EstimateBackground<std::uint8_t>(const ImageView<std::uint8_t>&, double,
                                               std::uint8_t*);
template void EstimateBackground<std::uint16_t>(const ImageView<std::uint16_t>&, double,
                                                std::uint16_t*);

}  // namespace hmlvs
