// Robot forward kinematics from Denavit-Hartenberg tables (paper Eq. 4).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "hmlvs/model/arrays.h"

namespace hmlvs::geometry {

enum class DHConvention {
  kStandard,  ///< T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)
  kModified,  ///< Craig: T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)
};

/// One row of a DH table. For a revolute joint theta = reading + offset and d is fixed; for a
/// prismatic joint d = reading + offset and theta is fixed (`theta`).
struct DHJoint {
  double a = 0.0;       ///< link length (mm)
  double alpha = 0.0;   ///< link twist (rad)
  double d = 0.0;       ///< link offset (mm)
  double theta = 0.0;   ///< joint angle (rad), used for prismatic joints
  double offset = 0.0;  ///< added to the joint reading (rad or mm)
  bool prismatic = false;
};

struct DHRobot {
  std::vector<DHJoint> joints;
  DHConvention convention = DHConvention::kStandard;
  Eigen::Matrix4d base_from_link0 = Eigen::Matrix4d::Identity();
  Eigen::Matrix4d flange_from_hand = Eigen::Matrix4d::Identity();  ///< tool transform
};

/// One link transform.
Eigen::Matrix4d DHLinkTransform(const DHJoint& joint, double reading, DHConvention convention);

/// The base_from_hand pose of one set of joint readings (no checks: see ForwardKinematics).
Eigen::Matrix4d BaseFromHand(const DHRobot& robot, const Eigen::Ref<const Eigen::VectorXd>& joints);

/// Joint readings (m x n, rad for revolute and mm for prismatic joints) -> base_from_hand
/// poses (m x 16, row-major 4x4 each). Throws std::invalid_argument on a shape mismatch or a
/// non-finite reading.
RowMatX16 ForwardKinematics(
    const DHRobot& robot,
    const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>&
        joints);

}  // namespace hmlvs::geometry
