// Stripe extraction on synthetic columns: a wide noisy profile split at the threshold is one
// peak (its shoulders do not count), and AssessStripe's statuses.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
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

TEST(Stripe, DetectionSmoothedAlongTheStripeFindsAFaintStripe) {
  // a stripe of peak 12 on Gaussian noise of 3 (4 sigmas): the automatic threshold of
  // 5 sigmas cuts most columns; found on the image smoothed 2 px along the stripe (the noise
  // 0.38 x), nearly all. The transposed image, scanned by rows, gives the same centres.
  Image im(300);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 3.0);
  for (int c = 0; c < im.cols; ++c) {
    for (int r = 0; r < kRows; ++r) {
      const double x = (r - 40.3) / 2.0;
      const double v = 12.0 * std::exp(-0.5 * x * x) + noise(rng);  // a difference image
      im.at(r, c) = static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 255.0)));
    }
  }
  std::vector<std::uint8_t> t(im.data.size());
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < im.cols; ++c) t[static_cast<size_t>(c) * kRows + r] = im.at(r, c);
  }
  StripeOptions o;
  o.method = StripeMethod::kSteger;
  o.steger_sigma = 3.0;
  o.noise = 3.0;
  auto found = [&](const StripeResult& r) {
    int n = 0;
    for (int c = 0; c < im.cols; ++c)
      n += r.status[c] == static_cast<std::uint8_t>(StripeStatus::kFound);
    return n;
  };
  const StripeResult plain = ExtractStripe(im.View(), o);
  o.detect_sigma_along = 2.0;
  const StripeResult smoothed = ExtractStripe(im.View(), o);
  EXPECT_NEAR(plain.threshold, 15.0, 1e-12);
  EXPECT_NEAR(smoothed.threshold, 15.0 * SmoothingNoiseGain(2.0), 1e-9);
  EXPECT_LT(found(plain), im.cols / 2);
  EXPECT_GT(found(smoothed), im.cols * 95 / 100);
  o.direction = StripeDirection::kRows;
  const StripeResult rows =
      ExtractStripe(ImageView<std::uint8_t>{t.data(), im.cols, kRows, kRows, 1}, o);
  for (int c = 0; c < im.cols; ++c) {
    EXPECT_EQ(rows.status[c], smoothed.status[c]);
    if (smoothed.status[c] == static_cast<std::uint8_t>(StripeStatus::kFound)) {
      EXPECT_NEAR(rows.centre[c], smoothed.centre[c], 1e-9);
    }
  }
  EXPECT_NEAR(SmoothingNoiseGain(2.0), 1.0 / std::sqrt(4.0 * std::sqrt(M_PI)), 0.002);
  EXPECT_THROW(SmoothingNoiseGain(0.1), std::invalid_argument);
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
      off.at(r, c) = (c >= 3 && r > 41) ? 50 : 30;  // a square's edge, over scan lines 3-4
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

TEST(Stripe, AlbedoEdgeIsAStepNotTheNoiseOfADarkSquare) {
  // Laser-off level 10 with +-3 grey levels of noise: single pixels vary by up to 13 / 7, but
  // no scan line is an albedo edge. A step from 10 to 40 under the profile is one, unless the
  // laser's albedo is the level plus a large offset (40 + 200 is not 1.5 x 10 + 200).
  const int cols = 40;
  Image d(cols), off(cols);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> noise(-3, 3);
  for (int c = 0; c < cols; ++c) {
    d.Add(c, 40.3, 1.5, 200);
    for (int r = 0; r < kRows; ++r) off.at(r, c) = static_cast<std::uint8_t>(10 + noise(rng));
  }
  StripeOptions o;
  o.threshold = 20.0;
  o.noise = 1.0;
  const StripeResult found = ExtractStripe(d.View(), o);
  auto edges = [&](const Image& frame, double offset) {
    StripeResult res = found;
    StripeQualityOptions q;
    q.albedo_offset = offset;
    AssessStripe(d.View(), ImageView<std::uint8_t>{}, frame.View(), StripeDirection::kColumns, q,
                 &res);
    int n = 0;
    for (int c = 0; c < cols; ++c) {
      n += res.status[c] == static_cast<std::uint8_t>(StripeStatus::kAlbedoEdge);
    }
    return n;
  };
  for (int c = 0; c < cols; ++c) ASSERT_EQ(found.status[c], 0) << c;
  EXPECT_EQ(edges(off, 0.0), 0);
  Image step = off;
  for (int r = 42; r < kRows; ++r) {
    for (int c = 0; c < cols; ++c) step.at(r, c) = static_cast<std::uint8_t>(step.at(r, c) + 30);
  }
  EXPECT_EQ(edges(step, 0.0), cols);
  EXPECT_EQ(edges(step, 200.0), 0);
  StripeResult res = found;
  StripeQualityOptions bad;
  bad.albedo_offset = -1.0;
  EXPECT_THROW(AssessStripe(d.View(), ImageView<std::uint8_t>{}, off.View(),
                            StripeDirection::kColumns, bad, &res),
               std::invalid_argument);
}

template <typename T>
void CheckOffsetNormalisation(std::mt19937* gen) {
  const int rows = 31, cols = 45;
  const int top = std::numeric_limits<T>::max();
  std::uniform_int_distribution<int> pix(0, top);
  std::vector<T> on(static_cast<size_t>(rows) * cols), off(on.size()), out(on.size());
  double sum = 0.0;
  for (size_t i = 0; i < on.size(); ++i) {
    on[i] = static_cast<T>(pix(*gen));
    off[i] = static_cast<T>(i % 3 == 0 ? pix(*gen) / 40 : pix(*gen));  // the floor acts
    sum += off[i];
  }
  const ImageView<T> a{on.data(), rows, cols, cols, 1}, b{off.data(), rows, cols, cols, 1};
  const double mean = sum / static_cast<double>(on.size());
  for (const double offset : {-25.5, -2.0, 0.7, 19.25, 3000.0}) {
    DifferenceOptions o;
    o.normalize = true;
    o.offset = offset;
    DifferenceImage(a, b, out.data(), o);
    const double scale = mean + offset, floor = std::max(1.0, 0.1 * mean);
    for (size_t i = 0; i < on.size(); ++i) {
      const double x = on[i], y = off[i];
      const double d = std::max(x - y, 0.0) * scale / std::max(y + offset, floor);
      const double want = std::clamp(std::nearbyint(d), 0.0, static_cast<double>(top));
      ASSERT_EQ(out[i], static_cast<T>(want)) << "offset " << offset << " pixel " << i;
    }
  }
}

TEST(Stripe, RefinedCentreIsExactOnSymmetricProfiles) {
  // A profile symmetric about its centre, not Gaussian (a narrow core on a wide base): the
  // odd weight puts the root at the centre, whatever the model's width, peak and noise.
  const int cols = 6;
  std::vector<float> data(static_cast<size_t>(kRows) * cols, 0.0f);
  const double centres[cols] = {30.0, 30.25, 31.5, 40.71, 45.1, 20.93};
  StripeResult r;
  r.centre.resize(cols);
  r.width = Eigen::VectorXd::Constant(cols, 5.0);
  r.sigma = Eigen::VectorXd::Constant(cols, std::numeric_limits<double>::quiet_NaN());
  r.status = Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>::Zero(cols);
  for (int c = 0; c < cols; ++c) {
    for (int row = 0; row < kRows; ++row) {
      const double x = row - centres[c];
      data[static_cast<size_t>(row) * cols + c] = static_cast<float>(
          80.0 * std::exp(-0.5 * x * x / 2.0) + 30.0 * std::exp(-0.5 * x * x / 16.0));
    }
    r.centre[c] = centres[c] + (c % 2 == 0 ? 0.3 : -0.25);  // a start off the centre
  }
  const ImageView<float> view{data.data(), kRows, cols, cols, 1};
  Eigen::VectorXd noise = Eigen::VectorXd::Constant(cols, 1.0);
  noise[cols - 1] = std::numeric_limits<double>::quiet_NaN();  // not refined
  StripeRefineOptions o;
  RefineStripeCentres(view, StripeDirection::kColumns, noise, o, &r);
  for (int c = 0; c < cols - 1; ++c) {
    EXPECT_EQ(r.status[c], static_cast<std::uint8_t>(StripeStatus::kFound)) << c;
    // to the convergence tolerance (1e-4 px) plus the sampling at whole pixels, which makes the
    // weighted sum odd only up to ~1e-4 px for this narrow core (1.4 px sigma)
    EXPECT_NEAR(r.centre[c], centres[c], 3e-4) << c;
    EXPECT_GT(r.sigma[c], 0.0) << c;
  }
  EXPECT_DOUBLE_EQ(r.centre[cols - 1], centres[cols - 1] - 0.25);

  // a start farther than half a profile sigma from the root: the scan line fails
  StripeResult far = r;
  far.centre[0] = centres[0] + 3.0;
  RefineStripeCentres(view, StripeDirection::kColumns, noise, o, &far);
  EXPECT_EQ(far.status[0], static_cast<std::uint8_t>(StripeStatus::kFitFailed));
  EXPECT_TRUE(std::isnan(far.centre[0]));

  o.speckle = -0.1;
  EXPECT_THROW(RefineStripeCentres(view, StripeDirection::kColumns, noise, o, &r),
               std::invalid_argument);
  o = StripeRefineOptions();
  EXPECT_THROW(RefineStripeCentres(view, StripeDirection::kColumns, noise.head(3), o, &r),
               std::invalid_argument);
}

TEST(Difference, OffsetNormalisationInDoubleRoundedHalfToEven) {
  std::mt19937 gen(7);
  CheckOffsetNormalisation<std::uint8_t>(&gen);
  CheckOffsetNormalisation<std::uint16_t>(&gen);
  // (on - off) x 1 / (off + 1) = 0.5, 1.5, 2.5, 3.5, 4.5 round to even; 300 clips at 255
  const std::vector<std::uint8_t> off(6, 1), on = {2, 4, 6, 8, 10, 255};
  std::vector<std::uint8_t> out(6);
  DifferenceOptions o;
  o.normalize = true;
  o.scale = 1.0;
  o.offset = 1.0;
  DifferenceImage<std::uint8_t>({on.data(), 1, 6, 6, 1}, {off.data(), 1, 6, 6, 1}, out.data(), o);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{0, 2, 2, 4, 4, 127}));
  o.scale = 3.0;
  DifferenceImage<std::uint8_t>({on.data(), 1, 6, 6, 1}, {off.data(), 1, 6, 6, 1}, out.data(), o);
  EXPECT_EQ(out[5], 255);  // 381 clipped
  o.offset = std::numeric_limits<double>::infinity();
  EXPECT_THROW(DifferenceImage<std::uint8_t>({on.data(), 1, 6, 6, 1}, {off.data(), 1, 6, 6, 1},
                                             out.data(), o),
               std::invalid_argument);
}

TEST(Difference, ColumnPeaksOfTheBoxSum) {
  // 4 x 6 image; the box sum over columns c - 1 .. c + 1 mirrors at the borders (column -1
  // reads column 1, column 6 reads column 4)
  const std::vector<std::uint16_t> im = {
      0, 9, 0, 0, 0, 0,  //
      5, 0, 0, 0, 0, 7,  //
      0, 0, 3, 3, 0, 0,  //
      0, 0, 0, 0, 4, 0,  //
  };
  const ColumnPeaks p = FindColumnPeaks<std::uint16_t>({im.data(), 4, 6, 6, 1}, 1);
  // column sums per row: row 0: 18 9 9 0 0 0; row 1: 5 5 0 0 7 7; row 2: 0 3 6 6 3 0;
  // row 3: 0 0 0 4 4 8
  EXPECT_EQ(p.row, (Eigen::VectorXi(6) << 0, 0, 0, 2, 1, 3).finished());
  EXPECT_EQ(p.sum, (Eigen::VectorXd(6) << 18, 9, 9, 6, 7, 8).finished());
  // ties keep the first row; an all-zero column gives row 0
  const std::vector<std::uint8_t> flat = {0, 2, 0, 2, 0, 2};
  const ColumnPeaks q = FindColumnPeaks<std::uint8_t>({flat.data(), 3, 2, 2, 1}, 0);
  EXPECT_EQ(q.row, (Eigen::VectorXi(2) << 0, 0).finished());
  EXPECT_EQ(q.sum, (Eigen::VectorXd(2) << 0, 2).finished());
  EXPECT_THROW(FindColumnPeaks<std::uint8_t>({flat.data(), 3, 2, 2, 1}, -1), std::invalid_argument);
}

}  // namespace
}  // namespace hmlvs
