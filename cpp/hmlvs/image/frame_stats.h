// The frame pipeline's pass over every pixel (StripeFromFrames, frames.cpp): what the
// thresholds, the noise, the albedo fit and the bounds on the difference need, gathered in
// the pixel type in one pass over the rows. Internal.
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include "hmlvs/image/difference_rule.h"
#include "hmlvs/image/frame_buffers.h"

namespace hmlvs::scan {

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

// The statistics of the frames `f` (one pass over every pixel), a few rows at a time as the
// frames' rows become final: Rows(r0, r1) for rows r0 .. r1 - 1 (in order, every row once),
// then Finish.
template <typename T>
class StatsCollector {
 public:
  StatsCollector(const Frames<T>& f, Stats<T>* st);
  ~StatsCollector();
  void Rows(int r0, int r1);
  void Finish();

 private:
  class Pass;
  std::unique_ptr<Pass> pass_;
};

// The statistics of the frames `f`, in one pass over the rows.
template <typename T>
void CollectStats(const Frames<T>& f, Stats<T>* st) {
  StatsCollector<T> stats(f, st);
  stats.Rows(0, f.rows);
  stats.Finish();
}

// The statistics of the normalised difference over the caller's every 4th row: its noise
// (EstimateDifferenceNoise) and its maximum.
template <typename T>
void DifferenceStats(const Frames<T>& f, const Stats<T>& st, const DifferenceRule<T>& rule,
                     double* noise, double* maximum);

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

}  // namespace hmlvs::scan
