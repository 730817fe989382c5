// The multi-start Levenberg-Marquardt of the paper model (the paper's 1000 runs): independent
// RunLm solves from many starts, in parallel.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "hmlvs/solvers/lm.h"
#include "hmlvs/solvers/progress.h"

namespace hmlvs::solvers {

/// Starts, one 14-vector (paper order) a row.
using StartsRef =
    Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, paper::kNumParams, Eigen::RowMajor>>;

struct MultiStartResult {
  std::vector<LmResult> results;    ///< per start; default values where it has an error
  std::vector<std::string> errors;  ///< per start: empty, RunLm's error, or "cancelled"
};

/// RunLm from every start, on `threads` threads (<= 0: all hardware threads; never more than
/// starts). Each start's result is RunLm's from it, whatever the thread count. A start RunLm
/// refuses gets its error and the others go on. The optional `progress` (done, total, lowest
/// final cost so far) is called by the caller's thread after each of its solves; when it returns
/// false no further start is taken, and the starts not taken get the error "cancelled" (a solve
/// under way runs to its end).
MultiStartResult RunLmMany(const paper::FitnessData& data, StartsRef starts,
                           const LmOptions& options, int threads,
                           const ProgressCallback& progress = {});

}  // namespace hmlvs::solvers
