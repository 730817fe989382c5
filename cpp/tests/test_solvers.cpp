// Solvers on synthetic data with known parameters: PSO and random search are deterministic for a
// seed whatever the thread count, and LM from a slightly perturbed truth reaches a zero cost.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "hmlvs/model/paper.h"
#include "hmlvs/model/paper_fitness.h"
#include "hmlvs/solvers/lm.h"
#include "hmlvs/solvers/random.h"
#include "hmlvs/solvers/search.h"
#include "test_util.h"

namespace hmlvs {
namespace {

using namespace hmlvs::paper;
using namespace hmlvs::solvers;

using test::BitIdentical;
using test::Generic;
using test::MakeScene;
using test::PerturbedTruth;

PsoOptions<kNumParams> SmallPso(int runs, int threads) {
  PsoOptions<kNumParams> o;
  test::Table2Bounds(&o.lower, &o.upper);
  o.swarm_size = 20;
  o.iterations = 150;
  o.runs = runs;
  o.threads = threads;
  o.seed = 11;
  return o;
}

TEST(Solvers, PsoSameSeedSameResultForAnyThreadCount) {
  const test::Scene s = MakeScene(Generic(), 50, 1);
  const FitnessData data(s.pixels, s.poses, s.points);
  // runs = 1: the particles of one swarm are shared among the threads; runs = 3: whole runs are
  // spread over the threads. Both must not depend on the thread count, to the last bit.
  for (int runs : {1, 3}) {
    const PsoResult<kNumParams> reference = RunPso(data, SmallPso(runs, 1));
    ASSERT_EQ(static_cast<int>(reference.runs.size()), runs);
    for (const PsoRun<kNumParams>& run : reference.runs) {
      // A real search happened: the best fitness fell and is the fitness of the best vector.
      ASSERT_EQ(run.history.size(), 150u);
      EXPECT_LT(run.history.back(), run.history.front());
      EXPECT_EQ(run.best_fitness, data.Evaluate(run.best.data()));
      EXPECT_EQ(run.termination, "max_iterations");
    }
    for (int threads : {2, 3}) {
      const PsoResult<kNumParams> other = RunPso(data, SmallPso(runs, threads));
      EXPECT_EQ(other.best_run, reference.best_run);
      for (int r = 0; r < runs; ++r) {
        EXPECT_TRUE(BitIdentical(other.runs[r].best, reference.runs[r].best))
            << "runs " << runs << ", threads " << threads << ", run " << r;
        EXPECT_EQ(other.runs[r].best_fitness, reference.runs[r].best_fitness);
        EXPECT_EQ(other.runs[r].history, reference.runs[r].history);
      }
    }
  }
  // The seed matters: another seed gives another result.
  PsoOptions<kNumParams> o = SmallPso(1, 2);
  o.seed = 12;
  EXPECT_FALSE(
      BitIdentical(RunPso(data, o).runs[0].best, RunPso(data, SmallPso(1, 2)).runs[0].best));
}

// The PSO draws its random numbers in pairs (four at a time with AVX2): the same bits as drawing
// them one by one, for any count (whole vectors and a scalar tail) and any stream.
TEST(Solvers, UniformPairsAreTheSequentialDraws) {
  for (int n : {1, 3, 4, 5, 8, 14, 17}) {
    for (std::uint64_t key = 0; key < 300; ++key) {
      Rng one(StreamKey(7, key)), pairs(StreamKey(7, key));
      for (int round = 0; round < 4; ++round) {
        std::vector<double> a1(n), a2(n), b1(n), b2(n);
        for (int d = 0; d < n; ++d) {
          a1[d] = one.Uniform();
          a2[d] = one.Uniform();
        }
        UniformPairs(pairs, n, b1.data(), b2.data());
        ASSERT_EQ(0, std::memcmp(a1.data(), b1.data(), sizeof(double) * n)) << n << " " << key;
        ASSERT_EQ(0, std::memcmp(a2.data(), b2.data(), sizeof(double) * n)) << n << " " << key;
        ASSERT_EQ(one.State(), pairs.State());
      }
    }
  }
}

TEST(Solvers, RandomSearchSameSeedSameResultForAnyThreadCount) {
  const test::Scene s = MakeScene(Generic(), 50, 2);
  const FitnessData data(s.pixels, s.poses, s.points);
  RandomSearchOptions<kNumParams> o;
  test::Table2Bounds(&o.lower, &o.upper);
  o.evaluations = 20000;  // not a multiple of the 4096-evaluation blocks
  o.seed = 5;
  o.threads = 1;
  const RandomSearchResult<kNumParams> reference = RunRandomSearch(data, o);
  EXPECT_EQ(reference.evaluations, 20000);
  EXPECT_GE(reference.best_index, 0);
  EXPECT_EQ(reference.best_fitness, data.Evaluate(reference.best.data()));
  EXPECT_TRUE(
      ((reference.best.array() >= o.lower.array()) && (reference.best.array() <= o.upper.array()))
          .all());
  for (int threads : {2, 3}) {
    o.threads = threads;
    const RandomSearchResult<kNumParams> other = RunRandomSearch(data, o);
    EXPECT_EQ(other.threads, threads);
    EXPECT_EQ(other.evaluations, 20000);
    EXPECT_EQ(other.best_index, reference.best_index) << threads << " threads";
    EXPECT_TRUE(BitIdentical(other.best, reference.best)) << threads << " threads";
    EXPECT_EQ(other.best_fitness, reference.best_fitness);
  }
}

double HeldOutRms(const Vector14d& q, const test::Scene& held_out) {
  const PointsResult p = BasePointsFromPixels(q, held_out.pixels, held_out.poses, true);
  return std::sqrt((p.points - held_out.points).squaredNorm() / held_out.points.rows());
}

TEST(Solvers, LmFromPerturbedTruthReachesZeroCost) {
  const Vector14d truth = Generic();
  const test::Scene fit = MakeScene(truth, 50, 3);
  const test::Scene held_out = MakeScene(truth, 50, 4);
  const FitnessData data(fit.pixels, fit.poses, fit.points);
  const Vector14d start = PerturbedTruth(truth, 9);
  const double start_cost = data.Evaluate(start.data());
  ASSERT_GT(start_cost, 1.0);  // the start is visibly off (mm^2)

  LmOptions o;
  test::Table2Bounds(&o.lower, &o.upper);
  o.fixed[kSu] = true;
  for (LmMode mode : {LmMode::kModern, LmMode::kPaper}) {
    o.mode = mode;
    const bool modern = mode == LmMode::kModern;
    const LmResult r = RunLm(data, start, o);
    SCOPED_TRACE(modern ? "modern" : "paper");
    EXPECT_TRUE(r.usable);
    EXPECT_EQ(r.initial_cost, start_cost);
    EXPECT_EQ(r.final_cost, data.Evaluate(r.params.data()));
    // Noise-free data: the modern mode (smooth 3m residuals, autodiff) converges to rounding:
    // F = 6e-25 mm^2 measured, bound 1e-12 mm^2. The paper mode's ||E|| residual is not
    // differentiable at 0 and its forward differences stall earlier (docs/model.md): F = 1.9e-4
    // mm^2 measured (RMS 3e-3 mm), bound 1e-2 mm^2, still 1e6 below the start.
    EXPECT_LT(r.final_cost, modern ? 1e-12 : 1e-2);
    // Parameters are not all identifiable (docs/model.md), so compare what the data determines:
    // base points of held-out pixels and poses. Measured RMS: 1e-13 mm (modern), 2.7e-3 mm
    // (paper); bounds 1e-6 and 3e-2 mm.
    EXPECT_LT(HeldOutRms(r.params, held_out), modern ? 1e-6 : 3e-2);
    EXPECT_EQ(r.params[kSu], truth[kSu]);
  }
}

TEST(Solvers, PaperLmFastCostChangesNoBit) {
  // The paper-mode LM's cost function shares work between the points and the difference steps
  // (NewPaperCost with a PaperTrigCache). It must compute exactly what Ceres'
  // NumericDiffCostFunction over the plain residual computes: the same parameters to the last bit,
  // the same iterations and costs, from starts near and far (the far ones run thousands of
  // iterations, where any difference in the last bit would grow), with all 14 parameters free as in
  // the study and with one held fixed (Ceres' SubsetManifold).
  const Vector14d truth = Generic();
  const test::Scene fit = MakeScene(truth, 50, 3);
  const FitnessData data(fit.pixels, fit.poses, fit.points);
  std::mt19937_64 rng(5);
  int long_runs = 0;
  for (double spread : {1e-3, 0.05, 0.2}) {
    std::uniform_real_distribution<double> u(-0.5 * spread, 0.5 * spread);
    for (int run = 0; run < 4; ++run) {
      Vector14d start = truth;
      for (int j = 0; j < kNumParams; ++j) start[j] = truth[j] * (1.0 + u(rng)) + 0.1 * u(rng);
      if (!std::isfinite(data.Evaluate(start.data()))) continue;
      for (bool fix_su : {false, true}) {
        LmOptions o;
        o.mode = LmMode::kPaper;
        o.use_bounds = false;
        o.fixed[kSu] = fix_su;
        o.max_iterations = 2000;
        LmResult with, without;
        try {
          with = RunLm(data, start, o);
          o.paper_fast_cost = false;
          without = RunLm(data, start, o);
        } catch (const std::invalid_argument&) {
          continue;  // a start whose ray misses the plane is refused before any solve
        }
        SCOPED_TRACE("spread " + std::to_string(spread) + ", run " + std::to_string(run));
        EXPECT_TRUE(BitIdentical(with.params, without.params));
        EXPECT_EQ(with.iterations, without.iterations);
        EXPECT_EQ(with.final_cost, without.final_cost);
        EXPECT_EQ(with.termination, without.termination);
        if (with.iterations > 500) ++long_runs;
      }
    }
  }
  EXPECT_GT(long_runs, 0);  // the comparison covered long, sensitive runs
}

}  // namespace
}  // namespace hmlvs
