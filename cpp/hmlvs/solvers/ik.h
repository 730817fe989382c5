// Inverse kinematics of the session simulator: the joint readings that put a camera on the hand
// at a position, looking along an axis. A damped least-squares (Levenberg-Marquardt) solve in
// plain IEEE operations in a fixed order: no BLAS, no LAPACK, no fused multiply-add, so every
// CPU gets the same bits (a solve that took another path on another machine could land in
// another basin, elbow up instead of elbow down, and change the simulated scene).
#pragma once

#include <Eigen/Core>

#include "hmlvs/geometry/kinematics.h"

namespace hmlvs::solvers {

/// Where the camera is wanted. Residuals (mm): position - `position`, 300 (z axis - `axis`)
/// and, with `has_x`, 100 (x axis - `x`), the camera's axes taken in the base frame.
struct LookAtTarget {
  Eigen::Matrix4d hand_from_camera = Eigen::Matrix4d::Identity();
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  bool has_x = false;
  Eigen::Vector3d x = Eigen::Vector3d::UnitX();
};

struct LookAtOptions {
  double max_step = 0.2;  ///< rad: the longest joint step (keeps the solve in its start's basin)
  int iterations = 200;
};

struct LookAtResult {
  Eigen::VectorXd joints;
  double error = 0.0;  ///< the residual's norm at `joints`
};

/// Minimises the residual's norm from `start` within [`lower`, `upper`] (per joint; +-inf for
/// none). Central-difference Jacobian (steps of 1e-6 rad), damping scaled by the normal
/// matrix's diagonal; stops when a step lowers the cost by less than 1e-14 of it, or when no
/// step lowers it. Throws std::invalid_argument on mismatched sizes or non-finite joints.
LookAtResult SolveLookAt(const geometry::DHRobot& robot, const LookAtTarget& target,
                         const Eigen::VectorXd& start, const Eigen::VectorXd& lower,
                         const Eigen::VectorXd& upper, const LookAtOptions& options = {});

}  // namespace hmlvs::solvers
