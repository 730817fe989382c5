// A frame's stripe measured (measure/profile.h) with either model: on every found scan line the
// camera point of the model's batch function to the bit (opencv::LaserPointsInCamera within the
// image, paper::CameraPointsFromPixels with measurement's grazing check), the base point of its
// batch function (LaserPointsInBase, BasePointsFromPixels: another order of the same sums) to
// 1e-9 mm, the statuses that say why a scan line has no point; a stripe along image rows is
// refused.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <stdexcept>

#include "hmlvs/geometry/geometry.h"
#include "hmlvs/measure/profile.h"
#include "hmlvs/model/opencv.h"
#include "hmlvs/model/opencv_fitness.h"
#include "hmlvs/model/paper.h"
#include "test_util.h"

namespace hmlvs {
namespace {

constexpr int kCols = 1024, kRows = 768;
constexpr auto kFound = static_cast<std::uint8_t>(StripeStatus::kFound);

// A stripe across a 1024 x 768 image from row 40 to row 740 (the general camera's rays meet its
// laser plane on the lower part only; the paper sensor's rays at all of them), with a few
// scan lines without a centre and a few found centres off the image.
StripeResult Stripe() {
  StripeResult s;
  s.centre.resize(kCols);
  s.status.resize(kCols);
  for (int i = 0; i < kCols; ++i) {
    s.centre[i] = 40.0 + 700.0 * i / (kCols - 1) + 0.3 * std::sin(0.05 * i);
    s.status[i] = kFound;
    if (i % 17 == 3) {
      s.centre[i] = std::nan("");
      s.status[i] =
          static_cast<std::uint8_t>(i % 2 ? StripeStatus::kNone : StripeStatus::kMultiple);
    }
  }
  s.centre[100] = -0.7;         // off the image: no point for the general model
  s.centre[900] = kRows - 0.5;  // on the image's edge: in it
  s.centre[901] = kRows - 0.49;
  return s;
}

Eigen::Matrix4d BaseFromHand() {
  const double w[3] = {0.3, -0.2, 0.9};
  return geometry::Transform(geometry::Rodrigues(w), Eigen::Vector3d(420.0, -130.0, 610.0));
}

// BaseFromHand() as m rows of poses (row-major 4x4 each).
RowMatX16 Poses(Eigen::Index m) {
  const Eigen::Matrix<double, 4, 4, Eigen::RowMajor> pose = BaseFromHand();
  RowMatX16 poses(m, 16);
  for (Eigen::Index k = 0; k < m; ++k) {
    poses.row(k) = Eigen::Map<const Eigen::Matrix<double, 1, 16>>(pose.data());
  }
  return poses;
}

// The found scan lines' pixels (u, v).
RowMatX2 FoundPixels(const StripeResult& s, Eigen::VectorXi* lines) {
  int m = 0;
  for (int i = 0; i < kCols; ++i) m += s.status[i] == kFound;
  RowMatX2 px(m, 2);
  lines->resize(m);
  for (int i = 0, k = 0; i < kCols; ++i) {
    if (s.status[i] != kFound) continue;
    px.row(k) << i, s.centre[i];
    (*lines)[k++] = i;
  }
  return px;
}

// The profile against the batch functions' camera and base points of the found pixels (`inside`:
// whether pixel k lies in the image, which the general model requires).
void ExpectProfile(const FrameProfile& p, const StripeResult& s, const Eigen::VectorXi& lines,
                   const PointsResult& camera, const PointsResult& base, const Mask& inside) {
  ASSERT_EQ(p.status.size(), kCols);
  EXPECT_EQ(p.stripe_status, s.status);
  int measured = 0, no_point = 0;
  for (Eigen::Index k = 0; k < lines.size(); ++k) {
    const int i = lines[k];
    EXPECT_EQ(p.pixels(i, 0), i);
    EXPECT_EQ(p.pixels(i, 1), s.centre[i]);
    if (camera.valid[k] && inside[k]) {
      ++measured;
      EXPECT_EQ(p.status[i], static_cast<std::uint8_t>(PointStatus::kMeasured));
      EXPECT_TRUE(test::BitIdentical(Eigen::Vector3d(p.camera_points.row(i).transpose()),
                                     Eigen::Vector3d(camera.points.row(k).transpose())))
          << "scan line " << i;
      EXPECT_LT((p.points.row(i) - base.points.row(k)).cwiseAbs().maxCoeff(), 1e-9);
    } else {
      ++no_point;
      EXPECT_EQ(p.status[i], static_cast<std::uint8_t>(PointStatus::kNoPoint));
      EXPECT_TRUE(p.points.row(i).hasNaN() && p.camera_points.row(i).hasNaN());
    }
  }
  for (int i = 0; i < kCols; ++i) {
    if (s.status[i] == kFound) continue;
    EXPECT_EQ(p.status[i], static_cast<std::uint8_t>(PointStatus::kNoStripe));
    EXPECT_TRUE(p.pixels.row(i).array().isNaN().all() && p.points.row(i).array().isNaN().all());
  }
  EXPECT_GT(measured, 300);
  EXPECT_GT(no_point, 0);  // some found centres have no point: the check is exercised
}

TEST(Profile, GeneralModelGivesItsBatchFunctionsPoints) {
  opencv::IntrinsicsVector in = opencv::IntrinsicsVector::Zero();
  in.head<opencv::kNumClassicIntrinsics>() << 1100, 1090, 512, 384, -0.165, 0.05, 0.0005, -0.0003,
      0.01;
  const double w[3] = {0.02, -0.03, 1.6};
  const Eigen::Matrix4d hfc =
      geometry::Transform(geometry::Rodrigues(w), Eigen::Vector3d(60.0, 5.0, -45.0));
  const Eigen::Vector4d plane = 3.0 * opencv::PlaneFromAngles(0.03, 0.45, 90.0);  // not unit
  const LaserSensor sensor = LaserSensor::OpenCv(in, plane, hfc, kCols, kRows);
  const StripeResult s = Stripe();
  const FrameProfile p = MeasureStripe(sensor, s, StripeDirection::kColumns, BaseFromHand());
  Eigen::VectorXi lines;
  const RowMatX2 px = FoundPixels(s, &lines);
  Mask inside(px.rows());
  for (Eigen::Index k = 0; k < px.rows(); ++k) {
    inside[k] = px(k, 1) >= -0.5 && px(k, 1) <= kRows - 0.5;
  }
  EXPECT_EQ(inside.cast<int>().sum(), px.rows() - 2);  // scan lines 100 and 901
  ExpectProfile(p, s, lines, opencv::LaserPointsInCamera(in, plane, px, false),
                opencv::LaserPointsInBase(in, plane, hfc, px, Poses(px.rows()), false), inside);
}

TEST(Profile, PaperModelGivesItsBatchFunctionsPoints) {
  paper::Vector14d q = test::Generic();
  q[paper::kTheta] = 0.02;  // the rays above row 240 - f tan(theta) / Sv meet the plane behind
  const LaserSensor sensor = LaserSensor::Paper(q);
  const StripeResult s = Stripe();
  const FrameProfile p = MeasureStripe(sensor, s, StripeDirection::kColumns, BaseFromHand());
  Eigen::VectorXi lines;
  const RowMatX2 px = FoundPixels(s, &lines);
  ExpectProfile(p, s, lines, paper::CameraPointsFromPixels(q, px, false, kMinRaySine),
                paper::BasePointsFromPixels(q, px, Poses(px.rows()), false, kMinRaySine),
                Mask::Ones(px.rows()));
  EXPECT_EQ(sensor.hand_from_camera(), paper::HandFromCamera(q));
}

TEST(Profile, EmptyProfileAndStripesAlongRows) {
  const FrameProfile e = EmptyProfile(5);
  EXPECT_TRUE(e.pixels.array().isNaN().all() && e.points.array().isNaN().all() &&
              e.camera_points.array().isNaN().all());
  EXPECT_TRUE((e.status.array() == static_cast<std::uint8_t>(PointStatus::kNoStripe)).all());
  EXPECT_TRUE((e.stripe_status.array() == static_cast<std::uint8_t>(StripeStatus::kNone)).all());
  const LaserSensor sensor = LaserSensor::Paper(test::Generic());
  // scan lines along image rows: pixel (centre, scan line), measured like any other
  const StripeResult s = Stripe();
  const FrameProfile r = MeasureStripe(sensor, s, StripeDirection::kRows, BaseFromHand());
  int measured = 0;
  for (Eigen::Index i = 0; i < s.status.size(); ++i) {
    if (s.status[i] != kFound) {
      EXPECT_TRUE(std::isnan(r.pixels(i, 0))) << i;
      continue;
    }
    EXPECT_EQ(r.pixels(i, 0), s.centre[i]) << i;
    EXPECT_EQ(r.pixels(i, 1), static_cast<double>(i)) << i;
    double c[3];
    if (!sensor.CameraPoint(s.centre[i], static_cast<double>(i), c)) continue;
    ++measured;
    for (int k = 0; k < 3; ++k) EXPECT_EQ(r.camera_points(i, k), c[k]) << i;
  }
  EXPECT_GT(measured, 500);
  paper::Vector14d bad = test::Generic();
  bad[paper::kH] = -1.0;
  EXPECT_THROW(LaserSensor::Paper(bad), std::invalid_argument);
}

}  // namespace
}  // namespace hmlvs
