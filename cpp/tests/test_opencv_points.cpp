// The general model (model "opencv", 18 parameters) from calibration points: its point
// objective (opencv_fitness.h) is zero at the truth; PSO and random search over it are
// deterministic for a seed whatever the thread count, as on the paper model (test_solvers.cpp);
// the point problem (point_lm.h) on it has the Jacobian of central differences and its LM
// reaches a zero cost from a perturbed start.
#include <ceres/cost_function.h>
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "hmlvs/geometry/geometry.h"
#include "hmlvs/model/opencv.h"
#include "hmlvs/model/opencv_fitness.h"
#include "hmlvs/solvers/point_lm.h"
#include "hmlvs/solvers/search.h"
#include "test_util.h"

namespace hmlvs::opencv {
namespace {

using solvers::PsoOptions;
using solvers::PsoResult;
using solvers::RandomSearchOptions;
using solvers::RandomSearchResult;
using test::BitIdentical;
constexpr int N = kNumPointParams;

// Intrinsics with distortion, a laser plane tilted off the paper's two degrees of freedom
// (alpha != 0) and a generic hand-eye transform.
Vector18d Truth() {
  IntrinsicsVector in = IntrinsicsVector::Zero();
  in.head<kNumClassicIntrinsics>() << 1100, 1090, 512, 384, -0.165, 0.05, 0.0005, -0.0003, 0.01;
  const double w[3] = {0.02, -0.03, 1.6};  // rotation vector (rad)
  const Eigen::Matrix4d hfc =
      geometry::Transform(geometry::Rodrigues(w), Eigen::Vector3d(60.0, 5.0, -45.0));
  return PointParams(in, PlaneFromAngles(0.03, 0.45, 90.0), hfc);
}

// A 1024 x 768 camera's stripe pixels (its lower part, where the rays meet the laser plane) at
// random robot poses, and their exact base-frame points under x.
test::Scene MakeScene(const Vector18d& x, int m, unsigned seed) {
  test::Scene s = test::RandomPixelsAndPoses(m, seed, 1023.0, 300.0, 767.0);
  const Eigen::Matrix4d hfc = geometry::Transform(geometry::Rodrigues(x.data() + kRotationAt),
                                                  x.segment<3>(kTranslationAt));
  IntrinsicsVector in = IntrinsicsVector::Zero();
  in.head<kNumClassicIntrinsics>() = x.head<kNumClassicIntrinsics>();
  const Eigen::Vector4d plane = PlaneFromAngles(x[kPlaneAt], x[kPlaneAt + 1], x[kPlaneAt + 2]);
  s.points = LaserPointsInBase(in, plane, hfc, s.pixels, s.poses, /*throw_on_invalid=*/true).points;
  return s;
}

// Bounds around the truth: +-2 % of each value, at least +-0.01.
void Box(const Vector18d& x, Vector18d* lower, Vector18d* upper) {
  const Vector18d half = (0.02 * x.cwiseAbs()).cwiseMax(0.01);
  *lower = x - half;
  *upper = x + half;
}

// 40 calibration points and their objective.
class OpencvSearch : public ::testing::Test {
 protected:
  const test::Scene scene_ = MakeScene(Truth(), 40, 2);
  const PointFitness fitness_{scene_.pixels, scene_.poses, scene_.points};
};

TEST_F(OpencvSearch, PointObjectiveIsZeroAtTheTruth) {
  const Vector18d x = Truth();
  EXPECT_NEAR(x[kPlaneAt], 0.03, 1e-15);
  EXPECT_NEAR(x[kPlaneAt + 1], 0.45, 1e-15);
  EXPECT_NEAR(x[kPlaneAt + 2], 90.0, 1e-12);
  const PointFitness& fitness = fitness_;
  EXPECT_EQ(fitness.size(), 40);
  EXPECT_LT(fitness.Evaluate(x.data()), 1e-18);  // mm^2: rounding only
  Vector18d off = x;
  off[kFx] *= 1.01;
  EXPECT_GT(fitness.Evaluate(off.data()), 1.0);
  off = x;
  off[kPlaneAt + 1] = -1.4;  // the plane turned away: the rays meet it behind the camera
  EXPECT_EQ(fitness.Evaluate(off.data()), std::numeric_limits<double>::infinity());
  EXPECT_EQ(fitness.ParameterName(kPlaneAt), "plane_alpha");
}

TEST_F(OpencvSearch, PsoSameSeedSameResultForAnyThreadCount) {
  const PointFitness& fitness = fitness_;
  PsoOptions<N> o;
  Box(Truth(), &o.lower, &o.upper);
  o.swarm_size = 16;
  o.iterations = 60;
  o.seed = 5;
  for (int runs : {1, 3}) {
    o.runs = runs;
    o.threads = 1;
    const PsoResult<N> reference = solvers::RunPso(fitness, o);
    ASSERT_EQ(static_cast<int>(reference.runs.size()), runs);
    for (const auto& run : reference.runs) {
      ASSERT_EQ(run.history.size(), 60u);
      EXPECT_LT(run.history.back(), run.history.front());
      EXPECT_EQ(run.best_fitness, fitness.Evaluate(run.best.data()));
    }
    for (int threads : {2, 3}) {
      o.threads = threads;
      const PsoResult<N> other = solvers::RunPso(fitness, o);
      EXPECT_EQ(other.best_run, reference.best_run);
      for (int r = 0; r < runs; ++r) {
        EXPECT_TRUE(BitIdentical(other.runs[r].best, reference.runs[r].best))
            << runs << " runs, " << threads << " threads, run " << r;
        EXPECT_EQ(other.runs[r].history, reference.runs[r].history);
      }
    }
  }
  // Bounds are checked with the model's parameter names.
  o.lower[kPlaneAt + 2] = o.upper[kPlaneAt + 2] + 1.0;
  try {
    solvers::RunPso(fitness, o);
    ADD_FAILURE() << "reversed bounds accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("plane_h"), std::string::npos) << e.what();
  }
}

TEST_F(OpencvSearch, RandomSearchSameSeedSameResultForAnyThreadCount) {
  RandomSearchOptions<N> o;
  Box(Truth(), &o.lower, &o.upper);
  o.evaluations = 3000;
  o.seed = 9;
  o.threads = 1;
  const RandomSearchResult<N> reference = solvers::RunRandomSearch(fitness_, o);
  EXPECT_EQ(reference.evaluations, 3000);
  EXPECT_EQ(reference.best_fitness, fitness_.Evaluate(reference.best.data()));
  for (int threads : {2, 3}) {
    o.threads = threads;
    const RandomSearchResult<N> other = solvers::RunRandomSearch(fitness_, o);
    EXPECT_TRUE(BitIdentical(other.best, reference.best)) << threads << " threads";
    EXPECT_EQ(other.best_index, reference.best_index);
  }
}

TEST_F(OpencvSearch, PointCostMatchesCentralDifferences) {
  Vector18d x = Truth();
  x[kK1] += 0.01;  // off the truth: residuals not zero
  x[kPlaneAt + 2] += 1.0;
  const CalibrationPoints& p = fitness_.points();
  for (Eigen::Index i = 0; i < 5; ++i) {
    const std::unique_ptr<ceres::CostFunction> cost(
        solvers::NewPointCost<Model>(p.u[i], p.v[i], p.ReferenceInHand(i)));
    std::vector<const double*> blocks;
    for (int k = 0; k < N; ++k) blocks.push_back(&x[k]);
    double e[3], jac[N][3];
    double* jacobians[N];
    for (int k = 0; k < N; ++k) jacobians[k] = jac[k];
    ASSERT_TRUE(cost->Evaluate(blocks.data(), e, jacobians));
    for (int k = 0; k < N; ++k) {
      // central differences, step relative to the parameter's size
      const double step = 1e-6 * std::max(1.0, std::abs(x[k]));
      Vector18d xp = x, xm = x;
      xp[k] += step;
      xm[k] -= step;
      double ep[3], em[3];
      const double h[3] = {p.hx[i], p.hy[i], p.hz[i]};
      ASSERT_TRUE(Model::Residual(xp.data(), p.u[i], p.v[i], h, ep));
      ASSERT_TRUE(Model::Residual(xm.data(), p.u[i], p.v[i], h, em));
      for (int r = 0; r < 3; ++r) {
        const double numeric = (ep[r] - em[r]) / (2.0 * step);
        EXPECT_NEAR(jac[k][r], numeric, 1e-5 * std::max(1.0, std::abs(numeric)))
            << "point " << i << ", " << PointParamNames()[k] << ", residual " << r;
      }
    }
  }
}

TEST_F(OpencvSearch, PointLmFromAPerturbedStartReachesZeroCost) {
  const Vector18d truth = Truth();
  Vector18d start = truth;
  for (int k = 0; k < N; ++k)
    start[k] += 1e-3 * std::max(1.0, std::abs(truth[k])) * ((k % 3) - 1.0);
  solvers::PointLmOptions<N> o;
  start[kK3] = truth[kK3];
  o.fixed[kK3] = true;  // held: stays at its value
  const solvers::PointLmResult<N> r = solvers::RunPointLm<Model>(fitness_.points(), start, o);
  EXPECT_EQ(r.params[kK3], truth[kK3]);
  EXPECT_TRUE(r.usable) << r.message;
  EXPECT_GT(r.initial_cost, 1.0);
  EXPECT_EQ(r.initial_cost, fitness_.Evaluate(start.data()));
  EXPECT_EQ(r.final_cost, fitness_.Evaluate(r.params.data()));
  EXPECT_LT(r.final_cost, 1e-12) << r.message;  // mm^2, noise-free points
  // A start whose rays miss the plane is refused, naming the point.
  start[kPlaneAt + 1] = -1.4;
  EXPECT_THROW(solvers::RunPointLm<Model>(fitness_.points(), start, o), std::invalid_argument);
}

}  // namespace
}  // namespace hmlvs::opencv
