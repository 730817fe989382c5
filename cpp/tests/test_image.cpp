// Stripe extraction on synthetic columns: a wide noisy profile split at the threshold is one
// peak (its shoulders do not count), and AssessStripe's statuses.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

#include "hmlvs/image/image.h"

namespace hmlvs {
namespace {

constexpr int kRows = 80;

// A column-major set of profiles stored as an image (rows x cols), row-major.
struct Image {
  explicit Image(int cols) : cols(cols), data(static_cast<size_t>(kRows) * cols, 0) {}
  void Add(int c, double centre, double sigma, double peak) {
    for (int r = 0; r < kRows; ++r) {
      const double x = (r - centre) / sigma;
      const double v = at(r, c) + peak * std::exp(-0.5 * x * x);
      at(r, c) = static_cast<std::uint8_t>(std::lround(std::min(255.0, v)));
    }
  }
  std::uint8_t& at(int r, int c) { return data[static_cast<size_t>(r) * cols + c]; }
  ImageView<std::uint8_t> View() const { return {data.data(), kRows, cols, cols, 1}; }
  int cols;
  std::vector<std::uint8_t> data;
};

TEST(Stripe, WideNoisyProfileIsOnePeak) {
  // FWHM ~24 px (sigma 10), noise of +-6 grey levels: the flanks cross the threshold several
  // times, which made the old code see several peaks (MULTIPLE)
  Image im(50);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> noise(-6, 6);
  for (int c = 0; c < im.cols; ++c) {
    im.Add(c, 40.3, 10.0, 120.0);
    for (int r = 0; r < kRows; ++r) {
      im.at(r, c) = static_cast<std::uint8_t>(std::clamp(im.at(r, c) + noise(rng), 0, 255));
    }
  }
  StripeOptions o;
  o.threshold = 30.0;
  o.noise = 3.5;
  const StripeResult r = ExtractStripe(im.View(), o);
  int found = 0;
  double sum2 = 0.0;
  for (int c = 0; c < im.cols; ++c) {
    if (r.status[c] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
    ++found;
    sum2 += (r.centre[c] - 40.3) * (r.centre[c] - 40.3);
    EXPECT_EQ(r.num_peaks[c], 1);
    EXPECT_GT(r.width[c], 18.0);
  }
  EXPECT_GE(found, 48);
  EXPECT_LT(std::sqrt(sum2 / found), 0.3);
}

TEST(Stripe, AssessStripeStatuses) {
  Image d(5), on(5), off(5);
  d.Add(0, 40.2, 1.5, 200);  // clean
  d.Add(1, 1.0, 1.5, 200);   // at the border
  d.Add(2, 37.0, 1.5, 200);  // two humps in one run
  d.Add(2, 44.0, 1.5, 150);
  d.Add(3, 40.0, 1.5, 200);  // saturated in the laser-on frame
  d.Add(4, 40.0, 1.5, 200);  // an albedo step under the profile
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < 5; ++c) {
      off.at(r, c) = (c == 4 && r > 41) ? 50 : 30;
      on.at(r, c) = static_cast<std::uint8_t>(std::min(255, d.at(r, c) + off.at(r, c)));
    }
  }
  for (int r = 39; r <= 41; ++r) on.at(r, 3) = 255;
  StripeOptions o;
  o.threshold = 20.0;
  o.noise = 1.0;
  StripeResult res = ExtractStripe(d.View(), o);
  for (int c = 0; c < 5; ++c) ASSERT_EQ(res.status[c], 0) << c;
  EXPECT_LT(res.residual[0], 0.02);
  EXPECT_GT(res.residual[2], 0.05);
  const Eigen::VectorXd centre = res.centre;
  AssessStripe(d.View(), on.View(), off.View(), StripeDirection::kColumns, StripeQualityOptions(),
               &res);
  const std::vector<StripeStatus> want = {StripeStatus::kFound, StripeStatus::kClipped,
                                          StripeStatus::kDoublePeak, StripeStatus::kSaturated,
                                          StripeStatus::kAlbedoEdge};
  for (int c = 0; c < 5; ++c) EXPECT_EQ(res.status[c], static_cast<std::uint8_t>(want[c])) << c;
  EXPECT_EQ(res.centre, centre);  // centres are kept
  Image small(2);
  EXPECT_THROW(AssessStripe(d.View(), small.View(), off.View(), StripeDirection::kColumns,
                            StripeQualityOptions(), &res),
               std::invalid_argument);
}

}  // namespace
}  // namespace hmlvs
