// Global searches: the particle swarm optimizer (paper Eq. 19-21) and random search
// (paper section 4), over any objective of N parameters (fitness.h; instantiated for the
// paper model's N = 14 and the general model's N = 18). Both are multithreaded and
// deterministic for a seed whatever the thread count.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "hmlvs/solvers/fitness.h"
#include "hmlvs/solvers/progress.h"

namespace hmlvs::solvers {

template <int N>
struct PsoOptions {
  using Vector = typename Fitness<N>::Vector;
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
  Vector lower = Vector::Zero();  ///< search bounds (lower == upper holds it fixed)
  Vector upper = Vector::Zero();
  /// Box the initial swarm is drawn from (e.g. Eq. 22 around a nominal vector); it is
  /// intersected with the search bounds. Unset (lower > upper): the search bounds.
  Vector init_lower = Vector::Constant(1.0);
  Vector init_upper = Vector::Constant(-1.0);
  int progress_every = 100;  ///< iterations between progress callbacks
};

template <int N>
struct PsoRun {
  using Vector = typename Fitness<N>::Vector;
  Vector best = Vector::Zero();
  double best_fitness = 0.0;
  int iterations = 0;
  std::string termination;      ///< "max_iterations", "target_fitness" or "cancelled"
  std::vector<double> history;  ///< best fitness after each iteration
};

template <int N>
struct PsoResult {
  std::vector<PsoRun<N>> runs;
  int best_run = 0;
  int threads = 1;
  double seconds = 0.0;
  bool cancelled = false;
};

/// Throws std::invalid_argument for bad options (bounds reversed or not finite, swarm < 2, ...).
template <int N>
PsoResult<N> RunPso(const Fitness<N>& fitness, const PsoOptions<N>& options,
                    const ProgressCallback& progress = {});

template <int N>
struct RandomSearchOptions {
  using Vector = typename Fitness<N>::Vector;
  long long evaluations = 1000000;
  int threads = 0;
  std::uint64_t seed = 0;
  Vector lower = Vector::Zero();  ///< candidates are uniform in [lower, upper] (Eq. 22)
  Vector upper = Vector::Zero();
};

template <int N>
struct RandomSearchResult {
  using Vector = typename Fitness<N>::Vector;
  Vector best = Vector::Zero();
  double best_fitness = 0.0;
  long long evaluations = 0;
  long long best_index = -1;  ///< which evaluation found the best
  int threads = 1;
  double seconds = 0.0;
  bool cancelled = false;
};

/// Throws std::invalid_argument for bad options (bounds reversed or not finite, no evaluation).
template <int N>
RandomSearchResult<N> RunRandomSearch(const Fitness<N>& fitness,
                                      const RandomSearchOptions<N>& options,
                                      const ProgressCallback& progress = {});

}  // namespace hmlvs::solvers
