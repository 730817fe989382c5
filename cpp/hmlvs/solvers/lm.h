// Levenberg-Marquardt identification of the paper model with Ceres, in two modes:
//  - kPaper: the paper's NLSO: one scalar residual ||E_i|| per point, forward-difference
//    Jacobian, the 14 parameters with ZYZ Euler angles, no bounds, at most 300 x (free parameters)
//    iterations.
//  - kModern: the three components of E_i, analytic Jacobian (automatic differentiation when an
//    Euler angle is held fixed), the hand-eye rotation on SO(3) (unit quaternion manifold;
//    converted back to ZYZ Euler angles), bounds on the other parameters, any subset held
//    fixed, optional robust loss.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>

#include "hmlvs/model/paper_fitness.h"
#include "hmlvs/solvers/solve.h"

namespace hmlvs::solvers {

enum class LmMode { kModern, kPaper };

struct LmOptions {
  LmMode mode = LmMode::kModern;
  int max_iterations = 0;                       ///< <= 0: 300 x (number of free parameters)
  std::array<bool, paper::kNumParams> fixed{};  ///< held at the initial value
  bool use_bounds = true;                       ///< modern mode: keep parameters in [lower, upper]
  paper::Vector14d lower = paper::Vector14d::Constant(-1e300);
  paper::Vector14d upper = paper::Vector14d::Constant(1e300);
  LossKind loss = LossKind::kNone;
  double loss_scale = 1.0;  ///< mm
  double function_tolerance = 1e-14;
  double parameter_tolerance = 1e-14;
  double gradient_tolerance = 1e-16;
  /// Paper mode: the cost function that shares work between the points and the difference
  /// steps (NewPaperCost with a PaperTrigCache). false: Ceres' NumericDiffCostFunction, the
  /// reference it must match bit for bit (for the test that checks it does).
  bool paper_fast_cost = true;
};

/// The solve's summary, with initial_cost and final_cost the objective F before and after
/// (1/2 sum ||E||^2, without any robust loss), and the parameters found.
struct LmResult : SolveSummary {
  paper::Vector14d params = paper::Vector14d::Zero();
};

/// Throws std::invalid_argument for an initial vector that is not valid (a ray misses the laser
/// plane, outside bounds in modern mode) or fewer residuals than free parameters.
LmResult RunLm(const paper::FitnessData& data, const paper::Vector14d& initial,
               const LmOptions& options);

}  // namespace hmlvs::solvers
