#include "hmlvs/solvers/joint.h"

#include <ceres/ceres.h>
#include <ceres/sphere_manifold.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "hmlvs/geometry/geometry.h"
#include "hmlvs/solvers/joint_costs.h"

namespace hmlvs::solvers {

using namespace hmlvs::opencv;
using geometry::CheckTransform;

namespace {

// LaserScales of a view's stripe pixels for the board pose camera_from_board and the laser
// plane (normal, offset) as the solver holds them (the offset for the unit normal).
Eigen::VectorXd ScalesAt(const JointView& v, const double* intrinsics,
                         const Eigen::Matrix4d& camera_from_board, const Eigen::Vector3d& normal,
                         double offset) {
  const Eigen::Vector3d nb = camera_from_board.topLeftCorner<3, 3>().col(2);
  const double ob = -nb.dot(camera_from_board.topRightCorner<3, 1>());
  const Eigen::Vector3d unit = normal.normalized();
  return LaserScales(intrinsics, nb.data(), ob, unit.data(), offset, v.laser_pixels);
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Whether every intrinsic beyond the five-term lens is held at 0 (the corner costs then leave
// them out).
bool ClassicLensHeld(const JointOptions& o, const IntrinsicsVector& intrinsics) {
  for (int k = kNumClassicIntrinsics; k < kNumIntrinsics; ++k) {
    if (!o.fixed[k] || intrinsics[k] != 0.0) return false;
  }
  return true;
}

void CheckInput(const std::vector<JointView>& views, const JointState& s, const JointOptions& o) {
  if (!(o.pose_sigma_t >= 0.0 && o.pose_sigma_r >= 0.0) ||
      ((o.pose_sigma_t > 0.0) != (o.pose_sigma_r > 0.0))) {
    throw std::invalid_argument(
        "pose_sigma_t and pose_sigma_r must both be > 0 (uncertain robot poses) or both 0");
  }
  if (views.empty()) throw std::invalid_argument("the joint calibration needs at least one view");
  if (std::none_of(views.begin(), views.end(),
                   [](const JointView& v) { return v.corner_pixels.rows() > 0; })) {
    throw std::invalid_argument("the joint calibration needs at least one view with corners");
  }
  ValidateIntrinsics(s.intrinsics);
  if (!(o.corner_sigma > 0.0) || !(o.laser_sigma > 0.0)) {
    throw std::invalid_argument("corner_sigma and laser_sigma must be > 0");
  }
  for (std::size_t i = 0; i < views.size(); ++i) {
    const JointView& v = views[i];
    const std::string name = "view " + std::to_string(i);
    RequireSameRows(v.corner_pixels.rows(), (name + " corner pixels").c_str(),
                    v.corner_points.rows(), (name + " corner points").c_str());
    RequireFinite(v.corner_pixels.data(), v.corner_pixels.rows(), 2,
                  (name + " corner pixels").c_str());
    RequireFinite(v.corner_points.data(), v.corner_points.rows(), 3,
                  (name + " corner points").c_str());
    RequireFinite(v.laser_pixels.data(), v.laser_pixels.rows(), 2,
                  (name + " laser pixels").c_str());
    // In chain mode a view without corners (a laser-only frame: the stripe on the board's
    // plane, the board unseen) sees its board through base_from_board and the robot pose.
    // (Its stripe pixels may all have been dropped as outliers: then it adds nothing.)
    const bool laser_only = o.chain && v.corner_pixels.rows() == 0;
    if (v.corner_pixels.rows() < 4 && !laser_only) {
      throw std::invalid_argument(name + " has " + std::to_string(v.corner_pixels.rows()) +
                                  " corners; each view needs at least 4" +
                                  (o.chain ? " (or none: a laser-only view)" : ""));
    }
    if (o.chain) CheckTransform(v.base_from_hand, name + " base_from_hand");
  }
  const bool soft = SoftChain(o);
  if (o.chain) {
    CheckTransform(s.hand_from_camera, "hand_from_camera");
    CheckTransform(s.base_from_board, "base_from_board");
  }
  if (!o.chain || soft) {
    if (s.camera_from_board.size() != views.size()) {
      throw std::invalid_argument(
          std::string(soft ? "uncertain robot poses need" : "camera mode needs") +
          " one initial camera_from_board per view, got " +
          std::to_string(s.camera_from_board.size()) + " for " + std::to_string(views.size()) +
          " views");
    }
    for (std::size_t i = 0; i < views.size(); ++i) {
      CheckTransform(s.camera_from_board[i], "camera_from_board of view " + std::to_string(i));
    }
  }
  if (o.laser && !(s.laser_plane.head<3>().norm() > 0.0 && s.laser_plane.allFinite())) {
    throw std::invalid_argument("the initial laser plane needs a finite, non-zero normal");
  }
}

// The problem and its parameter blocks; built the same way for solving and for the Jacobian.
class JointProblem {
 public:
  JointProblem(const std::vector<JointView>& views, const JointState& s, const JointOptions& o)
      : options_(o), hand_eye_(s.hand_from_camera), board_(s.base_from_board) {
    CheckInput(views, s, o);
    intrinsics_ = s.intrinsics;
    classic_lens_ = ClassicLensHeld(o, intrinsics_);
    const double n = s.laser_plane.head<3>().norm();
    normal_ = s.laser_plane.head<3>() / n;
    offset_ = s.laser_plane[3] / n;
    if (!o.chain || SoftChain(o)) {
      for (const auto& m : s.camera_from_board) views_pose_.emplace_back(m);
    }
    ceres::Problem::Options popt;
    popt.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_ = std::make_unique<ceres::Problem>(popt);
    loss_ = MakeLoss(o.loss, o.loss_scale, "sigmas");
    for (std::size_t i = 0; i < views.size(); ++i) AddView(views[i], i);
    HoldAndName();
  }

  ceres::Problem& problem() { return *problem_; }
  const std::vector<double*>& free_blocks() const { return free_; }
  const std::vector<std::string>& names() const { return names_; }
  const std::vector<int>& rotation_columns() const { return rotation_columns_; }
  int num_residuals() const { return num_residuals_; }

  JointState State() const {
    JointState s;
    s.intrinsics = intrinsics_;
    s.laser_plane << normal_.normalized(), offset_;
    s.hand_from_camera = hand_eye_.Matrix();
    s.base_from_board = board_.Matrix();
    for (const auto& p : views_pose_) s.camera_from_board.push_back(p.Matrix());
    return s;
  }

 private:
  void AddBlock(ceres::CostFunction* cost, const std::vector<double*>& blocks, int residuals) {
    problem_->AddResidualBlock(cost, loss_.get(), blocks);
    num_residuals_ += residuals;
  }

  // The residual blocks of view i: its corners, its stripe and, with uncertain robot poses, the
  // robot pose error its own board pose implies.
  void AddView(const JointView& view, std::size_t i) {
    const JointOptions& o = options_;
    const JointView* v = &view;
    const double wc = 1.0 / o.corner_sigma, wl = 1.0 / o.laser_sigma;
    const int nc = 2 * static_cast<int>(v->corner_pixels.rows());
    const int nl = static_cast<int>(v->laser_pixels.rows());
    const bool soft = SoftChain(o);
    if (o.chain && !soft) {
      if (nc > 0) {  // none in a laser-only view
        AddBlock(NewChainCornerCost(v, wc, classic_lens_),
                 {intrinsics_.data(), hand_eye_.q.data(), hand_eye_.t.data(), board_.q.data(),
                  board_.t.data()},
                 nc);
      }
      if (o.laser && nl > 0) {
        AddBlock(NewLaserCost(v, wl, true, classic_lens_),
                 {intrinsics_.data(), hand_eye_.q.data(), hand_eye_.t.data(), board_.q.data(),
                  board_.t.data(), normal_.data(), &offset_},
                 nl);
      }
      return;
    }
    // The view's own board pose: camera mode, or uncertain robot poses (tied to the chain).
    PoseBlocks& p = views_pose_[i];
    if (nc > 0) {  // none in a laser-only view
      AddBlock(NewFreeCornerCost(v, wc, classic_lens_),
               {intrinsics_.data(), p.q.data(), p.t.data()}, nc);
    }
    if (o.laser && nl > 0) {
      // The scale-free residual (LaserLineDistance): nothing else fixes this board's scale.
      const Eigen::VectorXd scales = ScalesAt(*v, intrinsics_.data(), p.Matrix(), normal_, offset_);
      AddBlock(NewLaserCost(v, wl, false, classic_lens_, &scales),
               {intrinsics_.data(), p.q.data(), p.t.data(), normal_.data(), &offset_}, nl);
    }
    if (soft) {
      AddBlock(NewPosePriorCost(v, 1.0 / o.pose_sigma_r, 1.0 / o.pose_sigma_t),
               {p.q.data(), p.t.data(), hand_eye_.q.data(), hand_eye_.t.data(), board_.q.data(),
                board_.t.data()},
               6);
    }
  }

  // Manifolds and what is held fixed, and the names of the free unknowns in the order of the
  // Jacobian's columns.
  void HoldAndName() {
    const JointOptions& o = options_;
    std::vector<int> fixed;
    for (int k = 0; k < kNumIntrinsics; ++k) {
      if (o.fixed[k]) fixed.push_back(k);
    }
    if (HoldEntries(problem_.get(), intrinsics_.data(), kNumIntrinsics, fixed)) {
      free_.push_back(intrinsics_.data());
      for (int k = 0; k < kNumIntrinsics; ++k) {
        if (!o.fixed[k]) names_.push_back(kIntrinsicNames[k]);
      }
    }
    if (o.chain) {
      AddPose(hand_eye_, o.hand_eye_known, "hand_");
      AddPose(board_, o.board_pose_known, "board_");
    }
    for (std::size_t i = 0; i < views_pose_.size(); ++i) {
      AddPose(views_pose_[i], false, "view" + std::to_string(i) + "_");
    }
    if (o.laser && o.plane_known && problem_->HasParameterBlock(normal_.data())) {
      problem_->SetParameterBlockConstant(normal_.data());
      problem_->SetParameterBlockConstant(&offset_);
    } else if (o.laser && problem_->HasParameterBlock(normal_.data())) {
      problem_->SetManifold(normal_.data(), new ceres::SphereManifold<3>());
      free_.push_back(normal_.data());
      free_.push_back(&offset_);
      for (const char* c : {"plane_n1", "plane_n2", "plane_d"}) names_.push_back(c);
    }
  }

  // A transform's blocks: on SO(3) x R^3, held or free (its six columns named `prefix` rx ...).
  void AddPose(PoseBlocks& p, bool constant, const std::string& prefix) {
    problem_->SetManifold(p.q.data(), new ceres::EigenQuaternionManifold());
    if (constant) {
      problem_->SetParameterBlockConstant(p.q.data());
      problem_->SetParameterBlockConstant(p.t.data());
      return;
    }
    free_.push_back(p.q.data());
    free_.push_back(p.t.data());
    rotation_columns_.push_back(static_cast<int>(names_.size()));
    for (const char* c : {"rx", "ry", "rz", "tx", "ty", "tz"}) names_.push_back(prefix + c);
  }

  JointOptions options_;
  IntrinsicsVector intrinsics_;
  bool classic_lens_ =
      false;  // k4 to tauy held at 0 (ClassicLensHeld): every view's costs skip them
  Eigen::Vector3d normal_;
  double offset_ = 0.0;
  PoseBlocks hand_eye_, board_;
  std::vector<PoseBlocks> views_pose_;
  std::unique_ptr<ceres::LossFunction> loss_;
  std::unique_ptr<ceres::Problem> problem_;
  std::vector<double*> free_;
  std::vector<std::string> names_;
  std::vector<int> rotation_columns_;
  int num_residuals_ = 0;
};

}  // namespace

JointResult SolveJoint(const std::vector<JointView>& views, const JointState& initial,
                       const JointOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  JointProblem jp(views, initial, options);
  int free = 0;
  for (double* b : jp.free_blocks()) free += jp.problem().ParameterBlockTangentSize(b);
  if (jp.num_residuals() < free) {
    std::ostringstream msg;
    msg << "the joint calibration has " << jp.num_residuals() << " residuals for " << free
        << " unknowns; it needs more views or more corners";
    throw std::invalid_argument(msg.str());
  }
  double cost0 = 0.0;
  if (!jp.problem().Evaluate(ceres::Problem::EvaluateOptions(), &cost0, nullptr, nullptr,
                             nullptr) ||
      !std::isfinite(cost0)) {
    throw std::invalid_argument(
        "the initial state cannot be evaluated: a board corner lies behind the camera, or a "
        "stripe pixel's ray misses its view's board plane or cannot be undistorted");
  }
  // Uncertain robot poses tie every view's pose to the chain's: dense QR, which, unlike the
  // Schur complement's Cholesky factorisation, copes with the poorly conditioned systems of
  // laser-only views (whose poses the priors and a stripe alone determine).
  const StopRules stop{options.max_iterations, options.function_tolerance,
                       options.parameter_tolerance, options.gradient_tolerance};
  JointResult r;
  static_cast<SolveSummary&>(r) =
      SolveLm(&jp.problem(), stop, options.chain ? ceres::DENSE_QR : ceres::DENSE_SCHUR, start);
  r.state = jp.State();
  return r;
}

bool SoftChain(const JointOptions& o) {
  return o.chain && o.pose_sigma_t > 0.0 && o.pose_sigma_r > 0.0;
}

JointResiduals EvaluateJoint(const std::vector<JointView>& views, const JointState& s,
                             const JointOptions& o, const JointState* scales_at) {
  CheckInput(views, s, o);
  const bool soft = SoftChain(o);
  JointResiduals out;
  const Eigen::Vector3d normal = s.laser_plane.head<3>() / s.laser_plane.head<3>().norm();
  const double offset = s.laser_plane[3] / s.laser_plane.head<3>().norm();
  for (std::size_t i = 0; i < views.size(); ++i) {
    const JointView& v = views[i];
    Eigen::Matrix4d cb;
    if (o.chain && !soft) {
      cb = s.hand_from_camera.inverse() * v.base_from_hand.inverse() * s.base_from_board;
    } else {
      cb = s.camera_from_board[i];
    }
    if (soft) {
      out.pose.push_back(PoseError(PoseBlocks(cb), PoseBlocks(s.hand_from_camera),
                                   PoseBlocks(s.base_from_board), v.base_from_hand));
    }
    const Eigen::Matrix3d r = cb.topLeftCorner<3, 3>();
    const Eigen::Vector3d t = cb.topRightCorner<3, 1>();
    RowMatX2 c(v.corner_pixels.rows(), 2);
    CornerResiduals(s.intrinsics.data(), r, t, v, 1.0, c.data());
    out.corners.push_back(c);
    const Eigen::Vector3d nb = r.col(2);
    const double ob = -nb.dot(t);
    Eigen::VectorXd l(v.laser_pixels.rows());
    Eigen::VectorXd scales;
    if (scales_at != nullptr && !(o.chain && !soft)) {
      scales = ScalesAt(v, scales_at->intrinsics.data(), scales_at->camera_from_board[i],
                        scales_at->laser_plane.head<3>(),
                        scales_at->laser_plane[3] / scales_at->laser_plane.head<3>().norm());
    }
    const opencv::Untilt untilt(s.intrinsics.data());
    for (Eigen::Index k = 0; k < v.laser_pixels.rows(); ++k) {
      double x, y, jd[4], res;
      const bool ok =
          LaserResidual(s.intrinsics.data(), nb.data(), ob, normal.data(), offset,
                        v.laser_pixels(k, 0), v.laser_pixels(k, 1), &x, &y, jd, &res, &untilt);
      if (ok && scales.size() > 0) {
        res = scales[k] *
              LaserLineDistance(s.intrinsics.data(), nb.data(), ob, normal.data(), offset, x, y);
      }
      l[k] = ok ? res : kNaN;
    }
    out.laser.push_back(l);
  }
  return out;
}

Eigen::MatrixXd JointJacobian(const std::vector<JointView>& views, const JointState& state,
                              const JointOptions& options, std::vector<std::string>* names) {
  JointProblem jp(views, state, options);
  ceres::Problem::EvaluateOptions eopt;
  eopt.parameter_blocks = jp.free_blocks();
  eopt.apply_loss_function = false;
  std::vector<ceres::ResidualBlockId> blocks;
  jp.problem().GetResidualBlocks(&blocks);
  // Corners of every view first, then the laser pixels, then the robot pose errors (see the
  // header); the kind of a block by its number of parameter blocks.
  const bool soft = SoftChain(options);
  const std::size_t corner_blocks = options.chain && !soft ? 5u : 3u;
  const std::size_t pose_blocks = 6u;
  auto kind = [&](ceres::ResidualBlockId b) {
    const std::size_t n =
        jp.problem().GetCostFunctionForResidualBlock(b)->parameter_block_sizes().size();
    return n == corner_blocks ? 0 : (soft && n == pose_blocks) ? 2 : 1;
  };
  std::vector<ceres::ResidualBlockId> ordered;
  for (int pass = 0; pass < 3; ++pass) {
    for (ceres::ResidualBlockId b : blocks) {
      if (kind(b) == pass) ordered.push_back(b);
    }
  }
  eopt.residual_blocks = ordered;
  ceres::CRSMatrix crs;
  double cost = 0.0;
  if (!jp.problem().Evaluate(eopt, &cost, nullptr, nullptr, &crs)) {
    throw std::invalid_argument("the Jacobian cannot be evaluated at this state");
  }
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r) {
    for (int k = crs.rows[r]; k < crs.rows[r + 1]; ++k) j(r, crs.cols[k]) = crs.values[k];
  }
  // Ceres' quaternion tangent delta rotates by 2 |delta|: per radian of rotation, halve.
  for (int c : jp.rotation_columns()) j.middleCols(c, 3) *= 0.5;
  if (names != nullptr) *names = jp.names();
  return j;
}

}  // namespace hmlvs::solvers
