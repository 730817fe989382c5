// One Ceres problem for either sensor model: Levenberg-Marquardt over a model trait
// (paper::Model in paper.h, opencv::Model in opencv_fitness.h) from calibration points
// (calibration_points.h). One residual block of three numbers per point, the hand-frame residual
// h_i - hP_i(x), over one scalar parameter block per parameter (so that any subset is held or
// bounded alone), Jacobian by automatic differentiation. The paper model's RunLm (lm.h) builds
// its modern mode with an Euler angle held from these blocks.
#pragma once

#include <ceres/cost_function.h>
#include <ceres/problem.h>

#include <Eigen/Core>
#include <array>

#include "hmlvs/model/calibration_points.h"
#include "hmlvs/solvers/solve.h"

namespace hmlvs::solvers {

template <int N>
struct PointLmOptions {
  using Vector = Eigen::Matrix<double, N, 1>;
  std::array<bool, N> fixed{};  ///< held at the initial value
  bool use_bounds = true;       ///< keep the free parameters in [lower, upper]
  Vector lower = Vector::Constant(-1e300);
  Vector upper = Vector::Constant(1e300);
  LossKind loss = LossKind::kNone;
  double loss_scale = 1.0;                 ///< mm
  StopRules stop{0, 1e-14, 1e-14, 1e-16};  ///< max_iterations <= 0: 300 x (free parameters)
};

template <int N>
struct PointLmResult : SolveSummary {
  Eigen::Matrix<double, N, 1> params = Eigen::Matrix<double, N, 1>::Zero();
};

/// The residual block of one point (u, v) whose reference point in its hand frame is h: three
/// residuals over Model::kNumParams scalar blocks. The caller owns it.
template <class Model>
ceres::CostFunction* NewPointCost(double u, double v, const Eigen::Vector3d& h);

/// Adds the blocks of every point to `problem`, over the scalars x[0], ..., x[N - 1], each
/// under `loss` (may be null; not owned), then holds the fixed ones and bounds the others (with
/// `use_bounds`).
template <class Model>
void AddPointBlocks(ceres::Problem* problem, const CalibrationPoints& points, double* x,
                    ceres::LossFunction* loss, const PointLmOptions<Model::kNumParams>& options);

/// Solves from `initial`; initial_cost and final_cost are PointObjective<Model> (without the
/// robust loss). Throws std::invalid_argument for a start that is not finite or where a point
/// has no residual, bounds that are reversed or do not hold it, nothing free, or fewer
/// residuals than free parameters.
template <class Model>
PointLmResult<Model::kNumParams> RunPointLm(
    const CalibrationPoints& points, const Eigen::Matrix<double, Model::kNumParams, 1>& initial,
    const PointLmOptions<Model::kNumParams>& options);

}  // namespace hmlvs::solvers
