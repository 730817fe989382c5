// How a long solve (PSO, random search, the multi-start LM) reports its progress and is stopped.
#pragma once

#include <functional>

namespace hmlvs::solvers {

/// Progress of a long solve; a callback returning false stops the solve early (e.g. Ctrl-C).
struct Progress {
  long long done = 0;         ///< iterations (PSO, summed over runs), evaluations or solves done
  long long total = 0;        ///< the same, when finished
  double best_fitness = 0.0;  ///< the lowest objective so far
};
using ProgressCallback = std::function<bool(const Progress&)>;

}  // namespace hmlvs::solvers
