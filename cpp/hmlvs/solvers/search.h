// Global searches: the particle swarm optimizer (paper Eq. 19-21) and random search
// (paper section 4). Both are multithreaded and deterministic for a seed whatever the thread
// count.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "hmlvs/model/paper_fitness.h"
#include "hmlvs/solvers/progress.h"

namespace hmlvs::solvers {

struct PsoOptions {
  int swarm_size = 50;
  int iterations = 5000;        ///< T
  double w_max = 0.9;           ///< inertia at t = 0 (Eq. 20)
  double w_min = 0.4;           ///< inertia at t = T
  double c1 = 2.0;              ///< pull towards the particle's best
  double c2 = 2.0;              ///< pull towards the swarm's best
  double vmax = 0.1;            ///< velocity limit, fraction of each parameter's range
  double target_fitness = 0.0;  ///< stop when the best fitness F(q) is <= this
  int runs = 1;                 ///< independent runs (different random streams)
  int threads = 0;              ///< <= 0: all hardware threads
  std::uint64_t seed = 0;
  paper::Vector14d lower =
      paper::Vector14d::Zero();  ///< search bounds (lower == upper holds it fixed)
  paper::Vector14d upper = paper::Vector14d::Zero();
  /// Box the initial swarm is drawn from (e.g. Eq. 22 around a nominal vector); it is
  /// intersected with the search bounds. Unset (lower > upper): the search bounds.
  paper::Vector14d init_lower = paper::Vector14d::Constant(1.0);
  paper::Vector14d init_upper = paper::Vector14d::Constant(-1.0);
  int progress_every = 100;  ///< iterations between progress callbacks
};

struct PsoRun {
  paper::Vector14d best = paper::Vector14d::Zero();
  double best_fitness = 0.0;
  int iterations = 0;
  std::string termination;      ///< "max_iterations", "target_fitness" or "cancelled"
  std::vector<double> history;  ///< best fitness after each iteration
};

struct PsoResult {
  std::vector<PsoRun> runs;
  int best_run = 0;
  int threads = 1;
  double seconds = 0.0;
  bool cancelled = false;
};

/// Throws std::invalid_argument for bad options (bounds reversed or not finite, swarm < 2, ...).
PsoResult RunPso(const paper::FitnessData& data, const PsoOptions& options,
                 const ProgressCallback& progress = {});

struct RandomSearchOptions {
  long long evaluations = 1000000;
  int threads = 0;
  std::uint64_t seed = 0;
  paper::Vector14d lower =
      paper::Vector14d::Zero();  ///< candidates are uniform in [lower, upper] (Eq. 22)
  paper::Vector14d upper = paper::Vector14d::Zero();
};

struct RandomSearchResult {
  paper::Vector14d best = paper::Vector14d::Zero();
  double best_fitness = 0.0;
  long long evaluations = 0;
  long long best_index = -1;  ///< which evaluation found the best
  int threads = 1;
  double seconds = 0.0;
  bool cancelled = false;
};

RandomSearchResult RunRandomSearch(const paper::FitnessData& data,
                                   const RandomSearchOptions& options,
                                   const ProgressCallback& progress = {});

}  // namespace hmlvs::solvers
