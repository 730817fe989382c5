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
  // van Herk / Gil-Werman, each row a vector of columns: over the rows extended by h replicated
  // ones either side (index i is image row i - h), per block of k of them the running extreme
  // from the block's start (g) and to its end (e); the extreme over image rows r - h .. r + h
  // (indices r .. r + 2h) is that of e at r and g at r + 2h.
  const int n = rows + 2 * h;
  const size_t size = static_cast<size_t>(n) * cols;
  scan::Workspace& ws = scan::ThreadWorkspace();
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

template void EstimateBackground<std::uint8_t>(const ImageView<std::uint8_t>&, double,
                                               std::uint8_t*);
template void EstimateBackground<std::uint16_t>(const ImageView<std::uint16_t>&, double,
                                                std::uint16_t*);

}  // namespace hmlvs
