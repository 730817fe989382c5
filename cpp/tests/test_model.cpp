// The sensor model: hand-computed values, round trips, batch vs single-point functions, and
// pixels whose ray misses the laser plane.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>

#include "hmlvs/model/paper.h"
#include "hmlvs/model/paper_cost.h"
#include "hmlvs/model/paper_fitness.h"
#include "hmlvs/solvers/lm.h"
#include "test_util.h"

namespace hmlvs {
namespace {

using namespace hmlvs::paper;
using namespace hmlvs::solvers;

using test::Generic;
using test::kPi;
using test::MakeScene;
using test::Nominal;

// Runs `fn` and checks that it throws std::invalid_argument whose message contains `text`.
void ExpectInvalidArgument(const std::function<void()>& fn, const std::string& text) {
  try {
    fn();
    ADD_FAILURE() << "no exception; expected one containing: " << text;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos)
        << "message: " << e.what() << "\nexpected to contain: " << text;
  }
}

RowMatX16 PoseRows(const Eigen::Matrix4d& t) {
  RowMatX16 p(1, 16);
  for (int k = 0; k < 16; ++k) p(0, k) = t(k / 4, k % 4);
  return p;
}

// docs/model.md steps 1-5 written out independently of the library: the two-division form of
// Eq. 1-3 as docs/model.md states it and R_C from Eigen's angle-axis product.
Eigen::Vector3d IndependentBasePoint(const Vector14d& q, double u, double v,
                                     const Eigen::Matrix4d& base_from_hand,
                                     Eigen::Vector3d* camera_point) {
  const double xd = q[kSu] * (u - q[kCu]);
  const double yd = q[kSv] * (v - q[kCv]);
  const double r2 = xd * xd + yd * yd;
  const double xu = xd / (1.0 + q[kK] * r2);
  const double yu = yd / (1.0 + q[kK] * r2);
  const double rho = q[kH] / (yu + q[kF] * std::tan(q[kTheta]));
  *camera_point = Eigen::Vector3d(rho * xu, rho * yu, rho * q[kF]);
  const Eigen::Matrix3d rc = (Eigen::AngleAxisd(q[kOmega], Eigen::Vector3d::UnitZ()) *
                              Eigen::AngleAxisd(q[kPhi], Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(q[kVarphi], Eigen::Vector3d::UnitZ()))
                                 .toRotationMatrix();
  const Eigen::Vector3d hand = rc * *camera_point + Eigen::Vector3d(q[kTx], q[kTy], q[kTz]);
  return base_from_hand.topLeftCorner<3, 3>() * hand + base_from_hand.topRightCorner<3, 1>();
}

// A pose with a rotation of 90 deg about z and a translation: base = (-hy, hx, hz) + P_N.
Eigen::Matrix4d QuarterTurnPose() {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.topRightCorner<3, 1>() << 100.0, 200.0, 300.0;
  return t;
}

TEST(Model, HandComputedPixelWithTable2Nominal) {
  // Pixel (400, 300) with the Table 2 nominal parameters. By hand (docs/model.md):
  //   Xd = 0.0074 * 80 = 0.592 mm, Yd = 0.0074 * 60 = 0.444 mm, k = 0: Xu = Xd, Yu = Yd
  //   Yu + f tan(25 deg) = 0.444 + 8 * 0.466307658155 = 4.17446126524 mm
  //   rho = 140 / 4.17446126524 = 33.5372617894
  //   cP = rho [0.592, 0.444, 8] = [19.8540589393, 14.8905442045, 268.298093775]
  //   R_C = I, hand = cP + (60, 0, -45); base = Rz(90 deg) hand + (100, 200, 300)
  //        = (100 - 14.8905442045, 200 + 79.8540589393, 300 + 223.298093775)
  // The literals are these numbers to 30 digits (evaluated with mpmath).
  const Vector14d q = Nominal();
  const RowMatX2 pixel = (RowMatX2(1, 2) << 400.0, 300.0).finished();
  const Eigen::Matrix4d pose = QuarterTurnPose();
  const Eigen::Vector3d camera_expected(19.8540589393240541564469838855,
                                        14.8905442044930406173352379141,
                                        268.298093774649380492526809264);
  const Eigen::Vector3d base_expected(85.109455795506959382664762085868,
                                      279.854058939324054156446983885509,
                                      523.298093774649380492526809263782);

  Eigen::Vector3d camera_independent;
  const Eigen::Vector3d base_independent =
      IndependentBasePoint(q, 400.0, 300.0, pose, &camera_independent);
  const PointsResult camera = CameraPointsFromPixels(q, pixel, true);
  const PointsResult base = BasePointsFromPixels(q, pixel, PoseRows(pose), true);
  ASSERT_EQ(camera.num_invalid, 0);
  ASSERT_EQ(base.num_invalid, 0);
  // About ten double operations from exact inputs: a few 1e-16 relative error. 1e-12 mm on
  // values of at most 523 mm leaves a wide margin and still catches any formula slip.
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(camera.points(0, i), camera_expected[i], 1e-12 * 300) << "camera " << i;
    EXPECT_NEAR(camera_independent[i], camera_expected[i], 1e-12 * 300) << "test's own formula";
    EXPECT_NEAR(base.points(0, i), base_expected[i], 1e-12 * 600) << "base " << i;
    EXPECT_NEAR(base_independent[i], base_expected[i], 1e-12 * 600) << "test's own formula";
  }
}

TEST(Model, HandComputedPixelWithDistortionAndRotation) {
  // The same pixel with k = 0.01 /mm^2 (division model, docs/model.md step 2): r2 = 0.592^2 +
  // 0.444^2 = 0.5476, 1 + k r2 = 1.005476, and (mpmath) cP = [19.7573749015, 14.8180311761,
  // 268.453598466].
  Vector14d q = Nominal();
  q[kK] = 0.01;
  const RowMatX2 pixel = (RowMatX2(1, 2) << 400.0, 300.0).finished();
  const Eigen::Vector3d camera_expected(19.7573749015084086248010927906,
                                        14.8180311761313064686008195929,
                                        268.453598465798225276087886145);
  const PointsResult camera = CameraPointsFromPixels(q, pixel, true);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(camera.points(0, i), camera_expected[i], 1e-12 * 300);

  // Generic Euler angles and translation: the library's RotationZYZ and PixelToBase against
  // the independent chain (Eigen angle-axis rotations) for a set of pixels and poses. Both are
  // rounding-level computations of the same numbers on points of up to ~1500 mm: 1e-9 mm.
  const Vector14d g = Generic();
  const test::Scene s = MakeScene(g, 40, 3);
  for (Eigen::Index i = 0; i < s.pixels.rows(); ++i) {
    Eigen::Matrix4d pose;
    for (int k = 0; k < 16; ++k) pose(k / 4, k % 4) = s.poses(i, k);
    Eigen::Vector3d cp;
    const Eigen::Vector3d expected =
        IndependentBasePoint(g, s.pixels(i, 0), s.pixels(i, 1), pose, &cp);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(s.points(i, c), expected[c], 1e-9) << i << " " << c;
  }
}

TEST(Model, BasePointsRoundTripThroughPixels) {
  // PixelsFromBasePoints inverts BasePointsFromPixels (closed-form inverse of the division
  // model). The chain is well conditioned (pixel pitch 7.4 um, ranges < 2 m), so the round trip
  // loses a few 1e-13 px; the bound is 1e-9 px.
  for (const Vector14d& q : {Nominal(), Generic()}) {
    const test::Scene s = MakeScene(q, 300, 7);
    const PixelsResult back = PixelsFromBasePoints(q, s.points, s.poses, /*plane_tolerance=*/1e-6);
    ASSERT_EQ(back.num_invalid, 0);
    EXPECT_LT((back.pixels - s.pixels).cwiseAbs().maxCoeff(), 1e-9);
    // The points lie on the laser plane (docs/model.md step 3): distance at the rounding level.
    EXPECT_LT(LaserPlaneDistance(q, s.points, s.poses).cwiseAbs().maxCoeff(), 1e-9);
  }
}

TEST(Model, BatchFunctionsAgreeWithSinglePointFunctions) {
  const Vector14d q = Generic();
  const test::Scene s = MakeScene(q, 50, 11);
  // References off the model's points by ~1 mm, so that residuals are not zero.
  RowMatX3 refs = s.points;
  for (Eigen::Index i = 0; i < refs.rows(); ++i)
    refs.row(i) += Eigen::RowVector3d(0.5, -1.0, 0.25) * std::cos(i);

  const PointsResult camera = CameraPointsFromPixels(q, s.pixels, true);
  const PointsResult base = BasePointsFromPixels(q, s.pixels, s.poses, true);
  const RowMatX3 residuals = Residuals(q, s.pixels, s.poses, refs);
  const RowMatX3 rays = CameraRaysFromPixels(q, s.pixels);
  const Eigen::Matrix3d rc = geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  const double tan_theta = std::tan(q[kTheta]);
  const FitnessData data(s.pixels, s.poses, refs);
  const Eigen::VectorXd errors = data.PointErrors(q.data());

  // The batch functions loop over the same templated functions, so they agree to rounding
  // (different inlining may contract multiply-adds differently on some targets): 1e-12 of the
  // magnitude (points up to ~2000 mm).
  const double tol = 1e-12 * 2000;
  double sum_sq = 0.0;
  for (Eigen::Index i = 0; i < s.pixels.rows(); ++i) {
    const double u = s.pixels(i, 0), v = s.pixels(i, 1);
    double cp[3], bp[3], e[3], eh[3];
    EXPECT_GT(PixelToCamera(q.data(), tan_theta, u, v, cp), 0.0);
    EXPECT_GT(PixelToBase(q.data(), rc, tan_theta, u, v, geometry::PoseRotation(s.poses, i),
                          geometry::PosePosition(s.poses, i), bp),
              0.0);
    EXPECT_GT(PointResidual(q.data(), rc, tan_theta, u, v, geometry::PoseRotation(s.poses, i),
                            geometry::PosePosition(s.poses, i), refs.row(i).transpose(), e),
              0.0);
    const Eigen::Vector3d h = geometry::PoseRotation(s.poses, i).transpose() *
                              (refs.row(i).transpose() - geometry::PosePosition(s.poses, i));
    EXPECT_GT(HandResidual(q.data(), rc, tan_theta, u, v, h.data(), eh), 0.0);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(camera.points(i, c), cp[c], tol);
      EXPECT_NEAR(base.points(i, c), bp[c], tol);
      EXPECT_NEAR(residuals(i, c), e[c], tol);
      // The viewing ray (Xu, Yu, f) scaled by rho = z / f is the camera point.
      EXPECT_NEAR(rays(i, c) * cp[2] / q[kF], cp[c], tol);
    }
    EXPECT_DOUBLE_EQ(rays(i, 2), q[kF]);
    // The hand-frame residual is the base-frame one rotated: same norm.
    const double norm = Eigen::Vector3d(e[0], e[1], e[2]).norm();
    EXPECT_NEAR(Eigen::Vector3d(eh[0], eh[1], eh[2]).norm(), norm, tol);
    EXPECT_NEAR(errors[i], norm, tol);
    sum_sq += norm * norm;
  }
  // Objective and fitness: F = 1/2 sum ||E||^2 (docs/model.md), relative 1e-12.
  const double objective = Objective(q, s.pixels, s.poses, refs);
  EXPECT_GT(objective, 1.0);
  EXPECT_NEAR(objective, 0.5 * sum_sq, 1e-12 * objective);
  EXPECT_NEAR(data.Evaluate(q.data()), objective, 1e-12 * objective);
}

TEST(Model, FitnessKernelAgreesWithObjectiveOnALargeDataSet) {
  // The vectorised fitness kernel on 1101 points (not a multiple of any vector width, so the
  // loop's remainder runs too) against the base-frame objective. Every E_i is (0.3, 0, 0) mm up
  // to rounding on coordinates below 2048 mm (2.3e-13 mm), so F = 1101 x 0.09 / 2 to 1e-9 mm^2,
  // and the two computations of F agree to 1e-12 relative.
  const Vector14d q = Generic();
  const test::Scene s = MakeScene(q, 1101, 5);
  RowMatX3 refs = s.points;
  refs.col(0).array() += 0.3;
  const FitnessData data(s.pixels, s.poses, refs);
  const double objective = Objective(q, s.pixels, s.poses, refs);
  EXPECT_NEAR(objective, 0.5 * 1101 * 0.09, 1e-9);
  EXPECT_NEAR(data.Evaluate(q.data()), objective, 1e-12 * objective);
}

TEST(Model, PixelWhoseRayMissesTheLaserPlane) {
  // theta = 0.01: f tan(theta) = 0.0800027 mm. Row 10 has Yd = 0.0074 (10 - 240) = -1.702 mm,
  // so Yu + f tan(theta) = -1.6219973 mm <= 0: no measurement (docs/model.md step 3). Row 300 is
  // fine.
  Vector14d q = Nominal();
  q[kTheta] = 0.01;
  const RowMatX2 pixels = (RowMatX2(2, 2) << 320.0, 300.0, 320.0, 10.0).finished();
  RowMatX16 poses(2, 16);
  poses.row(0) = PoseRows(Eigen::Matrix4d::Identity());
  poses.row(1) = PoseRows(QuarterTurnPose());
  const RowMatX3 refs = RowMatX3::Zero(2, 3);
  const std::string message =
      "pixel 1 (u=320, v=10) has a ray that misses the laser plane: Yu + f tan(theta) = -1.622 mm";

  double cp[3];
  EXPECT_LT(PixelToCamera(q.data(), std::tan(q[kTheta]), 320.0, 10.0, cp), 0.0);
  EXPECT_GT(PixelToCamera(q.data(), std::tan(q[kTheta]), 320.0, 300.0, cp), 0.0);

  ExpectInvalidArgument([&] { CameraPointsFromPixels(q, pixels, true); }, message);
  ExpectInvalidArgument([&] { BasePointsFromPixels(q, pixels, poses, true); }, message);
  ExpectInvalidArgument([&] { Residuals(q, pixels, poses, refs); }, message);
  Eigen::VectorXd r;
  Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor> j;
  ExpectInvalidArgument([&] { ResidualJacobian(q, pixels, poses, refs, &r, &j); }, message);

  for (const PointsResult& res :
       {CameraPointsFromPixels(q, pixels, false), BasePointsFromPixels(q, pixels, poses, false)}) {
    EXPECT_EQ(res.num_invalid, 1);
    EXPECT_EQ(res.valid[0], 1);
    EXPECT_EQ(res.valid[1], 0);
    EXPECT_TRUE(res.points.row(0).allFinite());
    EXPECT_TRUE(res.points.row(1).array().isNaN().all());
  }
  EXPECT_EQ(Objective(q, pixels, poses, refs), std::numeric_limits<double>::infinity());

  const FitnessData data(pixels, poses, refs);
  EXPECT_EQ(data.Evaluate(q.data()), std::numeric_limits<double>::infinity());
  const Eigen::VectorXd errors = data.PointErrors(q.data());
  EXPECT_TRUE(std::isfinite(errors[0]));
  EXPECT_TRUE(std::isnan(errors[1]));
  LmOptions o;
  o.use_bounds = false;
  ExpectInvalidArgument([&] { RunLm(data, q, o); },
                        "the ray of calibration point 1 misses the laser plane");
}

}  // namespace
}  // namespace hmlvs
