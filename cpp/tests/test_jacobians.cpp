// Every Jacobian the solvers use, against central differences: the residual Jacobian of the
// identifiability/uncertainty analyses (autodiff) and the three LM residual blocks (autodiff on
// the quaternion manifold, autodiff over Euler angles, the paper mode's forward differences).
// Not ceres::GradientChecker (Ceres 2.1): its Ridders differences take the relative initial step
// (default 1e-2) also as an absolute minimum step, which moves Su = 0.0074 mm/px off the model's
// domain; with a smaller setting they returned a wrong derivative for one paper-mode entry
// (-6802 where central differences at steps 1e-4 to 1e-10 agree on -25732); and it judges
// entries that are analytically 0 (three on the quaternion's tangent space) by relative error
// alone.
#include <ceres/manifold.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "hmlvs/model/paper.h"
#include "hmlvs/model/paper_cost.h"
#include "hmlvs/model/paper_fitness.h"
#include "hmlvs/solvers/lm_costs.h"
#include "hmlvs/solvers/point_lm.h"
#include "test_util.h"

namespace hmlvs {
namespace {

using namespace hmlvs::paper;
using namespace hmlvs::solvers;

using test::Generic;
using test::MakeScene;

// A scene whose reference points are off the model's by ~1 mm, so that no residual (and no
// ||E||, whose gradient is undefined at 0) vanishes.
struct OffsetScene {
  test::Scene scene;
  RowMatX3 references;
};

OffsetScene MakeOffsetScene(const Vector14d& q, int m) {
  OffsetScene s{MakeScene(q, m, 21), RowMatX3()};
  s.references = s.scene.points;
  for (Eigen::Index i = 0; i < m; ++i) {
    s.references.row(i) += Eigen::RowVector3d(std::sin(i), std::cos(2.0 * i), 0.7);
  }
  return s;
}

Eigen::Vector3d ReferenceInHand(const OffsetScene& s, Eigen::Index i) {
  return geometry::PoseRotation(s.scene.poses, i).transpose() *
         (s.references.row(i).transpose() - geometry::PosePosition(s.scene.poses, i));
}

// One residual block per point of the scene, made by `make(u, v, reference_in_hand)`.
template <typename Make>
std::vector<ceres::CostFunction*> CostsOf(const OffsetScene& s, Eigen::Index n, Make make) {
  std::vector<ceres::CostFunction*> costs;
  for (Eigen::Index i = 0; i < n; ++i) {
    costs.push_back(make(s.scene.pixels(i, 0), s.scene.pixels(i, 1), ReferenceInHand(s, i)));
  }
  return costs;
}

TEST(Jacobians, ResidualJacobianMatchesCentralDifferences) {
  const Vector14d q = Generic();
  const OffsetScene s = MakeOffsetScene(q, 25);
  Eigen::VectorXd r;
  Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor> jac;
  ResidualJacobian(q, s.scene.pixels, s.scene.poses, s.references, &r, &jac);
  ASSERT_EQ(r.size(), 75);
  ASSERT_EQ(jac.rows(), 75);

  // The residuals are those of the batch function, flattened row by row.
  const RowMatX3 e = Residuals(q, s.scene.pixels, s.scene.poses, s.references);
  for (Eigen::Index i = 0; i < 25; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(r[3 * i + c], e(i, c), 1e-10);

  // Central differences of Residuals with a step of 1e-5 of each parameter's scale. Truncation
  // error is ~(step / scale)^2 = 1e-10 of the derivative, rounding ~1e-16 |E| / step with
  // |E| < 2000 mm; measured at most 2.1e-9 relative to the column's largest entry, 1e-6 allowed.
  // A wrong derivative (e.g. a missed chain-rule factor) is off by O(1) of that scale.
  Vector14d scale = q.cwiseAbs();
  for (int j : {kK, kOmega, kPhi, kVarphi, kTy}) scale[j] = std::max(scale[j], 0.1);
  for (int j = 0; j < kNumParams; ++j) {
    const double h = 1e-5 * scale[j];
    Vector14d qp = q, qm = q;
    qp[j] += h;
    qm[j] -= h;
    const RowMatX3 ep = Residuals(qp, s.scene.pixels, s.scene.poses, s.references);
    const RowMatX3 em = Residuals(qm, s.scene.pixels, s.scene.poses, s.references);
    const Eigen::Map<const Eigen::VectorXd> fp(ep.data(), 75), fm(em.data(), 75);
    const Eigen::VectorXd numeric = (fp - fm) / (2.0 * h);
    const double column_max = jac.col(j).cwiseAbs().maxCoeff();
    EXPECT_GT(column_max, 0.0) << ParamNames()[j];
    EXPECT_LT((numeric - jac.col(j)).cwiseAbs().maxCoeff(), 1e-6 * column_max) << ParamNames()[j];
  }
}

// Jacobians of one LM residual block per calibration point, stacked (rows: points x residuals;
// columns: the tangent-space coordinates of all parameter blocks).
struct StackedJacobians {
  Eigen::MatrixXd analytic;  // from CostFunction::Evaluate (times PlusJacobian on a manifold)
  Eigen::MatrixXd numeric;   // central differences along the manifold's Plus
};

// Central differences (f(x [+] h e_j) - f(x [+] -h e_j)) / 2h in each block's tangent space,
// with h = 1e-5 max(|x_j|, 1e-3) for a scalar block and 1e-5 rad on the quaternion manifold.
// Truncation error ~(h / scale)^2 = 1e-10 of the derivative; rounding ~1e-16 |f| / h < 1e-7
// with |f| of a few mm.
StackedJacobians Differentiate(const std::vector<ceres::CostFunction*>& costs,
                               const std::vector<std::vector<double>>& blocks,
                               const std::vector<const ceres::Manifold*>& manifolds) {
  const int n_blocks = static_cast<int>(blocks.size());
  int n_tangent = 0;
  for (int k = 0; k < n_blocks; ++k) {
    n_tangent += manifolds[k] ? manifolds[k]->TangentSize() : static_cast<int>(blocks[k].size());
  }
  const int n_res = costs.front()->num_residuals();
  StackedJacobians out{Eigen::MatrixXd(n_res * costs.size(), n_tangent),
                       Eigen::MatrixXd(n_res * costs.size(), n_tangent)};
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  for (std::size_t c = 0; c < costs.size(); ++c) {
    std::unique_ptr<ceres::CostFunction> cost(costs[c]);
    auto evaluate = [&](const std::vector<std::vector<double>>& x, double* residuals,
                        std::vector<RowMatrix>* jacobians) {
      std::vector<const double*> ptrs;
      for (const auto& b : x) ptrs.push_back(b.data());
      std::vector<double*> jac_ptrs;
      if (jacobians) {
        jacobians->clear();
        for (const auto& b : x) jacobians->emplace_back(n_res, static_cast<int>(b.size()));
        for (auto& j : *jacobians) jac_ptrs.push_back(j.data());
      }
      EXPECT_TRUE(cost->Evaluate(ptrs.data(), residuals, jacobians ? jac_ptrs.data() : nullptr));
    };
    std::vector<double> r0(n_res), rp(n_res), rm(n_res);
    std::vector<RowMatrix> ambient;
    evaluate(blocks, r0.data(), &ambient);
    int col = 0;
    for (int k = 0; k < n_blocks; ++k) {
      const int size = static_cast<int>(blocks[k].size());
      const ceres::Manifold* m = manifolds[k];
      const int tangent = m ? m->TangentSize() : size;
      RowMatrix plus_jacobian = RowMatrix::Identity(size, tangent);
      if (m) m->PlusJacobian(blocks[k].data(), plus_jacobian.data());
      out.analytic.block(n_res * c, col, n_res, tangent) = ambient[k] * plus_jacobian;
      for (int j = 0; j < tangent; ++j) {
        const double h = m ? 1e-5 : 1e-5 * std::max(std::abs(blocks[k][j]), 1e-3);
        std::vector<std::vector<double>> xp = blocks, xm = blocks;
        if (m) {
          std::vector<double> delta(tangent, 0.0);
          delta[j] = h;
          m->Plus(blocks[k].data(), delta.data(), xp[k].data());
          delta[j] = -h;
          m->Plus(blocks[k].data(), delta.data(), xm[k].data());
        } else {
          xp[k][j] += h;
          xm[k][j] -= h;
        }
        evaluate(xp, rp.data(), nullptr);
        evaluate(xm, rm.data(), nullptr);
        for (int i = 0; i < n_res; ++i)
          out.numeric(n_res * c + i, col + j) = (rp[i] - rm[i]) / (2 * h);
      }
      col += tangent;
    }
  }
  return out;
}

// Largest error of each column relative to the column's largest analytic entry (over all
// points), so that entries that are analytically 0 are judged on the column's scale.
double WorstColumnError(const StackedJacobians& j) {
  double worst = 0.0;
  for (Eigen::Index c = 0; c < j.analytic.cols(); ++c) {
    const double scale = j.analytic.col(c).cwiseAbs().maxCoeff();
    EXPECT_GT(scale, 0.0) << "column " << c << " is identically zero";
    worst = std::max(worst, (j.numeric.col(c) - j.analytic.col(c)).cwiseAbs().maxCoeff() / scale);
  }
  return worst;
}

std::vector<std::vector<double>> ScalarBlocks(const Vector14d& q) {
  std::vector<std::vector<double>> blocks;
  for (int j = 0; j < kNumParams; ++j) blocks.push_back({q[j]});
  return blocks;
}

TEST(Jacobians, ModernQuaternionCostOnItsManifold) {
  const Vector14d q = Generic();
  const OffsetScene s = MakeOffsetScene(q, 12);
  const Eigen::Quaterniond rot(geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]));
  const std::vector<std::vector<double>> blocks = {
      std::vector<double>(q.data() + kF, q.data() + kTheta + 1),
      {rot.x(), rot.y(), rot.z(), rot.w()},
      std::vector<double>(q.data() + kTx, q.data() + kTz + 1)};
  ceres::EigenQuaternionManifold quaternion;
  const std::vector<const ceres::Manifold*> manifolds = {nullptr, &quaternion, nullptr};
  const std::vector<ceres::CostFunction*> costs = CostsOf(s, 12, NewModernQuaternionCost);
  const StackedJacobians j = Differentiate(costs, blocks, manifolds);
  ASSERT_EQ(j.analytic.cols(), 14);  // 8 + 3 (tangent of the quaternion) + 3
  // The analytic Jacobian is exact to rounding and the differences good to ~1e-9 (above);
  // measured 1.4e-9 (with autodiff, which the analytic one replaced). A wrong derivative is off
  // by O(1).
  EXPECT_LT(WorstColumnError(j), 1e-6);
}

TEST(Jacobians, PointCostOfThePaperModel) {
  const Vector14d q = Generic();
  const OffsetScene s = MakeOffsetScene(q, 12);
  // The point problem (point_lm.h) on the paper model: RunLm's modern mode with an Euler angle
  // held.
  const std::vector<ceres::CostFunction*> costs = CostsOf(s, 12, NewPointCost<Model>);
  const StackedJacobians j =
      Differentiate(costs, ScalarBlocks(q), std::vector<const ceres::Manifold*>(14, nullptr));
  EXPECT_LT(WorstColumnError(j), 1e-6);  // as above
}

TEST(Jacobians, PaperCostForwardDifferences) {
  const Vector14d q = Generic();
  const OffsetScene s = MakeOffsetScene(q, 12);
  PaperTrigCache cache;  // as RunLm uses them: one cache shared by the points
  const std::vector<ceres::CostFunction*> costs =
      CostsOf(s, 12, [&cache](double u, double v, const Eigen::Vector3d& h) {
        return NewPaperCost(u, v, h, &cache);
      });
  const StackedJacobians j =
      Differentiate(costs, {std::vector<double>(q.data(), q.data() + kNumParams)}, {nullptr});
  // The paper mode's own Jacobian is a forward difference (Ceres: step 1e-6 |x|, at least
  // 1.5e-8), whose truncation error h f'' / 2 is largest where ||E|| (~1 mm) bends most:
  // measured 2.9e-4 of the column scale. 2e-3 bounds it; a wrong derivative is off by O(1).
  const double worst = WorstColumnError(j);
  EXPECT_LT(worst, 2e-3);
  EXPECT_GT(worst, 1e-9);  // it is a finite difference, not an exact derivative
}

TEST(Jacobians, PaperFastCostMatchesNumericDiffBitForBit) {
  // The paper mode's fast cost (NewPaperCost with a cache) against Ceres' NumericDiff over the
  // plain residual: residual and all 14 Jacobian columns the same to the last bit, at vectors
  // visited in an interleaved order (as an LM does with its trial steps), with and without a
  // Jacobian asked for.
  const Vector14d q0 = Generic();
  const OffsetScene s = MakeOffsetScene(q0, 12);
  PaperTrigCache cache;
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-0.02, 0.02);
  std::vector<Vector14d> vectors;
  for (int k = 0; k < 6; ++k) {
    Vector14d q = q0;
    for (int j = 0; j < kNumParams; ++j) q[j] = q0[j] * (1.0 + u(rng)) + 0.1 * u(rng);
    vectors.push_back(q);
  }
  int compared = 0;
  for (int pass = 0; pass < 2; ++pass) {
    for (Eigen::Index i = 0; i < 12; ++i) {
      const Eigen::Vector3d h = ReferenceInHand(s, i);
      const std::unique_ptr<ceres::CostFunction> fast(
          NewPaperCost(s.scene.pixels(i, 0), s.scene.pixels(i, 1), h, &cache));
      const std::unique_ptr<ceres::CostFunction> reference(
          NewPaperCost(s.scene.pixels(i, 0), s.scene.pixels(i, 1), h));
      for (std::size_t k = 0; k < vectors.size(); ++k) {
        const Vector14d& q = vectors[(k + i + pass) % vectors.size()];
        const double* params[] = {q.data()};
        double rf = 0, rr = 0, jf[kNumParams], jr[kNumParams];
        double* jfp[] = {jf};
        double* jrp[] = {jr};
        const bool with_jacobian = (k + pass) % 3 != 0;
        const bool ok_f = fast->Evaluate(params, &rf, with_jacobian ? jfp : nullptr);
        const bool ok_r = reference->Evaluate(params, &rr, with_jacobian ? jrp : nullptr);
        ASSERT_EQ(ok_f, ok_r);
        if (!ok_f) continue;
        EXPECT_EQ(std::memcmp(&rf, &rr, sizeof(double)), 0);
        if (with_jacobian) {
          EXPECT_EQ(std::memcmp(jf, jr, sizeof(jf)), 0) << "point " << i << ", vector " << k;
          ++compared;
        }
      }
    }
  }
  EXPECT_GT(compared, 50);
}

TEST(Jacobians, ModernBatchCostStacksThePointCostsBitForBit) {
  // The modern LM without a robust loss puts all points in one residual block: its residuals
  // and Jacobian rows must be the per-point blocks' (checked against central differences
  // above), stacked in point order, to the last bit.
  const Vector14d q = Generic();
  const OffsetScene s = MakeOffsetScene(q, 12);
  const FitnessData data(s.scene.pixels, s.scene.poses, s.references);
  const Eigen::Quaterniond rot(geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]));
  const double quat[4] = {rot.x(), rot.y(), rot.z(), rot.w()};
  const double* params[] = {q.data() + kF, quat, q.data() + kTx};
  const std::unique_ptr<ceres::CostFunction> batch(NewModernBatchCost(data));
  ASSERT_EQ(batch->num_residuals(), 36);
  std::vector<double> r(36), j0(36 * 8), j1(36 * 4), j2(36 * 3);
  double* jac[] = {j0.data(), j1.data(), j2.data()};
  ASSERT_TRUE(batch->Evaluate(params, r.data(), jac));
  for (Eigen::Index i = 0; i < 12; ++i) {
    const std::unique_ptr<ceres::CostFunction> point(
        NewModernQuaternionCost(data.u(i), data.v(i), data.ReferenceInHand(i)));
    double ri[3], a[24], b[12], c[9];
    double* ji[] = {a, b, c};
    ASSERT_TRUE(point->Evaluate(params, ri, ji));
    EXPECT_EQ(std::memcmp(ri, r.data() + 3 * i, sizeof(ri)), 0) << "point " << i;
    EXPECT_EQ(std::memcmp(a, j0.data() + 24 * i, sizeof(a)), 0) << "point " << i;
    EXPECT_EQ(std::memcmp(b, j1.data() + 12 * i, sizeof(b)), 0) << "point " << i;
    EXPECT_EQ(std::memcmp(c, j2.data() + 9 * i, sizeof(c)), 0) << "point " << i;
  }
}

TEST(Jacobians, ModernBatchCostPackedBlocksAreTheFreeColumns) {
  // With parameters held, the batch cost's intrinsics and translation blocks hold the free ones
  // only: its residuals and Jacobian columns must be the full cost's (the columns a SubsetManifold
  // would keep), to the last bit, and the held values those of `held`.
  const Vector14d q = Generic();
  const OffsetScene s = MakeOffsetScene(q, 12);
  const FitnessData data(s.scene.pixels, s.scene.poses, s.references);
  const Eigen::Quaterniond rot(geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]));
  const double quat[4] = {rot.x(), rot.y(), rot.z(), rot.w()};
  std::array<bool, kNumParams> held{};
  held[kSu] = held[kK] = held[kTy] = true;
  const std::vector<int> free0 = {0, 2, 3, 4, 6, 7}, free2 = {0, 2};  // within each group
  std::vector<double> x0, x2;
  for (int i : free0) x0.push_back(q[kF + i]);
  for (int i : free2) x2.push_back(q[kTx + i]);
  const double* full_params[] = {q.data() + kF, quat, q.data() + kTx};
  const double* packed_params[] = {x0.data(), quat, x2.data()};
  const std::unique_ptr<ceres::CostFunction> full(NewModernBatchCost(data));
  const std::unique_ptr<ceres::CostFunction> packed(NewModernBatchCost(data, q, held));
  ASSERT_EQ(packed->parameter_block_sizes(), (std::vector<int32_t>{6, 4, 2}));
  const int rows = 36;
  std::vector<double> r(rows), j0(rows * 8), j1(rows * 4), j2(rows * 3);
  std::vector<double> pr(rows), p0(rows * 6), p1(rows * 4), p2(rows * 2);
  double* jac[] = {j0.data(), j1.data(), j2.data()};
  double* pjac[] = {p0.data(), p1.data(), p2.data()};
  ASSERT_TRUE(full->Evaluate(full_params, r.data(), jac));
  for (int pass = 0; pass < 2; ++pass) {  // the second evaluation is the kept one
    ASSERT_TRUE(packed->Evaluate(packed_params, pr.data(), pjac));
    EXPECT_EQ(std::memcmp(r.data(), pr.data(), rows * sizeof(double)), 0);
    EXPECT_EQ(std::memcmp(j1.data(), p1.data(), rows * 4 * sizeof(double)), 0);
    for (int row = 0; row < rows; ++row) {
      for (std::size_t c = 0; c < free0.size(); ++c) {
        EXPECT_EQ(std::memcmp(&j0[8 * row + free0[c]], &p0[6 * row + c], sizeof(double)), 0);
      }
      for (std::size_t c = 0; c < free2.size(); ++c) {
        EXPECT_EQ(std::memcmp(&j2[3 * row + free2[c]], &p2[2 * row + c], sizeof(double)), 0);
      }
    }
    std::fill(pr.begin(), pr.end(), 0.0);
    std::fill(p0.begin(), p0.end(), 0.0);
  }
  // Residuals alone at the same point, then at another: the kept evaluation only where it is one.
  ASSERT_TRUE(packed->Evaluate(packed_params, pr.data(), nullptr));
  EXPECT_EQ(std::memcmp(r.data(), pr.data(), rows * sizeof(double)), 0);
  x0[0] += 0.01;
  ASSERT_TRUE(packed->Evaluate(packed_params, pr.data(), nullptr));
  EXPECT_NE(std::memcmp(r.data(), pr.data(), rows * sizeof(double)), 0);
}

}  // namespace
}  // namespace hmlvs
