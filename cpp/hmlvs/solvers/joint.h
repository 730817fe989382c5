// Joint calibration of the general sensor (model "opencv", hmlvs::opencv) from board corners and
// laser stripe pixels: one Levenberg-Marquardt solve (Ceres) of
//   - corner residuals: projected board corner - detected corner (pixels), and
//   - laser residuals: the signed distance (mm) from the laser plane of the point where a stripe
//     pixel's ray meets the board plane of its view,
// each kind divided by its noise (sigma), optionally under a robust loss.
//
// The board pose of a view comes either from the robot chain
//   camera_from_board_i = inv(hand_from_camera) inv(base_from_hand_i) base_from_board
// (chain mode: hand_from_camera and base_from_board are unknowns, base_from_hand_i known), or
// from a free per-view pose (camera mode: camera_from_board_i are unknowns; no robot needed).
// Chain mode with uncertain robot poses (JointOptions::pose_sigma_t) keeps both: free per-view
// board poses, each tied to the chain's by a residual of the robot pose error it implies.
// Rotations live on SO(3) (unit quaternions), the laser normal on the unit sphere.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "hmlvs/model/opencv.h"
#include "hmlvs/solvers/solve.h"

namespace hmlvs::solvers {

using Vector6d = Eigen::Matrix<double, 6, 1>;

/// The data of one view.
struct JointView {
  Eigen::Matrix4d base_from_hand = Eigen::Matrix4d::Identity();  ///< chain mode
  RowMatX2 corner_pixels;                                        ///< detected corners (n x 2)
  RowMatX3 corner_points;  ///< the same corners in the board frame, mm (n x 3)
  RowMatX2 laser_pixels;   ///< stripe pixels on the board (m x 2)
};

/// Everything the joint solve estimates.
struct JointState {
  opencv::IntrinsicsVector intrinsics = opencv::IntrinsicsVector::Zero();
  Eigen::Vector4d laser_plane = Eigen::Vector4d(0, 1, 0, -100);    ///< (a, b, c, d), unit normal
  Eigen::Matrix4d hand_from_camera = Eigen::Matrix4d::Identity();  ///< chain mode
  Eigen::Matrix4d base_from_board = Eigen::Matrix4d::Identity();   ///< chain mode
  /// camera mode, and chain mode with uncertain robot poses: per view
  std::vector<Eigen::Matrix4d> camera_from_board;
};

/// Every intrinsic free but the distortion terms beyond the five-term lens.
constexpr std::array<bool, opencv::kNumIntrinsics> ClassicLens() {
  std::array<bool, opencv::kNumIntrinsics> held{};
  for (int k = opencv::kNumClassicIntrinsics; k < opencv::kNumIntrinsics; ++k) held[k] = true;
  return held;
}

struct JointOptions {
  bool chain = true;              ///< robot chain (true) or free per-view board poses
  bool board_pose_known = false;  ///< chain mode: hold base_from_board at its given value
  bool hand_eye_known = false;    ///< chain mode: hold hand_from_camera at its given value
  bool laser = true;              ///< include the laser residuals and the plane
  bool plane_known = false;       ///< hold the laser plane at its given value
  /// Chain mode: the robot poses' uncertainty, translation (mm) and rotation (rad), both > 0
  /// or both 0 (the poses exact). With it every view keeps its own board pose
  /// (camera_from_board), tied to the chain's by a residual per view: the robot pose error
  /// E = hand_from_camera camera_from_board_chain inv(camera_from_board) inv(hand_from_camera)
  /// (rotation vector / pose_sigma_r, translation / pose_sigma_t, in the hand frame).
  double pose_sigma_t = 0.0;
  double pose_sigma_r = 0.0;
  /// intrinsics held at their initial values: by default the distortion terms beyond the
  /// five-term lens (k4 to tauy)
  std::array<bool, opencv::kNumIntrinsics> fixed = ClassicLens();
  double corner_sigma = 0.1;  ///< pixels
  double laser_sigma = 0.05;  ///< mm
  LossKind loss = LossKind::kNone;
  double loss_scale = 3.0;  ///< in units of sigma
  int max_iterations = 100;
  double function_tolerance = 1e-10;
  double parameter_tolerance = 1e-10;
  double gradient_tolerance = 1e-14;
};

/// The solve's summary (Ceres' costs: 1/2 sum of squared weighted residuals) and its result.
struct JointResult : SolveSummary {
  JointState state;
};

/// Solves the joint problem from `initial`. Throws std::invalid_argument for bad input (views
/// without corners, mismatched shapes, non-finite values, an initial state where a laser ray
/// misses its board plane, fewer residuals than unknowns).
JointResult SolveJoint(const std::vector<JointView>& views, const JointState& initial,
                       const JointOptions& options);

/// Unweighted residuals at `state`: per view, the corner residuals (n x 2, pixels) and the laser
/// residuals (m, mm; NaN where the ray misses the board plane); with uncertain robot poses
/// also each view's robot pose error (rotation vector (rad), translation (mm); see
/// JointOptions::pose_sigma_t), empty otherwise.
struct JointResiduals {
  std::vector<RowMatX2> corners;
  std::vector<Eigen::VectorXd> laser;
  std::vector<Vector6d> pose;
};

/// Whether `o` is chain mode with uncertain robot poses (JointOptions::pose_sigma_t).
bool SoftChain(const JointOptions& o);
/// `scales_at` (tests of the Jacobian): the laser residuals of views with their own board pose
/// as the solver's cost computes them away from its start, LaserLineDistance times
/// LaserScales at `scales_at` (which equals the mm distance at `scales_at` itself).
JointResiduals EvaluateJoint(const std::vector<JointView>& views, const JointState& state,
                             const JointOptions& options, const JointState* scales_at = nullptr);

/// The Jacobian of the weighted residuals (corners of every view, then laser pixels of every
/// view, in order) with respect to the free unknowns in their tangent spaces, in the order
/// intrinsics (free ones), hand_from_camera (rotation 3, translation 3), base_from_board
/// (rotation 3, translation 3), laser plane (normal tangent 2, offset 1) in chain mode; in
/// camera mode the per-view poses (6 each) replace the two transforms. Rotations are
/// perturbed on the left (R <- exp([w]x) R), in radians. `names` receives the column names.
Eigen::MatrixXd JointJacobian(const std::vector<JointView>& views, const JointState& state,
                              const JointOptions& options, std::vector<std::string>* names);

}  // namespace hmlvs::solvers
