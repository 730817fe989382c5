// The residuals of the general model's joint calibration (SolveJoint) as Ceres cost functions,
// and the plain evaluations of the same residuals (EvaluateJoint). The caller owns the returned
// cost functions.
#pragma once

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <array>

#include "hmlvs/solvers/joint.h"

namespace hmlvs::solvers {

/// A transform as the parameter blocks of the solve: Eigen quaternion [x, y, z, w] + translation.
struct PoseBlocks {
  std::array<double, 4> q{};
  std::array<double, 3> t{};
  explicit PoseBlocks(const Eigen::Matrix4d& m);
  Eigen::Matrix4d Matrix() const;
};

/// The corner residuals of one view, (projected - detected) * inv_sigma (n x 2, row-major), for a
/// board pose camera_from_board = (r, t). Returns false when a corner is not in front of the
/// camera.
bool CornerResiduals(const double* intrinsics, const Eigen::Matrix3d& r, const Eigen::Vector3d& t,
                     const JointView& view, double inv_sigma, double* residuals);

/// One stripe pixel's laser residual: the signed distance (mm) of the point where its ray meets
/// the board plane nb . X + ob = 0 from the laser plane unit . X + d = 0 (unit normal). x, y
/// receive the undistorted normalised point and jd (row-major 2x2) the distortion's Jacobian
/// there. Returns false when the pixel cannot be undistorted or its ray does not meet the board
/// plane in front of the camera. `untilt`: as in opencv::UndistortNormalized.
bool LaserResidual(const double* intrinsics, const double* nb, double ob, const double* unit,
                   double d, double u, double v, double* x, double* y, double* jd, double* residual,
                   const opencv::Untilt* untilt = nullptr);

/// The scale-free laser residual of one stripe pixel with its ray (x, y, 1) undistorted:
/// the pixel's distance (px, in the undistorted image) from the line where the laser plane
/// unit . X + d = 0 meets the board plane nb . X + ob = 0, seen from the camera,
///   s N,  s = m . (x, y, 1),  m = unit - (d / ob) nb,  N = 1 / |(m_x / fx, m_y / fy)|.
/// The distance (mm) LaserResidual gives is depth s, depth = -ob / (nb . ray): it shrinks
/// with the scene, and a view whose board pose is free (no robot to fix the scale) lets a
/// least-squares fit shrink the scene to shrink the stripe's noise (renders: fx 3 % low with
/// 800 stripe pixels a view); this one does not.
double LaserLineDistance(const double* intrinsics, const double* nb, double ob, const double* unit,
                         double d, double x, double y);

/// Per stripe pixel of `pixels`, depth / N (LaserLineDistance) at the given camera, board
/// plane and laser plane: the factor that turns the scale-free residual into mm there (0 where
/// the pixel cannot be undistorted or its ray misses the board plane).
Eigen::VectorXd LaserScales(const double* intrinsics, const double* nb, double ob,
                            const double* unit, double d, const RowMatX2& pixels);

/// The robot pose error a view's own board pose implies (JointOptions::pose_sigma_t):
/// E = hand_from_camera camera_from_board_chain inv(camera_from_board) inv(hand_from_camera),
/// as (rotation vector, translation) in the hand frame.
Vector6d PoseError(const PoseBlocks& camera_from_board, const PoseBlocks& hand_from_camera,
                   const PoseBlocks& base_from_board, const Eigen::Matrix4d& base_from_hand);

/// Chain mode: the corner residuals of a view over the blocks intrinsics (18),
/// hand_from_camera (4, 3) and base_from_board (4, 3).
/// `classic_lens`: the intrinsics beyond the five-term lens (k4 to tauy) are held at 0, so they are
/// not read (their Jacobian columns are 0: fewer operations on the Jets).
ceres::CostFunction* NewChainCornerCost(const JointView* view, double inv_sigma, bool classic_lens);

/// A view with its own board pose: the corner residuals over the blocks intrinsics (18) and
/// camera_from_board (4, 3).
/// `classic_lens`: as NewChainCornerCost.
ceres::CostFunction* NewFreeCornerCost(const JointView* view, double inv_sigma, bool classic_lens);

/// The laser residuals of a view (analytic Jacobian) over the blocks intrinsics (18), the board
/// pose's blocks (chain: hand_from_camera (4, 3) and base_from_board (4, 3); else
/// camera_from_board (4, 3)), the laser plane's normal (3) and offset (1).
/// `scales` (views with their own board pose): the residuals are LaserLineDistance times these
/// fixed factors (LaserScales at the start, so that they read as mm there), not the mm
/// distance; null: LaserResidual. `classic_lens`: as NewChainCornerCost.
ceres::CostFunction* NewLaserCost(const JointView* view, double inv_sigma, bool chain,
                                  bool classic_lens, const Eigen::VectorXd* scales = nullptr);

/// Uncertain robot poses: the pose error of a view, rotation * w_r and translation * w_t, over
/// the blocks camera_from_board, hand_from_camera and base_from_board (4, 3 each).
ceres::CostFunction* NewPosePriorCost(const JointView* view, double w_r, double w_t);

}  // namespace hmlvs::solvers
