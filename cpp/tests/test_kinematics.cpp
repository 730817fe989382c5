// Forward kinematics (hand-computed poses) and the simulator's look-at inverse kinematics.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "hmlvs/geometry/kinematics.h"
#include "hmlvs/solvers/ik.h"

namespace hmlvs {
namespace {

using namespace hmlvs::geometry;
using namespace hmlvs::solvers;

constexpr double kInf = std::numeric_limits<double>::infinity();

// A six-joint arm in standard DH (PUMA 560-like proportions, mm).
DHRobot SixJointArm() {
  DHRobot r;
  const double half_pi = std::acos(0.0);
  const double table[6][3] = {{0, half_pi, 670}, {430, 0, 0},      {20, -half_pi, 150},
                              {0, half_pi, 430}, {0, -half_pi, 0}, {0, 0, 56}};
  for (const auto& row : table) {
    DHJoint j;
    j.a = row[0];
    j.alpha = row[1];
    j.d = row[2];
    r.joints.push_back(j);
  }
  return r;
}

TEST(Kinematics, TwoLinkPlanarArmByHand) {
  DHRobot r;
  for (double a : {300.0, 200.0}) {
    DHJoint j;
    j.a = a;
    r.joints.push_back(j);
  }
  Eigen::Matrix<double, 1, 2, Eigen::RowMajor> q(0.3, 0.5);
  const RowMatX16 p = ForwardKinematics(r, q);
  EXPECT_NEAR(p(0, 3), 300 * std::cos(0.3) + 200 * std::cos(0.8), 1e-12);
  EXPECT_NEAR(p(0, 7), 300 * std::sin(0.3) + 200 * std::sin(0.8), 1e-12);
  EXPECT_NEAR(p(0, 0), std::cos(0.8), 1e-15);
  EXPECT_NEAR(p(0, 4), std::sin(0.8), 1e-15);
  const Eigen::Vector2d one(0.3, 0.5);
  const Eigen::Matrix4d t = BaseFromHand(r, one);
  for (int i = 0; i < 16; ++i) EXPECT_EQ(t(i / 4, i % 4), p(0, i));
}

TEST(Kinematics, LookAtReachesAPoseTheArmCanTake) {
  const DHRobot robot = SixJointArm();
  Eigen::Matrix4d hfc = Eigen::Matrix4d::Identity();
  hfc.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).matrix();
  hfc.block<3, 1>(0, 3) << 60, 0, -45;
  Eigen::VectorXd truth(6);
  truth << 0.2, -0.5, 0.4, 0.3, -0.6, 0.8;
  const Eigen::Matrix4d cam = BaseFromHand(robot, truth) * hfc;
  LookAtTarget target;
  target.hand_from_camera = hfc;
  target.position = cam.block<3, 1>(0, 3);
  target.axis = cam.block<3, 1>(0, 2);
  target.has_x = true;
  target.x = cam.block<3, 1>(0, 0);
  const Eigen::VectorXd start = truth + Eigen::VectorXd::Constant(6, 0.15);
  const Eigen::VectorXd lo = Eigen::VectorXd::Constant(6, -kInf);
  const Eigen::VectorXd hi = Eigen::VectorXd::Constant(6, kInf);
  const LookAtResult r = SolveLookAt(robot, target, start, lo, hi);
  EXPECT_LT(r.error, 1e-6);
  const Eigen::Matrix4d got = BaseFromHand(robot, r.joints) * hfc;
  EXPECT_LT((got.block<3, 1>(0, 3) - target.position).norm(), 1e-6);
  EXPECT_LT((got.block<3, 3>(0, 0) - cam.block<3, 3>(0, 0)).norm(), 1e-8);

  // A bound the solution cannot pass: the joint stays at it, the error is what is left.
  Eigen::VectorXd hi2 = hi;
  hi2[0] = truth[0] - 0.1;
  const LookAtResult b = SolveLookAt(robot, target, start.cwiseMin(hi2), lo, hi2);
  EXPECT_LE(b.joints[0], hi2[0]);
  EXPECT_GT(b.error, 1.0);
}

TEST(Kinematics, LookAtRefusesBadInput) {
  const DHRobot robot = SixJointArm();
  const LookAtTarget target;
  const Eigen::VectorXd inf = Eigen::VectorXd::Constant(6, kInf);
  EXPECT_THROW(SolveLookAt(robot, target, Eigen::VectorXd::Zero(5), -inf, inf),
               std::invalid_argument);
  EXPECT_THROW(SolveLookAt(robot, target, Eigen::VectorXd::Constant(6, std::nan("")), -inf, inf),
               std::invalid_argument);
}

}  // namespace
}  // namespace hmlvs
