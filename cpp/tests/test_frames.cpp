// StripeFromFrames (the per-frame pipeline computed where scan lines read) against the
// whole-image steps it reproduces, its accuracy on a known stripe, the background's opening
// against its definition, threads, and bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

#include "hmlvs/image/frames.h"
#include "hmlvs/image/image.h"

namespace hmlvs {
namespace {

constexpr int kRows = 240, kCols = 320;
using Frame = std::vector<std::uint8_t>;

double TrueCentre(int c) { return 101.3 + 0.21 * c + 4.0 * std::sin(c / 37.0); }

// A laser-off frame of 64 x 64 px squares (dark 30, light 150; taller than the background's
// opening line) with noise, and its laser-on frame: a slanted, curved Gaussian stripe (sigma
// 1.5 px) whose return follows the print as off + 40, unsaturated.
void MakePair(unsigned seed, Frame* on, Frame* off) {
  std::mt19937 gen(seed);
  std::normal_distribution<double> noise(0.0, 1.2);
  on->resize(kRows * kCols);
  off->resize(kRows * kCols);
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < kCols; ++c) {
      const double level = ((r / 64 + c / 64) % 2 == 0) ? 30.0 : 150.0;
      const double x = (r - TrueCentre(c)) / 1.5;
      const double laser = 60.0 * (level + 40.0) / 150.0 * std::exp(-0.5 * x * x);
      auto px = [](double v) {
        return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
      };
      (*off)[r * kCols + c] = px(level + noise(gen));
      (*on)[r * kCols + c] = px(level + laser + noise(gen));
    }
  }
}

ImageView<std::uint8_t> View(const Frame& f) { return {f.data(), kRows, kCols, kCols, 1}; }

void ExpectSame(const StripeResult& a, const StripeResult& b) {
  ASSERT_EQ(a.status.size(), b.status.size());
  for (int s = 0; s < a.status.size(); ++s) {
    EXPECT_EQ(a.status[s], b.status[s]) << s;
    EXPECT_EQ(a.num_peaks[s], b.num_peaks[s]) << s;
    if (std::isfinite(b.centre[s])) {
      EXPECT_DOUBLE_EQ(a.centre[s], b.centre[s]) << s;
    }
    if (std::isfinite(b.width[s])) {
      EXPECT_DOUBLE_EQ(a.width[s], b.width[s]) << s;
    }
  }
  EXPECT_EQ(a.threshold, b.threshold);
  EXPECT_EQ(a.noise, b.noise);
}

TEST(Frames, DetectionWhereReadIsTheWholeImages) {
  // With a given method, threshold and offset (no fitted scale, no refinement, no checks) the
  // pipeline is ExtractStripe on DifferenceImage: the same runs, peaks and centres to the bit,
  // whether the peaks are found on the difference or on its smoothing along the stripe.
  Frame on, off;
  MakePair(1, &on, &off);
  for (const bool normalize : {false, true}) {
    for (const double along : {0.0, 2.0}) {
      for (const StripeMethod method : {StripeMethod::kCentroid, StripeMethod::kSteger}) {
        FrameStripeOptions o;
        o.normalize = normalize;
        o.albedo_offset = 12.5;
        o.assess = false;
        o.method_given = true;
        o.detect_sigma_along_given = true;
        o.stripe.method = method;
        o.stripe.steger_sigma = 2.0;
        o.stripe.threshold = normalize ? 25.0 : 20.0;
        o.stripe.detect_sigma_along = along;
        const FrameStripe got = StripeFromFrames(View(on), View(off), o);
        DifferenceOptions d;
        d.normalize = normalize;
        d.offset = normalize ? 12.5 : 0.0;
        Frame diff(on.size());
        DifferenceImage(View(on), View(off), diff.data(), d);
        ExpectSame(got.stripe, ExtractStripe(View(diff), o.stripe));
        EXPECT_FALSE(got.offset_fitted);
      }
    }
  }
}

TEST(Frames, DefaultPipelineFindsTheStripe) {
  Frame on, off;
  MakePair(2, &on, &off);
  const FrameStripe r = StripeFromFrames(View(on), View(off), FrameStripeOptions());
  EXPECT_TRUE(r.offset_fitted);
  EXPECT_TRUE(r.refined);
  // the return follows off + 40: the fit finds an offset of that order
  EXPECT_GT(r.albedo_offset, 20.0);
  EXPECT_LT(r.albedo_offset, 60.0);
  int found = 0;
  double sum2 = 0.0;
  for (int c = 0; c < kCols; ++c) {
    if (r.stripe.status[c] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    ++found;
    sum2 += (r.stripe.centre[c] - TrueCentre(c)) * (r.stripe.centre[c] - TrueCentre(c));
  }
  EXPECT_GT(found, 0.95 * kCols);
  EXPECT_LT(std::sqrt(sum2 / found), 0.05);  // measured 0.027 px
  // the laser-on frame alone: against its estimated background
  const FrameStripe alone =
      StripeFromFrames(View(on), ImageView<std::uint8_t>(), FrameStripeOptions());
  int found_alone = 0;
  double sum2_alone = 0.0;
  for (int c = 0; c < kCols; ++c) {
    if (alone.stripe.status[c] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    ++found_alone;
    sum2_alone += std::pow(alone.stripe.centre[c] - TrueCentre(c), 2);
  }
  EXPECT_GT(found_alone, 0.8 * kCols);
  // measured 0.10 px RMS, up to 1 px where the stripe crosses a corner of four squares
  EXPECT_LT(std::sqrt(sum2_alone / found_alone), 0.2);
}

TEST(Frames, ResidualsAreMeasuredUnlessAskedNotTo) {
  // without the residuals (measurement's call) the same stripe, to the bit, residuals NaN
  Frame on, off;
  MakePair(2, &on, &off);
  FrameStripeOptions without;
  without.residual = false;
  for (const ImageView<std::uint8_t>& o : {View(off), ImageView<std::uint8_t>()}) {
    const StripeResult a = StripeFromFrames(View(on), o, FrameStripeOptions()).stripe;
    const StripeResult b = StripeFromFrames(View(on), o, without).stripe;
    ExpectSame(b, a);
    EXPECT_TRUE((a.centre.array() == b.centre.array() || a.centre.array().isNaN()).all());
    EXPECT_TRUE((a.sigma.array() == b.sigma.array() || a.sigma.array().isNaN()).all());
    EXPECT_GT(a.residual.array().isFinite().count(), 0.8 * kCols);
    EXPECT_TRUE(b.residual.array().isNaN().all());
  }
}

TEST(Frames, BackgroundIsTheOpeningOfEveryColumn) {
  std::mt19937 gen(3);
  std::uniform_int_distribution<int> value(0, 255);
  for (const auto& [rows, cols] : {std::pair{40, 7}, std::pair{5, 3}, std::pair{1, 4}}) {
    Frame im(rows * cols);
    for (auto& v : im) v = static_cast<std::uint8_t>(value(gen));
    for (const double width : {1.0, 4.2, 20.0}) {
      const int h = std::max(9, 2 * static_cast<int>(std::ceil(1.5 * width)) + 1) / 2;
      Frame out(im.size()), eroded(im.size());
      EstimateBackground<std::uint8_t>({im.data(), rows, cols, cols, 1}, width, out.data());
      auto at = [&](const Frame& f, int r, int c) {
        return f[std::clamp(r, 0, rows - 1) * cols + c];
      };
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
          std::uint8_t m = 255;
          for (int k = -h; k <= h; ++k) m = std::min(m, at(im, r + k, c));
          eroded[r * cols + c] = m;
        }
      }
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
          std::uint8_t m = 0;
          for (int k = -h; k <= h; ++k) m = std::max(m, at(eroded, r + k, c));
          EXPECT_EQ(out[r * cols + c], m) << rows << " x " << cols << " at " << r << ", " << c;
        }
      }
    }
  }
}

TEST(Frames, ThreadsGiveTheSerialValues) {
  Frame on[2], off[2];
  MakePair(4, &on[0], &off[0]);
  MakePair(5, &on[1], &off[1]);
  FrameStripe serial[2], threaded[2];
  for (int k = 0; k < 2; ++k)
    serial[k] = StripeFromFrames(View(on[k]), View(off[k]), FrameStripeOptions());
  std::thread a(
      [&] { threaded[0] = StripeFromFrames(View(on[0]), View(off[0]), FrameStripeOptions()); });
  std::thread b(
      [&] { threaded[1] = StripeFromFrames(View(on[1]), View(off[1]), FrameStripeOptions()); });
  a.join();
  b.join();
  for (int k = 0; k < 2; ++k) ExpectSame(threaded[k].stripe, serial[k].stripe);
}

// A laser-on frame alone whose stripe runs down the image (the frame transposed, direction
// kRows) gives the stripe of the frame as taken, scan line for scan line, and its background
// in its own layout: the transposed background (exactly).
TEST(Frames, AloneFrameWithAVerticalStripeIsTheTransposedOne) {
  Frame on, off;
  MakePair(8, &on, &off);
  Frame tr(on.size());
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < kCols; ++c) tr[c * kRows + r] = on[r * kCols + c];
  }
  Frame bg(on.size()), bg_t(on.size());
  const FrameStripe a =
      StripeFromFrames(View(on), ImageView<std::uint8_t>(), FrameStripeOptions(), bg.data());
  FrameStripeOptions rows;
  rows.stripe.direction = StripeDirection::kRows;
  const FrameStripe b = StripeFromFrames(ImageView<std::uint8_t>{tr.data(), kCols, kRows, kRows, 1},
                                         ImageView<std::uint8_t>(), rows, bg_t.data());
  ASSERT_GT((a.stripe.status.array() == 0).count(), kCols / 2);
  // the same scan lines found, their centres within 5e-3 px: a transposed frame's albedo fit
  // takes its noise from its own histogram (PairStripe::Normalise), which moves the centres
  // by 2e-5 to 1.1e-3 px here
  ASSERT_EQ(b.stripe.status.size(), a.stripe.status.size());
  for (int s = 0; s < a.stripe.status.size(); ++s) {
    EXPECT_EQ(b.stripe.status[s], a.stripe.status[s]) << s;
    if (a.stripe.status[s] == 0) {
      EXPECT_NEAR(b.stripe.centre[s], a.stripe.centre[s], 5e-3) << s;
    }
  }
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < kCols; ++c) {
      ASSERT_EQ(bg_t[c * kRows + r], bg[r * kCols + c]) << r << ", " << c;
    }
  }
}

TEST(Frames, JumpsAndBadInput) {
  StripeResult s;
  s.centre = Eigen::VectorXd::LinSpaced(50, 10.0, 20.0);
  s.status = Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>::Zero(50);
  s.centre[20] += 2.0;
  DropJumps(&s);
  for (int i = 0; i < 50; ++i) {
    EXPECT_EQ(s.status[i], i == 20 ? static_cast<std::uint8_t>(StripeStatus::kMultiple) : 0) << i;
  }
  Frame on, off;
  MakePair(6, &on, &off);
  const ImageView<std::uint8_t> smaller{off.data(), kRows - 1, kCols, kCols, 1};
  EXPECT_THROW(StripeFromFrames(View(on), smaller, FrameStripeOptions()), std::invalid_argument);
  FrameStripeOptions bad;
  bad.smooth_along = 0.5;
  EXPECT_THROW(StripeFromFrames(View(on), View(off), bad), std::invalid_argument);
  EXPECT_THROW(EstimateBackground(View(on), std::nan(""), on.data()), std::invalid_argument);
}

}  // namespace
}  // namespace hmlvs
