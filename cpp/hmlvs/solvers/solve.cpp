#include "hmlvs/solvers/solve.h"

#include <ceres/manifold.h>
#include <ceres/solver.h>
#include <glog/logging.h>

#include <algorithm>
#include <stdexcept>

namespace hmlvs::solvers {

std::unique_ptr<ceres::LossFunction> MakeLoss(LossKind kind, double scale,
                                              const std::string& unit) {
  if (kind != LossKind::kNone && !(scale > 0.0)) {
    throw std::invalid_argument("the robust loss scale must be > 0 " + unit);
  }
  switch (kind) {
    case LossKind::kHuber:
      return std::make_unique<ceres::HuberLoss>(scale);
    case LossKind::kCauchy:
      return std::make_unique<ceres::CauchyLoss>(scale);
    case LossKind::kNone:
      break;
  }
  return nullptr;
}

bool HoldEntries(ceres::Problem* problem, double* block, int size, const std::vector<int>& fixed) {
  if (static_cast<int>(fixed.size()) == size) {
    problem->SetParameterBlockConstant(block);
    return false;
  }
  if (!fixed.empty()) problem->SetManifold(block, new ceres::SubsetManifold(size, fixed));
  return true;
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

SolveSummary SolveLm(ceres::Problem* problem, const StopRules& stop,
                     ceres::LinearSolverType linear_solver,
                     std::chrono::steady_clock::time_point start) {
  // Ceres writes a step whose linear solve failed (one it retries with more damping) to stderr
  // as a glog warning, even with SILENT logging; the summary says what matters.
  static const bool quiet = [] {
    FLAGS_minloglevel = std::max(FLAGS_minloglevel, static_cast<int>(google::GLOG_ERROR));
    return true;
  }();
  (void)quiet;
  ceres::Solver::Options options;
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type = linear_solver;
  options.max_num_iterations = stop.max_iterations;
  options.function_tolerance = stop.function_tolerance;
  options.parameter_tolerance = stop.parameter_tolerance;
  options.gradient_tolerance = stop.gradient_tolerance;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(options, problem, &summary);
  SolveSummary s;
  s.initial_cost = summary.initial_cost;
  s.final_cost = summary.final_cost;
  s.iterations = static_cast<int>(summary.iterations.size()) - 1;
  s.termination = ceres::TerminationTypeToString(summary.termination_type);
  s.message = summary.message;
  s.usable = summary.IsSolutionUsable();
  s.seconds = SecondsSince(start);
  return s;
}

}  // namespace hmlvs::solvers
