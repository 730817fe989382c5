#include "hmlvs/solvers/joint_costs.h"

#include <ceres/ceres.h>

#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "hmlvs/geometry/geometry.h"

namespace hmlvs::solvers {

using namespace hmlvs::opencv;
using geometry::Mat3;
using geometry::QuaternionPose;
using geometry::Vec3;

namespace {

// CornerResiduals (joint_costs.h) on any scalar; without kWide the lens terms beyond the
// five-term one are taken as 0 (Distort).
template <bool kWide, typename T>
bool Corners(const T* in, const Mat3<T>& r, const Vec3<T>& t, const JointView& view,
             double inv_sigma, T* residuals) {
  bool ok = true;
  T tilt[9];  // the tilted sensor's homography, once for all corners (kWide only)
  if constexpr (kWide) TiltHomography(in[kTauX], in[kTauY], false, tilt);
  for (Eigen::Index i = 0; i < view.corner_points.rows(); ++i) {
    const Vec3<T> p = r * view.corner_points.row(i).transpose().cast<T>() + t;
    T px[2];
    ok = ProjectPoint<kWide>(in, p.data(), px, tilt) && ok;
    residuals[2 * i] = (px[0] - view.corner_pixels(i, 0)) * inv_sigma;
    residuals[2 * i + 1] = (px[1] - view.corner_pixels(i, 1)) * inv_sigma;
  }
  return ok;
}

template <bool kWide>
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
    return Corners<kWide>(in, r, t, *view, inv_sigma, residuals);
  }
};

// The robot pose error a view's own board pose implies (JointOptions::pose_sigma_t):
// E = hand_from_camera camera_from_board_chain inv(camera_from_board) inv(hand_from_camera),
// as (rotation vector, translation) in the hand frame.
template <typename T>
void PoseErrorOf(const T* q_cb, const T* t_cb, const T* q_hc, const T* t_hc, const T* q_bb,
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
  const Vec3<T> w = geometry::RotationVector(re);
  for (int k = 0; k < 3; ++k) {
    out[k] = w[k];
    out[3 + k] = te[k];
  }
}

struct PosePrior {
  const JointView* view;
  double w_r, w_t;
  template <typename T>
  bool operator()(const T* q_cb, const T* t_cb, const T* q_hc, const T* t_hc, const T* q_bb,
                  const T* t_bb, T* residuals) const {
    PoseErrorOf(q_cb, t_cb, q_hc, t_hc, q_bb, t_bb, view->base_from_hand, residuals);
    for (int k = 0; k < 3; ++k) {
      residuals[k] *= w_r;
      residuals[3 + k] *= w_t;
    }
    return true;
  }
};

template <bool kWide>
struct FreeCorners {
  const JointView* view;
  double inv_sigma;
  template <typename T>
  bool operator()(const T* in, const T* q_cb, const T* t_cb, T* residuals) const {
    Mat3<T> r;
    Vec3<T> t;
    QuaternionPose(q_cb, t_cb, &r, &t);
    return Corners<kWide>(in, r, t, *view, inv_sigma, residuals);
  }
};

// Jets of fx, fy, cx, cy, taux, tauy (in that order), the unknowns the point the distortion
// must reach for a pixel depends on (DistortedTarget).
using J6 = ceres::Jet<double, 6>;
constexpr int kTargetIntrinsics[6] = {kFx, kFy, kCx, kCy, kTauX, kTauY};

// The inverse of the tilted sensor's homography (TiltHomography) as Jets of
// kTargetIntrinsics, once for a view's pixels (TargetDerivatives).
void UntiltJets(const double* in, J6* untilt) {
  TiltHomography(J6(in[kTauX], 4), J6(in[kTauY], 5), true, untilt);
}

// d(mx, my)/d(fx, fy, cx, cy, taux, tauy) of the point the distortion must reach for pixel
// (u, v) (DistortedTarget, through the tilted sensor's homography `untilt`, UntiltJets).
void TargetDerivatives(const double* in, const J6* untilt, double u, double v, double* dmx,
                       double* dmy) {
  J6 jin[kNumIntrinsics];
  for (int e = 0; e < 4; ++e) jin[kTargetIntrinsics[e]] = J6(in[kTargetIntrinsics[e]], e);
  J6 mx, my;
  DistortedTarget(jin, untilt, u, v, &mx, &my);
  for (int e = 0; e < 6; ++e) {
    dmx[e] = mx.v[e];
    dmy[e] = my.v[e];
  }
}

// One stripe pixel's row of d(residual)/d(intrinsics), times w, from the residual's derivatives
// drdx, drdy with respect to the undistorted point (x, y) and the distortion's Jacobian jd
// there (row-major 2x2), through the implicit function theorem (LaserCost). `classic`: the
// terms k4 to tauy are held at 0 and their entries are 0; otherwise `untilt` is UntiltJets'.
void IntrinsicsRow(const double* in, const J6* untilt, double u, double v, double x, double y,
                   const double* jd, double drdx, double drdy, double w, bool classic,
                   double* row) {
  const double det = jd[0] * jd[3] - jd[1] * jd[2];
  // g = (dr/dx, dr/dy) Jd^-1, so that dr/din = -g (d distort/d in - d m/d in)
  const double g0 = (drdx * jd[3] - drdy * jd[2]) / det;
  const double g1 = (-drdx * jd[1] + drdy * jd[0]) / det;
  const double r2 = x * x + y * y, r4 = r2 * r2, r6 = r4 * r2;
  if (classic) {  // m = ((u - cx) / fx, (v - cy) / fy)
    const double mx = (u - in[kCx]) / in[kFx], my = (v - in[kCy]) / in[kFy];
    row[kFx] = -g0 * (mx / in[kFx]) * w;  // -(g . (0 - dm/dfx)), dm_x/dfx = -mx/fx
    row[kFy] = -g1 * (my / in[kFy]) * w;
    row[kCx] = -g0 / in[kFx] * w;  // dm_x/dcx = -1/fx
    row[kCy] = -g1 / in[kFy] * w;
  } else {  // m through the tilted sensor's homography too
    double dmx[6], dmy[6];
    TargetDerivatives(in, untilt, u, v, dmx, dmy);
    for (int e = 0; e < 6; ++e) row[kTargetIntrinsics[e]] = (g0 * dmx[e] + g1 * dmy[e]) * w;
  }
  // classic: k4 to tauy held at 0, their rows 0 (the five-term lens's rows alone)
  // radial = num / den: d/dk1..k3 = r^2n / den, d/dk4..k6 = -radial r^2n / den (times x, y)
  const double den = classic ? 1.0 : 1.0 + r2 * (in[kK4] + r2 * (in[kK5] + r2 * in[kK6]));
  const double gr = -(g0 * x + g1 * y) * w / den;
  row[kK1] = gr * r2;
  row[kK2] = gr * r4;
  row[kK3] = gr * r6;
  if (classic) {
    for (int k = kK4; k <= kTauY; ++k) row[k] = 0.0;
  } else {
    const double radial = (1.0 + r2 * (in[kK1] + r2 * (in[kK2] + r2 * in[kK3]))) / den;
    row[kK4] = -gr * radial * r2;
    row[kK5] = -gr * radial * r4;
    row[kK6] = -gr * radial * r6;
    row[kS1] = -g0 * r2 * w;
    row[kS2] = -g0 * r4 * w;
    row[kS3] = -g1 * r2 * w;
    row[kS4] = -g1 * r4 * w;
  }
  row[kP1] = -(g0 * 2.0 * x * y + g1 * (r2 + 2.0 * y * y)) * w;
  row[kP2] = -(g0 * (r2 + 2.0 * x * x) + g1 * 2.0 * x * y) * w;
}

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

  LaserCost(const JointView* view, double inv_sigma, const Eigen::VectorXd* scales,
            bool classic_lens)
      : view_(view),
        w_(inv_sigma),
        scales_(scales ? *scales : Eigen::VectorXd()),
        classic_(classic_lens) {
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
    const Untilt untilt(in);
    J6 untilt_jets[9];
    if (!classic_ && jacobians != nullptr && jacobians[0] != nullptr) UntiltJets(in, untilt_jets);
    for (Eigen::Index i = 0; i < view_->laser_pixels.rows(); ++i) {
      const double u = view_->laser_pixels(i, 0), v = view_->laser_pixels(i, 1);
      double x, y, jd[4], res;
      if (!LaserResidual(in, nb, ob, unit, d, u, v, &x, &y, jd, &res, &untilt)) return false;
      if (scales_.size() > 0) {
        LineRow(in, untilt_jets, nb, ob, n, nn, d, x, y, jd, u, v, i, nbj, obj, residuals,
                jacobians);
        continue;
      }
      residuals[i] = res * w_;
      if (jacobians == nullptr) continue;
      const double ray[3] = {x, y, 1.0};
      const double a = n[0] * x + n[1] * y + n[2];
      const double b = nb[0] * x + nb[1] * y + nb[2];
      // dr/dx, dr/dy
      const double drdx = -ob / nn * (n[0] * b - a * nb[0]) / (b * b);
      const double drdy = -ob / nn * (n[1] * b - a * nb[1]) / (b * b);
      if (jacobians[0] != nullptr) {
        IntrinsicsRow(in, untilt_jets, u, v, x, y, jd, drdx, drdy, w_, classic_,
                      jacobians[0] + i * kNumIntrinsics);
      }
      // dr/d(nb, ob)
      const double k_nb = ob * a / (nn * b * b);
      const double dnb[3] = {k_nb * ray[0], k_nb * ray[1], k_nb * ray[2]};
      const double dob = -a / (b * nn);
      BoardPlaneRows(dnb, dob, w_, nbj, obj, i, jacobians);
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
  // Pixel i's residual scales_[i] LaserLineDistance and its Jacobian row: with
  // R = c s N, s = m . ray, m = unit - (d / ob) nb, N = |(m_x / fx, m_y / fy)|^-1,
  //   dR/d(x, y) = c N (m_x, m_y), through the undistortion to the intrinsics (IntrinsicsRow),
  //   plus directly dR/dfx = c s N^3 m_x^2 / fx^3 (and fy alike);
  //   g = dR/dm = c (N ray - s N^3 (m_x / fx^2, m_y / fy^2, 0)),
  //   dR/dnb = -(d / ob) g, dR/dob = (d / ob^2) g . nb, dR/dd = -(g . nb) / ob,
  //   dR/dn = (g - (g . unit) unit) / |n|.
  template <typename J>
  void LineRow(const double* in, const J6* untilt, const double* nb, double ob, const double* n,
               double nn, double d, double x, double y, const double* jd, double u, double v,
               Eigen::Index i, const Vec3<J>& nbj, const J& obj, double* residuals,
               double** jacobians) const {
    constexpr int kPoseBlocks = kChain ? 4 : 2;
    const double c = scales_[i] * w_;
    const double unit[3] = {n[0] / nn, n[1] / nn, n[2] / nn};
    const double m[3] = {unit[0] - d / ob * nb[0], unit[1] - d / ob * nb[1],
                         unit[2] - d / ob * nb[2]};
    const double ray[3] = {x, y, 1.0};
    const double sv = m[0] * x + m[1] * y + m[2];
    const double ax = m[0] / in[kFx], ay = m[1] / in[kFy];
    const double big_n = 1.0 / std::sqrt(ax * ax + ay * ay);
    residuals[i] = c * sv * big_n;
    if (jacobians == nullptr) return;
    const double n3 = big_n * big_n * big_n;
    if (jacobians[0] != nullptr) {
      double* row = jacobians[0] + i * kNumIntrinsics;
      IntrinsicsRow(in, untilt, u, v, x, y, jd, big_n * m[0], big_n * m[1], c, classic_, row);
      row[kFx] += c * sv * n3 * ax * ax / in[kFx];
      row[kFy] += c * sv * n3 * ay * ay / in[kFy];
    }
    const double g[3] = {c * (big_n * ray[0] - sv * n3 * ax / in[kFx]),
                         c * (big_n * ray[1] - sv * n3 * ay / in[kFy]), c * big_n * ray[2]};
    const double g_nb = g[0] * nb[0] + g[1] * nb[1] + g[2] * nb[2];
    const double dnb[3] = {-d / ob * g[0], -d / ob * g[1], -d / ob * g[2]};
    const double dob = d / (ob * ob) * g_nb;
    BoardPlaneRows(dnb, dob, 1.0, nbj, obj, i, jacobians);
    if (jacobians[1 + kPoseBlocks] != nullptr) {
      double* jn = jacobians[1 + kPoseBlocks] + 3 * i;
      const double gu = g[0] * unit[0] + g[1] * unit[1] + g[2] * unit[2];
      for (int e = 0; e < 3; ++e) jn[e] = (g[e] - gu * unit[e]) / nn;
    }
    if (jacobians[2 + kPoseBlocks] != nullptr) jacobians[2 + kPoseBlocks][i] = -g_nb / ob;
  }

  // Pixel i's rows of the board pose blocks, times w, from its residual's derivatives dnb,
  // dob with respect to the board plane (nb, ob), whose own derivatives with respect to the
  // blocks are the Jets nbj, obj.
  template <typename J>
  static void BoardPlaneRows(const double* dnb, double dob, double w, const Vec3<J>& nbj,
                             const J& obj, Eigen::Index i, double** jacobians) {
    constexpr int kPoseBlocks = kChain ? 4 : 2;
    int col = 0;
    for (int blk = 0; blk < kPoseBlocks; ++blk) {
      const int size = (blk % 2 == 0) ? 4 : 3;
      double* jb = jacobians[1 + blk];
      for (int e = 0; e < size; ++e, ++col) {
        if (jb == nullptr) continue;
        jb[i * size + e] = (dnb[0] * nbj[0].v[col] + dnb[1] * nbj[1].v[col] +
                            dnb[2] * nbj[2].v[col] + dob * obj.v[col]) *
                           w;
      }
    }
  }

  const JointView* view_;
  double w_;
  Eigen::VectorXd scales_;  // empty: the mm residual (LaserResidual)
  bool classic_;            // k4 to tauy held at 0 (IntrinsicsRow)
};

}  // namespace

PoseBlocks::PoseBlocks(const Eigen::Matrix4d& m) {
  const Eigen::Quaterniond rq(Eigen::Matrix3d(m.topLeftCorner<3, 3>()));
  q = {rq.x(), rq.y(), rq.z(), rq.w()};
  t = {m(0, 3), m(1, 3), m(2, 3)};
}

Eigen::Matrix4d PoseBlocks::Matrix() const {
  return geometry::Transform(geometry::QuaternionRotation(q.data()),
                             Eigen::Vector3d(t[0], t[1], t[2]));
}

bool CornerResiduals(const double* intrinsics, const Eigen::Matrix3d& r, const Eigen::Vector3d& t,
                     const JointView& view, double inv_sigma, double* residuals) {
  return Corners<true>(intrinsics, r, t, view, inv_sigma, residuals);
}

bool LaserResidual(const double* in, const double* nb, double ob, const double* unit, double d,
                   double u, double v, double* x, double* y, double* jd, double* residual,
                   const Untilt* untilt) {
  if (!UndistortNormalized(in, u, v, x, y, jd, untilt)) return false;
  double point[3];
  if (!(RayPlanePoint(*x, *y, nb, ob, point) > 0.0)) return false;
  *residual = unit[0] * point[0] + unit[1] * point[1] + unit[2] * point[2] + d;
  return true;
}

Vector6d PoseError(const PoseBlocks& camera_from_board, const PoseBlocks& hand_from_camera,
                   const PoseBlocks& base_from_board, const Eigen::Matrix4d& base_from_hand) {
  Vector6d e;
  PoseErrorOf(camera_from_board.q.data(), camera_from_board.t.data(), hand_from_camera.q.data(),
              hand_from_camera.t.data(), base_from_board.q.data(), base_from_board.t.data(),
              base_from_hand, e.data());
  return e;
}

ceres::CostFunction* NewChainCornerCost(const JointView* view, double inv_sigma,
                                        bool classic_lens) {
  const int n = 2 * static_cast<int>(view->corner_pixels.rows());
  if (classic_lens) {
    return new ceres::AutoDiffCostFunction<ChainCorners<false>, ceres::DYNAMIC, kNumIntrinsics, 4,
                                           3, 4, 3>(new ChainCorners<false>{view, inv_sigma}, n);
  }
  return new ceres::AutoDiffCostFunction<ChainCorners<true>, ceres::DYNAMIC, kNumIntrinsics, 4, 3,
                                         4, 3>(new ChainCorners<true>{view, inv_sigma}, n);
}

ceres::CostFunction* NewFreeCornerCost(const JointView* view, double inv_sigma, bool classic_lens) {
  const int n = 2 * static_cast<int>(view->corner_pixels.rows());
  if (classic_lens) {
    return new ceres::AutoDiffCostFunction<FreeCorners<false>, ceres::DYNAMIC, kNumIntrinsics, 4,
                                           3>(new FreeCorners<false>{view, inv_sigma}, n);
  }
  return new ceres::AutoDiffCostFunction<FreeCorners<true>, ceres::DYNAMIC, kNumIntrinsics, 4, 3>(
      new FreeCorners<true>{view, inv_sigma}, n);
}

ceres::CostFunction* NewLaserCost(const JointView* view, double inv_sigma, bool chain,
                                  bool classic_lens, const Eigen::VectorXd* scales) {
  if (chain) return new LaserCost<true>(view, inv_sigma, scales, classic_lens);
  return new LaserCost<false>(view, inv_sigma, scales, classic_lens);
}

double LaserLineDistance(const double* in, const double* nb, double ob, const double* unit,
                         double d, double x, double y) {
  double m[3];
  for (int k = 0; k < 3; ++k) m[k] = unit[k] - d / ob * nb[k];
  return (m[0] * x + m[1] * y + m[2]) / std::hypot(m[0] / in[kFx], m[1] / in[kFy]);
}

Eigen::VectorXd LaserScales(const double* in, const double* nb, double ob, const double* unit,
                            double d, const RowMatX2& pixels) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(pixels.rows());
  double m[3];
  for (int k = 0; k < 3; ++k) m[k] = unit[k] - d / ob * nb[k];
  const double inv_n = std::hypot(m[0] / in[kFx], m[1] / in[kFy]);
  const Untilt untilt(in);
  for (Eigen::Index i = 0; i < pixels.rows(); ++i) {
    double x, y, jd[4];
    if (!UndistortNormalized(in, pixels(i, 0), pixels(i, 1), &x, &y, jd, &untilt)) continue;
    const double depth = -ob / (nb[0] * x + nb[1] * y + nb[2]);
    if (depth > 0.0) out[i] = depth * inv_n;
  }
  return out;
}

ceres::CostFunction* NewPosePriorCost(const JointView* view, double w_r, double w_t) {
  return new ceres::AutoDiffCostFunction<PosePrior, 6, 4, 3, 4, 3, 4, 3>(
      new PosePrior{view, w_r, w_t});
}

}  // namespace hmlvs::solvers
