// The general sensor model (model "opencv"): projection and its exact inverse, the joint
// calibration's Jacobian against central differences, the closed-form hand-eye and the joint
// solve on exact data.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <utility>
#include <vector>

#include "hmlvs/geometry/hand_eye.h"
#include "hmlvs/model/opencv.h"
#include "hmlvs/solvers/joint.h"
#include "hmlvs/solvers/joint_costs.h"

namespace hmlvs::opencv {
namespace {

using geometry::HandEyeParkMartin;
using namespace hmlvs::solvers;

IntrinsicsVector Intrinsics() {
  IntrinsicsVector in = IntrinsicsVector::Zero();
  in.head<kNumClassicIntrinsics>() << 1100, 1090, 512, 384, -0.165, 0.05, 0.0005, -0.0003, 0.01;
  return in;
}

// A wide lens of OpenCV's fourteen terms: the rational model's denominator, the thin prism and
// a tilted (Scheimpflug) sensor, 3 and -2 degrees.
IntrinsicsVector WideIntrinsics() {
  IntrinsicsVector in;
  in << 700, 705, 515, 380, 0.35, -0.12, 0.0006, -0.0004, 0.01, 0.6, -0.05, 0.02, 0.002, -0.001,
      0.0015, 0.0008, 0.052, -0.035;
  return in;
}

Eigen::Matrix4d Transform(const Eigen::Vector3d& rotvec, const Eigen::Vector3d& t) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (rotvec.norm() > 0) {
    m.topLeftCorner<3, 3>() = Eigen::AngleAxisd(rotvec.norm(), rotvec.normalized()).matrix();
  }
  m.topRightCorner<3, 1>() = t;
  return m;
}

struct Scene {
  std::vector<JointView> views;
  JointState truth;
};

// 12 views of a 6 x 9 board (25 mm squares) in chain mode, with exact corners and stripe pixels.
Scene MakeScene(unsigned seed, const IntrinsicsVector& intrinsics = Intrinsics()) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> tilt(-0.4, 0.4), shift(-20, 20), depth(-50, 50);
  Scene s;
  s.truth.intrinsics = intrinsics;
  s.truth.hand_from_camera = Transform({0.02, -0.03, 1.6}, {60, 5, -45});
  s.truth.base_from_board = Transform({0.05, 0.02, 0.3}, {700, 50, 10});
  Eigen::Vector3d n(0.03, 0.6, 0.8);
  n.normalize();
  s.truth.laser_plane << n, -n.dot(Eigen::Vector3d(0, 60, 400));
  while (s.views.size() < 12) {
    const Eigen::Matrix4d cb = Transform({tilt(rng), tilt(rng), tilt(rng)},
                                         {-100 + shift(rng), -62 + shift(rng), 450 + depth(rng)});
    JointView v;
    v.base_from_hand = s.truth.base_from_board * cb.inverse() * s.truth.hand_from_camera.inverse();
    v.corner_points.resize(54, 3);
    v.corner_pixels.resize(54, 2);
    for (int i = 0; i < 54; ++i) {
      v.corner_points.row(i) << (i / 9) * 25.0, (i % 9) * 25.0, 0.0;
      const Eigen::Vector3d p =
          cb.topLeftCorner<3, 3>() * v.corner_points.row(i).transpose() + cb.topRightCorner<3, 1>();
      ProjectPoint(s.truth.intrinsics.data(), p.data(), v.corner_pixels.row(i).data());
    }
    std::vector<Eigen::Vector2d> laser;
    for (double x = -10; x <= 135; x += 1.0) {
      // board point (x, y, 0) on the laser plane: solve for y
      const Eigen::Vector3d r0 = cb.topLeftCorner<3, 3>().col(0) * x + cb.topRightCorner<3, 1>();
      const double a = n.dot(cb.topLeftCorner<3, 3>().col(1));
      const double y = -(n.dot(r0) + s.truth.laser_plane[3]) / a;
      if (y < -10 || y > 210) continue;
      const Eigen::Vector3d p = r0 + cb.topLeftCorner<3, 3>().col(1) * y;
      Eigen::Vector2d px;
      ProjectPoint(s.truth.intrinsics.data(), p.data(), px.data());
      laser.push_back(px);
    }
    if (laser.size() < 30) continue;
    v.laser_pixels.resize(static_cast<Eigen::Index>(laser.size()), 2);
    for (std::size_t k = 0; k < laser.size(); ++k) v.laser_pixels.row(k) = laser[k];
    s.views.push_back(v);
  }
  return s;
}

TEST(GeneralModel, UndistortInvertsProjection) {
  const IntrinsicsVector in = Intrinsics();
  for (double x = -0.45; x <= 0.45; x += 0.05) {
    for (double y = -0.35; y <= 0.35; y += 0.05) {
      const double p[3] = {x * 500, y * 500, 500};
      double px[2];
      ASSERT_TRUE(ProjectPoint(in.data(), p, px));
      double ux, uy;
      ASSERT_TRUE(UndistortNormalized(in.data(), px[0], px[1], &ux, &uy));
      EXPECT_NEAR(ux, x, 1e-12);
      EXPECT_NEAR(uy, y, 1e-12);
    }
  }
}

TEST(GeneralModel, UndistortInvertsAWideLensOfFourteenTerms) {
  const IntrinsicsVector in = WideIntrinsics();
  for (double x = -0.7; x <= 0.7; x += 0.05) {
    for (double y = -0.55; y <= 0.55; y += 0.05) {
      const double p[3] = {x * 500, y * 500, 500};
      double px[2], ux, uy;
      ASSERT_TRUE(ProjectPoint(in.data(), p, px));
      ASSERT_TRUE(UndistortNormalized(in.data(), px[0], px[1], &ux, &uy));
      EXPECT_NEAR(ux, x, 1e-12);
      EXPECT_NEAR(uy, y, 1e-12);
    }
  }
}

TEST(GeneralModel, UndistortRefusesFoldedRegion) {
  IntrinsicsVector in = Intrinsics();
  in[kK1] = -0.6;  // the distortion folds over at r ~ 0.75
  double x, y;
  EXPECT_FALSE(UndistortNormalized(in.data(), 512 + 1100 * 1.5, 384, &x, &y));
}

TEST(GeneralModel, LaserPointsLieOnThePlaneAndOnTheirRays) {
  const Scene s = MakeScene(1);
  const PointsResult r =
      LaserPointsInCamera(s.truth.intrinsics, s.truth.laser_plane, s.views[0].laser_pixels, true);
  for (Eigen::Index i = 0; i < r.points.rows(); ++i) {
    const Eigen::Vector3d p = r.points.row(i);
    EXPECT_NEAR(s.truth.laser_plane.head<3>().dot(p) + s.truth.laser_plane[3], 0.0, 1e-9);
    double px[2];
    ProjectPoint(s.truth.intrinsics.data(), p.data(), px);
    EXPECT_NEAR(px[0], s.views[0].laser_pixels(i, 0), 1e-8);
    EXPECT_NEAR(px[1], s.views[0].laser_pixels(i, 1), 1e-8);
  }
}

// The weighted residuals of every view, stacked as JointJacobian orders them.
Eigen::VectorXd Stacked(const std::vector<JointView>& views, const JointState& s,
                        const JointOptions& o, const JointState* scales_at = nullptr) {
  const JointResiduals r = EvaluateJoint(views, s, o, scales_at);
  std::vector<double> out;
  for (const auto& c : r.corners)
    for (Eigen::Index i = 0; i < c.size(); ++i) out.push_back(c.data()[i] / o.corner_sigma);
  for (const auto& l : r.laser)
    for (Eigen::Index i = 0; i < l.size(); ++i) out.push_back(l[i] / o.laser_sigma);
  return Eigen::Map<Eigen::VectorXd>(out.data(), static_cast<Eigen::Index>(out.size()));
}

Eigen::Matrix4d RotateLeft(const Eigen::Matrix4d& m, int axis, double h) {
  Eigen::Matrix4d out = m;
  out.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(h, Eigen::Vector3d::Unit(axis)).matrix() * m.topLeftCorner<3, 3>();
  return out;
}

// The analytic Jacobian of a state against central differences of the stacked residuals.
struct JacobianCheck {
  const std::vector<JointView>& views;
  const JointState& at;
  const JointOptions& options;
  std::vector<std::string> names;  // before j: JointJacobian fills it while j is built
  Eigen::MatrixXd j;

  JacobianCheck(const std::vector<JointView>& v, const JointState& s, const JointOptions& o)
      : views(v), at(s), options(o), j(JointJacobian(v, s, o, &names)) {}

  template <typename Perturb>
  Eigen::VectorXd Numeric(Perturb perturb, double h) const {
    JointState plus = at, minus = at;
    perturb(&plus, h);
    perturb(&minus, -h);
    return (Stacked(views, plus, options) - Stacked(views, minus, options)) / (2 * h);
  }

  void ExpectColumn(int col, const Eigen::VectorXd& d) const {
    const double scale = std::max(1.0, d.cwiseAbs().maxCoeff());
    EXPECT_LT((j.col(col) - d).cwiseAbs().maxCoeff() / scale, 1e-5) << names[col];
  }

  void ExpectIntrinsics() const {
    for (int k = 0; k < kNumIntrinsics; ++k) {
      if (options.fixed[k]) continue;
      ExpectColumn(k, Numeric([k](JointState* st, double e) { st->intrinsics[k] += e; },
                              k < 4 ? 1e-3 : 1e-6));
    }
  }
};

TEST(GeneralModel, JointJacobianMatchesCentralDifferences) {
  Scene s = MakeScene(2);
  // Off the solution, so that no column is judged at a stationary point.
  JointState at = s.truth;
  at.intrinsics[kFx] += 3;
  at.intrinsics[kK1] += 0.01;
  at.hand_from_camera = RotateLeft(at.hand_from_camera, 0, 0.01);
  at.laser_plane[3] += 1.0;
  JointOptions o;
  const JacobianCheck c(s.views, at, o);
  ASSERT_EQ(c.names.size(), 24u);
  ASSERT_EQ(c.j.cols(), 24);
  auto numeric = [&](auto perturb, double h) { return c.Numeric(perturb, h); };
  auto expect_column = [&](int col, const Eigen::VectorXd& d) { c.ExpectColumn(col, d); };
  const Eigen::MatrixXd& j = c.j;
  c.ExpectIntrinsics();
  // hand_from_camera (columns 9-14), then base_from_board (15-20): rotation, translation
  for (auto [first, member] :
       {std::pair{9, &JointState::hand_from_camera}, std::pair{15, &JointState::base_from_board}}) {
    for (int axis = 0; axis < 3; ++axis) {
      auto rotate = [axis, m = member](JointState* st, double e) {
        st->*m = RotateLeft(st->*m, axis, e);
      };
      auto shift = [axis, m = member](JointState* st, double e) { (st->*m)(axis, 3) += e; };
      expect_column(first + axis, numeric(rotate, 1e-6));
      expect_column(first + 3 + axis, numeric(shift, 1e-4));
    }
  }
  expect_column(23, numeric([](JointState* st, double e) { st->laser_plane[3] += e; }, 1e-4));
  // The normal's two tangent columns must span the derivative along any direction normal to it.
  const Eigen::Vector3d n = at.laser_plane.head<3>().normalized();
  const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
  for (const Eigen::Vector3d& e : {e1, e2}) {
    const Eigen::VectorXd d = numeric(
        [&](JointState* st, double h) { st->laser_plane.head<3>() = (n + h * e).normalized(); },
        1e-7);
    const Eigen::MatrixXd t = j.middleCols(21, 2);
    const Eigen::Vector2d c = t.colPivHouseholderQr().solve(d);
    EXPECT_LT((t * c - d).cwiseAbs().maxCoeff() / d.cwiseAbs().maxCoeff(), 1e-5);
  }
}

TEST(GeneralModel, JointJacobianOfEveryDistortionTermMatchesCentralDifferences) {
  Scene s = MakeScene(6, WideIntrinsics());
  JointState at = s.truth;
  at.intrinsics[kK4] += 0.05;  // off the solution
  at.intrinsics[kS2] += 0.001;
  at.intrinsics[kTauY] += 0.01;
  JointOptions o;
  o.fixed = {};  // all eighteen free: columns 0-17
  const JacobianCheck c(s.views, at, o);
  ASSERT_EQ(c.names.size(), 33u);
  EXPECT_EQ(c.names[kK4], "k4");
  EXPECT_EQ(c.names[kS4], "s4");
  EXPECT_EQ(c.names[kTauY], "tauy");
  c.ExpectIntrinsics();
}

TEST(GeneralModel, JointSolveFitsAWideLensOfFourteenTerms) {
  const Scene s = MakeScene(7, WideIntrinsics());
  JointState start = s.truth;
  start.intrinsics.tail<kNumIntrinsics - 4>().setZero();  // no distortion at the start
  start.intrinsics[kFx] *= 1.01;
  JointOptions o;
  o.fixed = {};
  const JointResult r = SolveJoint(s.views, start, o);
  // On exact data the cost falls towards 0 along the rational terms' flat valley by a large
  // fraction every step, so Ceres' relative tests never call it converged: the fit is judged
  // by what it predicts.
  EXPECT_LT(r.final_cost, 1e-8);
  // The rational terms trade off against each other over a finite field of view: the lens is
  // judged by its pixels (those of points up to the board views' corners), not term by term.
  double worst = 0.0;
  for (double x = -0.35; x <= 0.35; x += 0.05) {
    for (double y = -0.3; y <= 0.3; y += 0.05) {
      const double p[3] = {x, y, 1.0};
      double want[2], got[2];
      ProjectPoint(s.truth.intrinsics.data(), p, want);
      ProjectPoint(r.state.intrinsics.data(), p, got);
      worst = std::max(worst, std::hypot(got[0] - want[0], got[1] - want[1]));
    }
  }
  EXPECT_LT(worst, 0.01);
  EXPECT_LT((r.state.laser_plane - s.truth.laser_plane).cwiseAbs().maxCoeff(), 1e-4);
}

// The corner costs of a five-term lens (classic_lens: k4 to tauy held at 0 and not read) against
// those of the whole lens: the same residuals and derivatives, bit for bit, but for the held
// terms' columns, which are 0.
TEST(GeneralModel, CornerCostsOfAFiveTermLensMatchTheFullAutodiff) {
  const Scene s = MakeScene(2);
  const JointView& v = s.views[0];
  const PoseBlocks hc(s.truth.hand_from_camera), bb(s.truth.base_from_board);
  const PoseBlocks cb(s.truth.hand_from_camera.inverse() * v.base_from_hand.inverse() *
                      s.truth.base_from_board);
  const int n = 2 * static_cast<int>(v.corner_pixels.rows());
  for (bool chain : {true, false}) {
    std::unique_ptr<ceres::CostFunction> held(chain ? NewChainCornerCost(&v, 10.0, true)
                                                    : NewFreeCornerCost(&v, 10.0, true));
    std::unique_ptr<ceres::CostFunction> full(chain ? NewChainCornerCost(&v, 10.0, false)
                                                    : NewFreeCornerCost(&v, 10.0, false));
    std::vector<const double*> blocks = {s.truth.intrinsics.data(), hc.q.data(), hc.t.data(),
                                         bb.q.data(), bb.t.data()};
    if (!chain) blocks = {s.truth.intrinsics.data(), cb.q.data(), cb.t.data()};
    const std::vector<int> sizes = chain ? std::vector<int>{kNumIntrinsics, 4, 3, 4, 3}
                                         : std::vector<int>{kNumIntrinsics, 4, 3};
    std::vector<std::vector<double>> ja, jb;
    std::vector<double*> pa, pb;
    for (int size : sizes) {
      ja.emplace_back(static_cast<std::size_t>(n * size));
      jb.emplace_back(static_cast<std::size_t>(n * size));
    }
    for (std::size_t b = 0; b < sizes.size(); ++b) {
      pa.push_back(ja[b].data());
      pb.push_back(jb[b].data());
    }
    std::vector<double> ra(static_cast<std::size_t>(n)), rb(static_cast<std::size_t>(n));
    ASSERT_TRUE(held->Evaluate(blocks.data(), ra.data(), pa.data()));
    ASSERT_TRUE(full->Evaluate(blocks.data(), rb.data(), pb.data()));
    EXPECT_EQ(ra, rb);
    for (std::size_t b = 0; b < sizes.size(); ++b) {
      for (int i = 0; i < n; ++i) {
        for (int k = 0; k < sizes[b]; ++k) {
          const double want =
              (b == 0 && k >= kNumClassicIntrinsics) ? 0.0 : jb[b][i * sizes[b] + k];
          ASSERT_EQ(ja[b][i * sizes[b] + k], want) << "block " << b << " row " << i << " col " << k;
        }
      }
    }
  }
}

TEST(GeneralModel, CameraModeJacobianMatchesCentralDifferences) {
  Scene s = MakeScene(5);
  s.views.resize(3);
  JointState at = s.truth;
  for (auto& v : s.views) {
    at.camera_from_board.push_back(s.truth.hand_from_camera.inverse() * v.base_from_hand.inverse() *
                                   s.truth.base_from_board);
    v.base_from_hand.setIdentity();
  }
  at.intrinsics[kK2] += 0.02;
  at.camera_from_board[1] = RotateLeft(at.camera_from_board[1], 1, 0.01);
  at.laser_plane[3] += 1.0;
  JointOptions o;
  o.chain = false;
  std::vector<std::string> names;
  const Eigen::MatrixXd j = JointJacobian(s.views, at, o, &names);
  ASSERT_EQ(j.cols(), 9 + 3 * 6 + 3);
  auto numeric = [&](auto perturb, double h) {
    JointState plus = at, minus = at;
    perturb(&plus, h);
    perturb(&minus, -h);
    // the stripe's residual as the solver's cost holds it: scale-free, its factors from `at`
    return Eigen::VectorXd((Stacked(s.views, plus, o, &at) - Stacked(s.views, minus, o, &at)) /
                           (2 * h));
  };
  auto expect_column = [&](int col, const Eigen::VectorXd& d) {
    const double scale = std::max(1.0, d.cwiseAbs().maxCoeff());
    EXPECT_LT((j.col(col) - d).cwiseAbs().maxCoeff() / scale, 1e-5) << names[col];
  };
  // At its own start the scale-free residual reads as the mm distance.
  const Eigen::VectorXd mm = Stacked(s.views, at, o), scaled = Stacked(s.views, at, o, &at);
  EXPECT_LT((mm - scaled).cwiseAbs().maxCoeff(), 1e-9 * std::max(1.0, mm.cwiseAbs().maxCoeff()));
  for (int k = 0; k < kNumIntrinsics; ++k) {
    if (o.fixed[k]) continue;
    expect_column(
        k, numeric([k](JointState* st, double e) { st->intrinsics[k] += e; }, k < 4 ? 1e-3 : 1e-6));
  }
  for (int view = 0; view < 3; ++view) {
    for (int axis = 0; axis < 3; ++axis) {
      expect_column(9 + 6 * view + axis, numeric(
                                             [=](JointState* st, double e) {
                                               st->camera_from_board[view] =
                                                   RotateLeft(st->camera_from_board[view], axis, e);
                                             },
                                             1e-6));
      expect_column(
          12 + 6 * view + axis,
          numeric([=](JointState* st, double e) { st->camera_from_board[view](axis, 3) += e; },
                  1e-4));
    }
  }
  expect_column(29, numeric([](JointState* st, double e) { st->laser_plane[3] += e; }, 1e-4));
}

TEST(GeneralModel, HandEyeIsExactOnExactPoses) {
  const Scene s = MakeScene(3);
  std::vector<Eigen::Matrix4d> bfh, cfb;
  for (const auto& v : s.views) {
    bfh.push_back(v.base_from_hand);
    cfb.push_back(s.truth.hand_from_camera.inverse() * v.base_from_hand.inverse() *
                  s.truth.base_from_board);
  }
  const Eigen::Matrix4d x = HandEyeParkMartin(bfh, cfb);
  EXPECT_LT((x - s.truth.hand_from_camera).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(GeneralModel, HandEyeRefusesRotationsAboutOneAxis) {
  const Eigen::Matrix4d hfc = Transform({0.1, 0.2, 1.5}, {50, 0, -40});
  const Eigen::Matrix4d bfb = Transform({0, 0, 0.3}, {700, 0, 0});
  std::vector<Eigen::Matrix4d> bfh, cfb;
  for (int i = 0; i < 6; ++i) {
    const Eigen::Matrix4d h = Transform({0, 0, 0.2 * i}, {600, 10.0 * i, 400});
    bfh.push_back(h);
    cfb.push_back(hfc.inverse() * h.inverse() * bfb);
  }
  EXPECT_THROW(HandEyeParkMartin(bfh, cfb), std::invalid_argument);
}

TEST(GeneralModel, JointSolveRecoversTheTruthOnExactData) {
  const Scene s = MakeScene(4);
  JointState start = s.truth;
  start.intrinsics[kFx] *= 1.02;
  start.intrinsics[kFy] *= 0.98;
  start.intrinsics[kCx] += 6;
  start.intrinsics[kK1] = -0.1;
  start.intrinsics[kK3] = 0.0;
  start.hand_from_camera = RotateLeft(start.hand_from_camera, 2, 0.03);
  start.hand_from_camera(0, 3) += 3;
  start.base_from_board = RotateLeft(start.base_from_board, 1, -0.02);
  start.laser_plane.head<3>() =
      (start.laser_plane.head<3>() + Eigen::Vector3d(0.02, 0, -0.01)).normalized();
  start.laser_plane[3] += 5;
  JointOptions o;
  const JointResult r = SolveJoint(s.views, start, o);
  EXPECT_EQ(r.termination, "CONVERGENCE");
  EXPECT_LT((r.state.intrinsics - s.truth.intrinsics).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((r.state.hand_from_camera - s.truth.hand_from_camera).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((r.state.base_from_board - s.truth.base_from_board).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((r.state.laser_plane - s.truth.laser_plane).cwiseAbs().maxCoeff(), 1e-8);
}

}  // namespace
}  // namespace hmlvs::opencv
