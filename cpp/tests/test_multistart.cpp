// The multi-start LM (RunLmMany): each start's result is RunLm's from it, to the bit, whatever
// the thread count; a refused start gets its error while the others go on; a progress callback
// that returns false stops it taking starts.
#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

#include "hmlvs/model/paper.h"
#include "hmlvs/model/paper_fitness.h"
#include "hmlvs/solvers/lm.h"
#include "hmlvs/solvers/multistart.h"
#include "test_util.h"

namespace hmlvs {
namespace {

using namespace hmlvs::paper;
using namespace hmlvs::solvers;
using test::BitIdentical;

using Starts = Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor>;

constexpr int kBad = 2;  // the start whose rays miss the laser plane

Starts MakeStarts(int n) {
  Starts starts(n, kNumParams);
  for (int k = 0; k < n; ++k)
    starts.row(k) = test::PerturbedTruth(test::Generic(), 30 + k).transpose();
  starts(kBad, kTheta) = -1.4;  // the laser plane tilted away: every ray misses it
  return starts;
}

LmOptions Options() {
  LmOptions o;
  test::Table2Bounds(&o.lower, &o.upper);
  o.fixed[kSu] = true;
  return o;
}

TEST(MultiStart, EachStartIsItsOwnLmWhateverTheThreadCount) {
  const test::Scene s = test::MakeScene(test::Generic(), 40, 5);
  const FitnessData data(s.pixels, s.poses, s.points);
  const Starts starts = MakeStarts(6);
  const LmOptions o = Options();
  const MultiStartResult one = RunLmMany(data, starts, o, 1);
  ASSERT_EQ(one.results.size(), 6u);
  ASSERT_EQ(one.errors.size(), 6u);
  for (int k = 0; k < 6; ++k) {
    SCOPED_TRACE(k);
    if (k == kBad) {
      EXPECT_NE(one.errors[k].find("misses the laser plane"), std::string::npos) << one.errors[k];
      EXPECT_THROW(RunLm(data, starts.row(k).transpose(), o), std::invalid_argument);
      continue;
    }
    EXPECT_EQ(one.errors[k], "");
    const LmResult alone = RunLm(data, starts.row(k).transpose(), o);
    EXPECT_TRUE(BitIdentical(one.results[k].params, alone.params));
    EXPECT_EQ(one.results[k].final_cost, alone.final_cost);
    EXPECT_EQ(one.results[k].iterations, alone.iterations);
    EXPECT_LT(alone.final_cost, 1e-12);  // noise-free data (LmFromPerturbedTruthReachesZeroCost)
  }
  for (int threads : {2, 3, 8}) {
    SCOPED_TRACE(threads);
    const MultiStartResult other = RunLmMany(data, starts, o, threads);
    EXPECT_EQ(other.errors, one.errors);
    for (int k = 0; k < 6; ++k) {
      EXPECT_TRUE(BitIdentical(other.results[k].params, one.results[k].params)) << k;
      EXPECT_EQ(other.results[k].final_cost, one.results[k].final_cost) << k;
    }
  }
}

TEST(MultiStart, ProgressReportsAndStops) {
  const test::Scene s = test::MakeScene(test::Generic(), 40, 5);
  const FitnessData data(s.pixels, s.poses, s.points);
  const Starts starts = MakeStarts(6);
  std::vector<Progress> calls;
  // One thread: the starts are taken in order, and after the second report none is taken.
  const MultiStartResult r = RunLmMany(data, starts, Options(), 1, [&](const Progress& p) {
    calls.push_back(p);
    return calls.size() < 2;
  });
  ASSERT_EQ(calls.size(), 2u);
  EXPECT_EQ(calls[0].done, 1);
  EXPECT_EQ(calls[1].done, 2);
  EXPECT_EQ(calls[1].total, 6);
  EXPECT_EQ(calls[1].best_fitness, std::min(r.results[0].final_cost, r.results[1].final_cost));
  EXPECT_EQ(r.errors[0], "");
  EXPECT_EQ(r.errors[1], "");
  for (int k = 2; k < 6; ++k) EXPECT_EQ(r.errors[k], "cancelled") << k;
  // No start at all: nothing to do, no report.
  const MultiStartResult none =
      RunLmMany(data, starts.topRows(0), Options(), 2, [&](const Progress&) {
        ADD_FAILURE() << "a report without a start";
        return true;
      });
  EXPECT_TRUE(none.results.empty());
}

}  // namespace
}  // namespace hmlvs
