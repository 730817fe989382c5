// What the Levenberg-Marquardt solves with Ceres share (the paper model's RunLm, lm.h, and the
// general model's SolveJoint, joint.h): the robust loss, the solver's settings and the summary
// of a solve.
#pragma once

#include <ceres/loss_function.h>
#include <ceres/problem.h>
#include <ceres/types.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace hmlvs::solvers {

enum class LossKind { kNone, kHuber, kCauchy };

/// The robust loss of `kind` at `scale` (in the residuals' units, named `unit` in the error), or
/// none (nullptr) for kNone. Throws std::invalid_argument for a loss whose scale is not > 0.
std::unique_ptr<ceres::LossFunction> MakeLoss(LossKind kind, double scale, const std::string& unit);

/// Holds the entries `fixed` (0-based, ascending) of a parameter block of `size` entries at their
/// values: the whole block constant when all are, else a ceres::SubsetManifold when any is.
/// Returns whether any entry is left free.
bool HoldEntries(ceres::Problem* problem, double* block, int size, const std::vector<int>& fixed);

/// When a solve stops (Ceres' Solver::Options of the same names).
struct StopRules {
  int max_iterations = 100;
  double function_tolerance = 1e-10;
  double parameter_tolerance = 1e-10;
  double gradient_tolerance = 1e-14;
};

/// How a solve went. The costs are Ceres' (1/2 sum of squared residuals, after any robust loss)
/// unless the solver says otherwise (RunLm: its objective without the loss).
struct SolveSummary {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;
  std::string termination;  ///< Ceres' termination type, e.g. "CONVERGENCE"
  std::string message;      ///< Ceres' explanation
  bool usable = false;      ///< Ceres' IsSolutionUsable()
  double seconds = 0.0;     ///< from `start` (SolveLm) to the end of the solve
};

/// Solves `problem` by Levenberg-Marquardt on one thread (the cost sums of several threads would
/// depend on their schedule), silently, with the linear solver given; `seconds` counts from
/// `start`.
SolveSummary SolveLm(ceres::Problem* problem, const StopRules& stop,
                     ceres::LinearSolverType linear_solver,
                     std::chrono::steady_clock::time_point start);

/// Seconds since `start`.
double SecondsSince(std::chrono::steady_clock::time_point start);

}  // namespace hmlvs::solvers
