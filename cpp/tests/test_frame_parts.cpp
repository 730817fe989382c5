// The parts of the per-frame pipeline that must give the values of plainer code to the bit:
// the refinement four scan lines at a time (RefineLines) against RefineLine, the smoothing's
// vector loops (SumShifted) against one output at a time, the running median of DropJumps
// against a median per window, and the marks of the blocks to compute ahead.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/frames.h"
#include "hmlvs/image/refine_batch.h"
#include "hmlvs/image/scan_checks.h"
#include "hmlvs/image/scan_view.h"

namespace hmlvs {
namespace {

// Float profiles along n_prof rows, one per scan line
struct Profiles {
  using Pixel = float;
  int n_scan = 0, n_prof = 0;
  std::vector<float> values;  // scan line s at s * n_prof + p
  double at(int s, int p) const { return values[static_cast<size_t>(s) * n_prof + p]; }
};

void ExpectSameDouble(double a, double b, int s) {
  if (std::isnan(b)) {
    EXPECT_TRUE(std::isnan(a)) << s;
  } else {
    EXPECT_EQ(a, b) << s;
  }
}

TEST(FrameParts, FourLanesRefineAsOneLine) {
  // speckled Gaussian profiles of varied width, height and centre; some flat (no peak: fit
  // failed), some at the image's edge (kept), some far from their start (fit failed)
  std::mt19937 gen(11);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Profiles v;
  v.n_scan = 203;
  v.n_prof = 80;
  v.values.resize(static_cast<size_t>(v.n_scan) * v.n_prof);
  StripeResult start;
  start.centre.resize(v.n_scan);
  start.width.resize(v.n_scan);
  start.sigma.resize(v.n_scan);
  start.status = Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>::Zero(v.n_scan);
  std::vector<double> line_noise(v.n_scan);
  for (int s = 0; s < v.n_scan; ++s) {
    const double centre = (s % 17 == 0) ? 3.0 + unit(gen) : 20.0 + 40.0 * unit(gen);
    const double sigma = 0.8 + 3.0 * unit(gen),
                 height = (s % 13 == 0) ? 0.0 : 50.0 + 150 * unit(gen);
    for (int p = 0; p < v.n_prof; ++p) {
      const double x = (p - centre) / sigma;
      const double value = height * std::exp(-0.5 * x * x) * (1.0 + 0.1 * noise(gen)) + noise(gen);
      v.values[static_cast<size_t>(s) * v.n_prof + p] = static_cast<float>(std::max(value, 0.0));
    }
    start.centre[s] = centre + (s % 11 == 0 ? 4.0 : 0.3 * (unit(gen) - 0.5));
    start.width[s] = 2.3548 * sigma;
    start.sigma[s] = 0.1;
    line_noise[s] = s % 19 == 0 ? -1.0 : 1.0 + unit(gen);
  }
  const StripeRefineOptions o;
  StripeResult one = start, four = start;
  for (int s = 0; s < v.n_scan; ++s) scan::RefineLine(v, s, line_noise[s], o, &one);
  scan::RefineLines<Profiles> lines(v, o, &four);
  for (int s = 0; s < v.n_scan; ++s) {
    // windows of every kind: around the centre, too short (the view read beyond), none
    const int c = static_cast<int>(start.centre[s]);
    const std::pair<int, int> rows =
        s % 3 == 0 ? std::pair{c - 20, c + 20}
                   : (s % 3 == 1 ? std::pair{c - 2, c + 2} : std::pair{0, -1});
    lines.Add(s, line_noise[s], rows);
  }
  lines.Flush();
  int found = 0, failed = 0;
  for (int s = 0; s < v.n_scan; ++s) {
    EXPECT_EQ(four.status[s], one.status[s]) << s;
    ExpectSameDouble(four.centre[s], one.centre[s], s);
    ExpectSameDouble(four.sigma[s], one.sigma[s], s);
    found += one.status[s] == 0 && one.centre[s] != start.centre[s];
    failed += one.status[s] == static_cast<std::uint8_t>(StripeStatus::kFitFailed);
  }
  EXPECT_GT(found, 100);  // the cases above all occur
  EXPECT_GT(failed, 10);
}

TEST(FrameParts, SmoothingInRegistersIsOneOutputAtATime) {
  std::mt19937 gen(12);
  std::uniform_real_distribution<float> value(0.0f, 255.0f);
  std::vector<float> line(200), w(31);
  for (float& x : line) x = value(gen);
  for (int taps : {1, 5, 15, 31}) {
    for (float& x : w) x = value(gen) / 1000.0f;
    for (int n : {1, 7, 8, 15, 16, 17, 31, 32, 33, 64, 100, 169}) {
      std::vector<float> all(static_cast<size_t>(n)), one(1);
      scan::SumShifted(line.data(), w.data(), taps, n, all.data());
      for (int s = 0; s < n; ++s) {
        scan::SumShifted(line.data() + s, w.data(), taps, 1, one.data());
        EXPECT_EQ(all[s], one[0]) << taps << " taps, " << n << " outputs, at " << s;
      }
    }
  }
}

TEST(FrameParts, RunningMedianDropsWhatWindowMediansDrop) {
  std::mt19937 gen(13);
  std::uniform_int_distribution<int> step(-3, 3);
  for (const int n : {5, 6, 20, 41, 42, 150}) {
    for (const int window : {5, 41}) {
      StripeResult r;
      r.centre.resize(n + 3);
      r.status = Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>::Zero(n + 3);
      r.status[1] = static_cast<std::uint8_t>(StripeStatus::kNone);  // not among the found
      double c = 100.0;
      for (int i = 0; i < n + 3; ++i) {
        c += 0.5 * step(gen);  // ties and jumps of up to 1.5 px
        r.centre[i] = c;
      }
      // the reference: scipy.ndimage.median_filter's median of each window, ends repeated
      std::vector<int> f;
      for (int s = 0; s < r.status.size(); ++s) {
        if (r.status[s] == 0) f.push_back(s);
      }
      const int m = static_cast<int>(f.size()), size = std::min(window, m | 1), half = size / 2;
      std::vector<std::uint8_t> want(r.status.data(), r.status.data() + r.status.size());
      for (int i = 0; i < m; ++i) {
        std::vector<double> win;
        for (int k = -half; k <= half; ++k) win.push_back(r.centre[f[std::clamp(i + k, 0, m - 1)]]);
        std::nth_element(win.begin(), win.begin() + half, win.end());
        if (std::abs(r.centre[f[i]] - win[half]) > 1.0) {
          want[f[i]] = static_cast<std::uint8_t>(StripeStatus::kMultiple);
        }
      }
      DropJumps(&r, window);
      for (int s = 0; s < r.status.size(); ++s) EXPECT_EQ(r.status[s], want[s]) << n << ", " << s;
    }
  }
}

TEST(FrameParts, MarksHoldEveryRangeMarked) {
  std::mt19937 gen(14);
  std::uniform_int_distribution<int> row(-5, 64), block(-2, 12), len(0, 6);
  scan::Marks marks;
  for (int round = 0; round < 3; ++round) {  // Reset clears what the round before marked
    marks.Reset(60, 10);
    std::set<std::pair<int, int>> want;
    for (int k = 0; k < 200; ++k) {
      const int r0 = row(gen), r1 = r0 + len(gen) - 1, b0 = block(gen), b1 = b0 + len(gen) / 3;
      marks.Mark(r0, r1, b0, b1);
      for (int r = std::max(r0, 0); r <= std::min(r1, 59); ++r) {
        for (int b = std::max(b0, 0); b <= std::min(b1, 9); ++b) want.insert({r, b});
      }
    }
    std::vector<std::pair<int, int>> got;
    marks.ForEach([&](int r, int b) { got.push_back({r, b}); });
    const std::vector<std::pair<int, int>> in_row_order(want.begin(), want.end());
    EXPECT_EQ(got, in_row_order);
  }
}

}  // namespace
}  // namespace hmlvs
