#include "hmlvs/solvers/joint.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <ceres/sphere_manifold.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "hmlvs/model/checks.h"

namespace hmlvs::general {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

// The corner residuals of one view, (projected - detected) / sigma, for a board pose (r, t).
template <typename T>
bool CornerResiduals(const T* in, const Mat3<T>& r, const Vec3<T>& t, const JointView& view,
                     double inv_sigma, T* residuals) {
  bool ok = true;
  for (Eigen::Index i = 0; i < view.corner_points.rows(); ++i) {
    const Vec3<T> p = r * view.corner_points.row(i).transpose().cast<T>() + t;
    T px[2];
    ok = ProjectPoint(in, p.data(), px) && ok;
    residuals[2 * i] = (px[0] - view.corner_pixels(i, 0)) * inv_sigma;
    residuals[2 * i + 1] = (px[1] - view.corner_pixels(i, 1)) * inv_sigma;
  }
  return ok;
}

// One stripe pixel's laser residual: the signed distance (mm) of the point where its ray meets
// the board plane nb . X + ob = 0 from the laser plane unit . X + d = 0 (unit normal). x, y
// receive the undistorted normalised point and jd (row-major 2x2) the distortion's Jacobian
// there, for the analytic derivatives of LaserCost. Returns false when the pixel cannot be
// undistorted or its ray does not meet the board plane in front of the camera.
bool LaserResidual(const double* in, const double* nb, double ob, const double* unit, double d,
                   double u, double v, double* x, double* y, double* jd, double* residual) {
  if (!UndistortNormalized(in, u, v, x, y, jd)) return false;
  double point[3];
  if (!(RayPlanePoint(*x, *y, nb, ob, point) > 0.0)) return false;
  *residual = unit[0] * point[0] + unit[1] * point[1] + unit[2] * point[2] + d;
  return true;
}

template <typename T>
void QuaternionPose(const T* q, const T* t, Mat3<T>* r, Vec3<T>* v) {
  *r = Eigen::Quaternion<T>(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
  *v = Vec3<T>(t[0], t[1], t[2]);
}

struct ChainCorners {
  const JointView* view;
  double inv_sigma;
  template <typename T>
  bool operator()(const T* in, const T* q_hc, const T* t_hc, const T* q_bb, const T* t_bb,
                  T* residuals) const {
    Mat3<T> r;
    Vec3<T> t;
    CameraFromBoard(q_hc, t_hc, view->base_from_hand.topLeftCorner<3, 3>().eval(),
                    view->base_from_hand.topRightCorner<3, 1>().eval(), q_bb, t_bb, &r, &t);
    return CornerResiduals(in, r, t, *view, inv_sigma, residuals);
  }
};

// The robot pose error a view's own board pose implies (JointOptions::pose_sigma_t):
// E = hand_from_camera camera_from_board_chain inv(camera_from_board) inv(hand_from_camera),
// as (rotation vector, translation) in the hand frame.
template <typename T>
void PoseError(const T* q_cb, const T* t_cb, const T* q_hc, const T* t_hc, const T* q_bb,
               const T* t_bb, const Eigen::Matrix4d& base_from_hand, T* out) {
  Mat3<T> rp, rf, rh;
  Vec3<T> tp, tf, th;
  CameraFromBoard(q_hc, t_hc, base_from_hand.topLeftCorner<3, 3>().eval(),
                  base_from_hand.topRightCorner<3, 1>().eval(), q_bb, t_bb, &rp, &tp);
  QuaternionPose(q_cb, t_cb, &rf, &tf);
  QuaternionPose(q_hc, t_hc, &rh, &th);
  // chain * inv(free): rotation rp rf^T, translation tp - rp rf^T tf
  const Mat3<T> rd = rp * rf.transpose();
  const Vec3<T> td = tp - rd * tf;
  // hand_from_camera * D * inv(hand_from_camera)
  const Mat3<T> re = rh * rd * rh.transpose();
  const Vec3<T> te = rh * td + th - re * th;
  ceres::RotationMatrixToAngleAxis(re.data(), out);
  for (int k = 0; k < 3; ++k) out[3 + k] = te[k];
}

struct PosePrior {
  const JointView* view;
  double w_r, w_t;
  template <typename T>
  bool operator()(const T* q_cb, const T* t_cb, const T* q_hc, const T* t_hc, const T* q_bb,
                  const T* t_bb, T* residuals) const {
    PoseError(q_cb, t_cb, q_hc, t_hc, q_bb, t_bb, view->base_from_hand, residuals);
    for (int k = 0; k < 3; ++k) {
      residuals[k] *= w_r;
      residuals[3 + k] *= w_t;
    }
    return true;
  }
};

struct FreeCorners {
  const JointView* view;
  double inv_sigma;
  template <typename T>
  bool operator()(const T* in, const T* q_cb, const T* t_cb, T* residuals) const {
    Mat3<T> r;
    Vec3<T> t;
    QuaternionPose(q_cb, t_cb, &r, &t);
    return CornerResiduals(in, r, t, *view, inv_sigma, residuals);
  }
};

// The laser residuals of one view with an analytic Jacobian (the autodiff version of
// the same residual costs ~10x more: a Jet of 27 numbers through every pixel's arithmetic).
//
// With ray = (x, y, 1) the undistorted pixel, the board plane nb . X + ob = 0 and the laser
// plane n . X + d = 0 (n not necessarily unit), the residual is
//   r = (n . X) / |n| + d,  X = ray * depth,  depth = -ob / (nb . ray),
// i.e. r = -ob a / (b |n|) + d with a = n . ray, b = nb . ray. Its derivatives:
//   - intrinsics: through (x, y) by the implicit function theorem on distort(x, y) = m(in),
//     m = ((u - cx) / fx, (v - cy) / fy): d(x, y)/d in = -Jd^-1 (d distort/d in - d m/d in);
//   - the board pose blocks: through (nb, ob), whose derivatives come from one Jet evaluation
//     of the view's camera_from_board (CameraFromBoard or QuaternionPose);
//   - n and d directly.
// The residual values are LaserResidual's.
template <bool kChain>
class LaserCost final : public ceres::CostFunction {
 public:
  static constexpr int kPose = kChain ? 14 : 7;

  LaserCost(const JointView* view, double inv_sigma) : view_(view), w_(inv_sigma) {
    set_num_residuals(static_cast<int>(view->laser_pixels.rows()));
    auto* sizes = mutable_parameter_block_sizes();
    sizes->push_back(kNumIntrinsics);
    for (int b : kChain ? std::vector<int>{4, 3, 4, 3} : std::vector<int>{4, 3}) {
      sizes->push_back(b);
    }
    sizes->push_back(3);
    sizes->push_back(1);
  }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    using J = ceres::Jet<double, kPose>;
    constexpr int kPoseBlocks = kChain ? 4 : 2;
    const double* in = p[0];
    const double* n = p[1 + kPoseBlocks];
    const double d = p[2 + kPoseBlocks][0];
    // The board plane (nb, ob) in the camera frame and its derivatives w.r.t. the pose blocks.
    J pose[kPose];
    {
      int k = 0;
      for (int b = 0; b < kPoseBlocks; ++b) {
        const int size = (b % 2 == 0) ? 4 : 3;
        for (int e = 0; e < size; ++e, ++k) pose[k] = J(p[1 + b][e], k);
      }
    }
    Mat3<J> r;
    Vec3<J> t;
    if constexpr (kChain) {
      CameraFromBoard(pose, pose + 4, view_->base_from_hand.topLeftCorner<3, 3>().eval(),
                      view_->base_from_hand.topRightCorner<3, 1>().eval(), pose + 7, pose + 11, &r,
                      &t);
    } else {
      QuaternionPose(pose, pose + 4, &r, &t);
    }
    const Vec3<J> nbj = r.col(2);
    const J obj = -nbj.dot(t);
    const double nb[3] = {nbj[0].a, nbj[1].a, nbj[2].a};
    const double ob = obj.a;
    const double nn = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    const double unit[3] = {n[0] / nn, n[1] / nn, n[2] / nn};
    for (Eigen::Index i = 0; i < view_->laser_pixels.rows(); ++i) {
      const double u = view_->laser_pixels(i, 0), v = view_->laser_pixels(i, 1);
      double x, y, jd[4], res;
      if (!LaserResidual(in, nb, ob, unit, d, u, v, &x, &y, jd, &res)) return false;
      residuals[i] = res * w_;
      if (jacobians == nullptr) continue;
      const double ray[3] = {x, y, 1.0};
      const double a = n[0] * x + n[1] * y + n[2];
      const double b = nb[0] * x + nb[1] * y + nb[2];
      // dr/dx, dr/dy
      const double drdx = -ob / nn * (n[0] * b - a * nb[0]) / (b * b);
      const double drdy = -ob / nn * (n[1] * b - a * nb[1]) / (b * b);
      if (jacobians[0] != nullptr) {
        const double det = jd[0] * jd[3] - jd[1] * jd[2];
        // g = (dr/dx, dr/dy) Jd^-1, so that dr/din = -g (d distort/d in - d m/d in)
        const double g0 = (drdx * jd[3] - drdy * jd[2]) / det;
        const double g1 = (-drdx * jd[1] + drdy * jd[0]) / det;
        const double r2 = x * x + y * y;
        const double mx = (u - in[kCx]) / in[kFx], my = (v - in[kCy]) / in[kFy];
        double* row = jacobians[0] + i * kNumIntrinsics;
        row[kFx] = -g0 * (mx / in[kFx]) * w_;  // -(g . (0 - dm/dfx)), dm_x/dfx = -mx/fx
        row[kFy] = -g1 * (my / in[kFy]) * w_;
        row[kCx] = -g0 / in[kFx] * w_;  // dm_x/dcx = -1/fx
        row[kCy] = -g1 / in[kFy] * w_;
        row[kK1] = -(g0 * x + g1 * y) * r2 * w_;
        row[kK2] = -(g0 * x + g1 * y) * r2 * r2 * w_;
        row[kK3] = -(g0 * x + g1 * y) * r2 * r2 * r2 * w_;
        row[kP1] = -(g0 * 2.0 * x * y + g1 * (r2 + 2.0 * y * y)) * w_;
        row[kP2] = -(g0 * (r2 + 2.0 * x * x) + g1 * 2.0 * x * y) * w_;
      }
      // dr/d(nb, ob)
      const double k_nb = ob * a / (nn * b * b);
      const double dnb[3] = {k_nb * ray[0], k_nb * ray[1], k_nb * ray[2]};
      const double dob = -a / (b * nn);
      int col = 0;
      for (int blk = 0; blk < kPoseBlocks; ++blk) {
        const int size = (blk % 2 == 0) ? 4 : 3;
        double* jb = jacobians[1 + blk];
        for (int e = 0; e < size; ++e, ++col) {
          if (jb == nullptr) continue;
          jb[i * size + e] = (dnb[0] * nbj[0].v[col] + dnb[1] * nbj[1].v[col] +
                              dnb[2] * nbj[2].v[col] + dob * obj.v[col]) *
                             w_;
        }
      }
      if (jacobians[1 + kPoseBlocks] != nullptr) {
        double* jn = jacobians[1 + kPoseBlocks] + 3 * i;
        const double f = -ob / b;
        for (int e = 0; e < 3; ++e) jn[e] = f * (ray[e] / nn - a * n[e] / (nn * nn * nn)) * w_;
      }
      if (jacobians[2 + kPoseBlocks] != nullptr) jacobians[2 + kPoseBlocks][i] = w_;
    }
    return true;
  }

 private:
  const JointView* view_;
  double w_;
};

// A transform as the parameter blocks of the solve: Eigen quaternion [x, y, z, w] + translation.
struct PoseBlocks {
  std::array<double, 4> q{};
  std::array<double, 3> t{};
  explicit PoseBlocks(const Eigen::Matrix4d& m) {
    const Eigen::Quaterniond rq(Eigen::Matrix3d(m.topLeftCorner<3, 3>()));
    q = {rq.x(), rq.y(), rq.z(), rq.w()};
    t = {m(0, 3), m(1, 3), m(2, 3)};
  }
  Eigen::Matrix4d Matrix() const {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.topLeftCorner<3, 3>() =
        Eigen::Quaterniond(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
    m.topRightCorner<3, 1>() << t[0], t[1], t[2];
    return m;
  }
};

void CheckTransform(const Eigen::Matrix4d& m, const std::string& name) {
  const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
  const double err = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!m.allFinite() || err > 1e-6 || r.determinant() < 0.0 ||
      (m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-12) {
    throw std::invalid_argument(name +
                                " is not a rigid transform (finite, orthonormal rotation "
                                "with determinant +1, last row [0 0 0 1])");
  }
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

ceres::LossFunction* MakeJointLoss(const JointOptions& o) {
  switch (o.loss) {
    case LossKind::kHuber:
      return new ceres::HuberLoss(o.loss_scale);
    case LossKind::kCauchy:
      return new ceres::CauchyLoss(o.loss_scale);
    case LossKind::kNone:
      break;
  }
  return nullptr;
}

// The problem and its parameter blocks; built the same way for solving and for the Jacobian.
class JointProblem {
 public:
  JointProblem(const std::vector<JointView>& views, const JointState& s, const JointOptions& o)
      : options_(o), hand_eye_(s.hand_from_camera), board_(s.base_from_board) {
    CheckInput(views, s, o);
    intrinsics_ = s.intrinsics;
    const double n = s.laser_plane.head<3>().norm();
    normal_ = s.laser_plane.head<3>() / n;
    offset_ = s.laser_plane[3] / n;
    const bool soft = SoftChain(o);
    if (!o.chain || soft) {
      for (const auto& m : s.camera_from_board) views_pose_.emplace_back(m);
    }
    ceres::Problem::Options popt;
    popt.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_ = std::make_unique<ceres::Problem>(popt);
    loss_.reset(MakeJointLoss(o));
    const double wc = 1.0 / o.corner_sigma, wl = 1.0 / o.laser_sigma;
    for (std::size_t i = 0; i < views.size(); ++i) {
      const JointView* v = &views[i];
      const int nc = 2 * static_cast<int>(v->corner_pixels.rows());
      const int nl = static_cast<int>(v->laser_pixels.rows());
      if (o.chain && !soft) {
        if (nc > 0) {  // none in a laser-only view
          AddBlock(new ceres::AutoDiffCostFunction<ChainCorners, ceres::DYNAMIC, 9, 4, 3, 4, 3>(
                       new ChainCorners{v, wc}, nc),
                   {intrinsics_.data(), hand_eye_.q.data(), hand_eye_.t.data(), board_.q.data(),
                    board_.t.data()},
                   nc);
        }
        if (o.laser && nl > 0) {
          AddBlock(new LaserCost<true>(v, wl),
                   {intrinsics_.data(), hand_eye_.q.data(), hand_eye_.t.data(), board_.q.data(),
                    board_.t.data(), normal_.data(), &offset_},
                   nl);
        }
        continue;
      }
      // The view's own board pose: camera mode, or uncertain robot poses (tied to the chain).
      PoseBlocks& p = views_pose_[i];
      if (nc > 0) {  // none in a laser-only view
        AddBlock(new ceres::AutoDiffCostFunction<FreeCorners, ceres::DYNAMIC, 9, 4, 3>(
                     new FreeCorners{v, wc}, nc),
                 {intrinsics_.data(), p.q.data(), p.t.data()}, nc);
      }
      if (o.laser && nl > 0) {
        AddBlock(new LaserCost<false>(v, wl),
                 {intrinsics_.data(), p.q.data(), p.t.data(), normal_.data(), &offset_}, nl);
      }
      if (soft) {
        AddBlock(new ceres::AutoDiffCostFunction<PosePrior, 6, 4, 3, 4, 3, 4, 3>(
                     new PosePrior{v, 1.0 / o.pose_sigma_r, 1.0 / o.pose_sigma_t}),
                 {p.q.data(), p.t.data(), hand_eye_.q.data(), hand_eye_.t.data(), board_.q.data(),
                  board_.t.data()},
                 6);
      }
    }
    // Manifolds and what is held fixed, in the order of the Jacobian's columns.
    std::vector<int> fixed;
    for (int k = 0; k < kNumIntrinsics; ++k) {
      if (o.fixed[k]) fixed.push_back(k);
    }
    static const char* names[kNumIntrinsics] = {"fx", "fy", "cx", "cy", "k1",
                                                "k2", "p1", "p2", "k3"};
    if (static_cast<int>(fixed.size()) == kNumIntrinsics) {
      problem_->SetParameterBlockConstant(intrinsics_.data());
    } else {
      if (!fixed.empty()) {
        problem_->SetManifold(intrinsics_.data(), new ceres::SubsetManifold(kNumIntrinsics, fixed));
      }
      free_.push_back(intrinsics_.data());
      for (int k = 0; k < kNumIntrinsics; ++k) {
        if (!o.fixed[k]) names_.push_back(names[k]);
      }
    }
    auto add_pose = [&](PoseBlocks& p, bool constant, const std::string& prefix) {
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
    };
    if (o.chain) {
      add_pose(hand_eye_, o.hand_eye_known, "hand_");
      add_pose(board_, o.board_pose_known, "board_");
    }
    for (std::size_t i = 0; i < views_pose_.size(); ++i) {
      add_pose(views_pose_[i], false, "view" + std::to_string(i) + "_");
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

  JointOptions options_;
  Vector9d intrinsics_;
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
  ceres::Solver::Options sopt;
  sopt.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  // Uncertain robot poses tie every view's pose to the chain's: dense QR, which, unlike the
  // Schur complement's Cholesky factorisation, copes with the poorly conditioned systems of
  // laser-only views (whose poses the priors and a stripe alone determine).
  sopt.linear_solver_type = options.chain ? ceres::DENSE_QR : ceres::DENSE_SCHUR;
  sopt.max_num_iterations = options.max_iterations;
  sopt.function_tolerance = options.function_tolerance;
  sopt.parameter_tolerance = options.parameter_tolerance;
  sopt.gradient_tolerance = options.gradient_tolerance;
  sopt.num_threads = 1;  // the cost sums of several threads would depend on their schedule
  sopt.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(sopt, &jp.problem(), &summary);

  JointResult r;
  r.state = jp.State();
  r.initial_cost = summary.initial_cost;
  r.final_cost = summary.final_cost;
  r.iterations = static_cast<int>(summary.iterations.size()) - 1;
  r.termination = ceres::TerminationTypeToString(summary.termination_type);
  r.message = summary.message;
  r.usable = summary.IsSolutionUsable();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

bool SoftChain(const JointOptions& o) {
  return o.chain && o.pose_sigma_t > 0.0 && o.pose_sigma_r > 0.0;
}

JointResiduals EvaluateJoint(const std::vector<JointView>& views, const JointState& s,
                             const JointOptions& o) {
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
      const PoseBlocks f(cb), h(s.hand_from_camera), b(s.base_from_board);
      Vector6d e;
      PoseError(f.q.data(), f.t.data(), h.q.data(), h.t.data(), b.q.data(), b.t.data(),
                v.base_from_hand, e.data());
      out.pose.push_back(e);
    }
    const Eigen::Matrix3d r = cb.topLeftCorner<3, 3>();
    const Eigen::Vector3d t = cb.topRightCorner<3, 1>();
    RowMatX2 c(v.corner_pixels.rows(), 2);
    CornerResiduals(s.intrinsics.data(), r, t, v, 1.0, c.data());
    out.corners.push_back(c);
    const Eigen::Vector3d nb = r.col(2);
    const double ob = -nb.dot(t);
    Eigen::VectorXd l(v.laser_pixels.rows());
    for (Eigen::Index k = 0; k < v.laser_pixels.rows(); ++k) {
      double x, y, jd[4], res;
      l[k] = LaserResidual(s.intrinsics.data(), nb.data(), ob, normal.data(), offset,
                           v.laser_pixels(k, 0), v.laser_pixels(k, 1), &x, &y, jd, &res)
                 ? res
                 : kNaN;
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

Eigen::Matrix4d MeanTransform(const std::vector<Eigen::Matrix4d>& transforms) {
  if (transforms.empty()) throw std::invalid_argument("no transforms to average");
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  for (const auto& m : transforms) {
    sum += m.topLeftCorner<3, 3>();
    t += m.topRightCorner<3, 1>();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  Eigen::Matrix4d out = Eigen::Matrix4d::Identity();
  out.topLeftCorner<3, 3>() = svd.matrixU() * d * svd.matrixV().transpose();
  out.topRightCorner<3, 1>() = t / static_cast<double>(transforms.size());
  return out;
}

Eigen::Matrix4d HandEyeParkMartin(const std::vector<Eigen::Matrix4d>& base_from_hand,
                                  const std::vector<Eigen::Matrix4d>& camera_from_board,
                                  double min_angle) {
  if (base_from_hand.size() != camera_from_board.size()) {
    throw std::invalid_argument("hand-eye: " + std::to_string(base_from_hand.size()) +
                                " robot poses but " + std::to_string(camera_from_board.size()) +
                                " camera poses");
  }
  const std::size_t n = base_from_hand.size();
  for (std::size_t i = 0; i < n; ++i) {
    CheckTransform(base_from_hand[i], "robot pose " + std::to_string(i));
    CheckTransform(camera_from_board[i], "camera pose " + std::to_string(i));
  }
  struct Motion {
    Eigen::Matrix4d a, b;
  };
  std::vector<Motion> motions;
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      // A = hand_i_from_hand_j, B = camera_i_from_camera_j: A X = X B.
      const Eigen::Matrix4d a = base_from_hand[i].inverse() * base_from_hand[j];
      const Eigen::Matrix4d b = camera_from_board[i] * camera_from_board[j].inverse();
      const Eigen::AngleAxisd aa(Eigen::Matrix3d(a.topLeftCorner<3, 3>()));
      const Eigen::AngleAxisd ab(Eigen::Matrix3d(b.topLeftCorner<3, 3>()));
      if (aa.angle() < min_angle || ab.angle() < min_angle) continue;
      m += (ab.axis() * ab.angle()) * (aa.axis() * aa.angle()).transpose();
      motions.push_back({a, b});
    }
  }
  if (motions.size() < 2) {
    throw std::invalid_argument(
        "hand-eye calibration needs at least two pairs of views whose orientations differ by "
        "more than " +
        std::to_string(min_angle * 180.0 / M_PI) + " degrees; got " +
        std::to_string(motions.size()));
  }
  // R_X = (M^T M)^(-1/2) M^T, through the SVD M = U S V^T: R_X = V U^T (det-corrected).
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d s = svd.singularValues();
  if (!(s[1] > 1e-3 * s[0])) {
    throw std::invalid_argument(
        "hand-eye calibration needs robot rotations about at least two non-parallel axes; the "
        "poses rotate about one axis only");
  }
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  const Eigen::Matrix3d rx = svd.matrixV() * d * svd.matrixU().transpose();
  // Translation: (R_A - I) t_X = R_X t_B - t_A, stacked, least squares.
  Eigen::MatrixXd c(3 * motions.size(), 3);
  Eigen::VectorXd rhs(3 * motions.size());
  for (std::size_t k = 0; k < motions.size(); ++k) {
    c.middleRows<3>(3 * k) = motions[k].a.topLeftCorner<3, 3>() - Eigen::Matrix3d::Identity();
    rhs.segment<3>(3 * k) =
        rx * motions[k].b.topRightCorner<3, 1>() - motions[k].a.topRightCorner<3, 1>();
  }
  Eigen::Matrix4d x = Eigen::Matrix4d::Identity();
  x.topLeftCorner<3, 3>() = rx;
  x.topRightCorner<3, 1>() = c.colPivHouseholderQr().solve(rhs);
  return x;
}

}  // namespace hmlvs::general
