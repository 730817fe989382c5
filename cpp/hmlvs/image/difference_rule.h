// The value of the (albedo-normalised) difference image at one pixel, the rule DifferenceImage
// applies and the frame pipeline reproduces where it reads. Internal (see scan_lines.h).
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <type_traits>
#include <vector>

#include "hmlvs/image/image.h"

namespace hmlvs::scan {

// DifferenceImage's value at a pixel as a function of the laser-on value's excess over the
// laser-off value, diff = max(on - off, 0) (a whole number), and the laser-off value y: the
// plain difference, or one of the two rules of the albedo normalisation (DifferenceOptions).
template <typename T>
struct DifferenceRule {
  using Acc = std::conditional_t<sizeof(T) == 1, float, double>;
  static constexpr double kTop = static_cast<double>(std::numeric_limits<T>::max());
  bool normalize = false;
  bool offset_rule = false;  // a non-zero offset: double precision, rounded half to even
  double scale = 1.0, offset = 0.0, floor = 1.0;
  std::vector<Acc> gain;      // the plain normalisation's gain per laser-off value
  std::vector<double> bound;  // per laser-off value: the gain, rounded up (see Bound)

  DifferenceRule() = default;
  // `mean`: the laser-off image's mean (the default scale and floor)
  DifferenceRule(const DifferenceOptions& o, double mean) : normalize(o.normalize) {
    if (!normalize) return;
    floor = o.floor > 0.0 ? o.floor : std::max(1.0, 0.1 * mean);
    offset = o.offset;
    offset_rule = o.offset != 0.0;
    scale = o.scale > 0.0 ? o.scale : mean + (offset_rule ? o.offset : 0.0);
    const size_t n = static_cast<size_t>(std::numeric_limits<T>::max()) + 1;
    bound.resize(n);
    if (offset_rule) {
      for (size_t y = 0; y < n; ++y) bound[y] = scale / std::max(y + offset, floor);
    } else {
      // Single precision for 8-bit images (exact enough: values below 2^12), double for 16
      gain.resize(n);
      for (size_t y = 0; y < n; ++y) {
        gain[y] = static_cast<Acc>(scale / std::max(static_cast<double>(y), floor));
        bound[y] = static_cast<double>(gain[y]);
      }
    }
    for (double& b : bound) b *= 1.0 + 1e-9;
  }
  T operator()(double diff, T y) const {
    if (!normalize) return static_cast<T>(diff);
    if (offset_rule) {
      // d = max(x - y, 0) * s / max(y + offset, floor) in NumPy's order, clipped, rounded half
      // to even by adding and subtracting 2^52 (exact for 0 <= d < 2^51 under the default
      // rounding mode; clipping before rounding gives NumPy's rint-then-clip)
      constexpr double kRound = 0x1p52;
      const double d = diff * scale / std::max(y + offset, floor);
      return static_cast<T>(static_cast<int>((std::min(std::max(d, 0.0), kTop) + kRound) - kRound));
    }
    // d >= 0.5 so truncating rounds (an int: a 64-bit conversion is ~10x slower)
    const Acc d = std::min(static_cast<Acc>(kTop), static_cast<Acc>(diff) * gain[y] + Acc(0.5));
    return static_cast<T>(static_cast<int>(d));
  }
  T At(T x, T y) const { return (*this)(static_cast<double>(std::max(x, y) - y), y); }
  // 8-bit: the value of every (laser-off y, laser-on x) pair at table[y << 8 | x]
  void Table(std::vector<T>* table) const {
    static_assert(sizeof(T) == 1, "a table of every pair of 8-bit values");
    table->assign(256 * 256, T(0));
    for (int y = 0; y < 256; ++y) {
      T* row = table->data() + (y << 8);
      if (!normalize) {
        for (int x = y + 1; x < 256; ++x) row[x] = static_cast<T>(x - y);
      } else if (offset_rule) {
        constexpr double kRound = 0x1p52;
        const double den = std::max(y + offset, floor);
        for (int x = y + 1; x < 256; ++x) {
          const double d = (x - y) * scale / den;
          row[x] = static_cast<T>(
              static_cast<int>((std::min(std::max(d, 0.0), kTop) + kRound) - kRound));
        }
      } else {
        const Acc g = gain[y];
        for (int x = y + 1; x < 256; ++x) {
          row[x] = static_cast<T>(static_cast<int>(
              std::min(static_cast<Acc>(kTop), static_cast<Acc>(x - y) * g + Acc(0.5))));
        }
      }
    }
  }
  // At least the value of any pixel whose diff is at most `diff` and laser-off value at least
  // `y` (the value grows with diff and falls with y)
  double Bound(double diff, T y) const {
    return normalize ? std::min(kTop, diff * bound[y] + 0.5) : diff;
  }
};

}  // namespace hmlvs::scan
