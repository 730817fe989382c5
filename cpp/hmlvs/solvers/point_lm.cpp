#include "hmlvs/solvers/point_lm.h"

#include <ceres/ceres.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hmlvs/model/opencv_fitness.h"
#include "hmlvs/model/paper.h"

namespace hmlvs::solvers {

namespace {

// Model::Residual over one scalar block per parameter.
template <class Model>
struct PointResidual {
  double u, v;
  Eigen::Vector3d h;

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    T x[Model::kNumParams];
    for (int i = 0; i < Model::kNumParams; ++i) x[i] = p[i][0];
    return Model::Residual(x, u, v, h.data(), residual);
  }
};

// Throws std::invalid_argument for what RunPointLm refuses (point_lm.h); returns the number of
// free parameters.
template <class Model>
int CheckPointLmInput(const CalibrationPoints& points, const double* x,
                      const PointLmOptions<Model::kNumParams>& o) {
  constexpr int n = Model::kNumParams;
  const auto& names = Model::Names();
  int free = 0;
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(x[i]))
      throw std::invalid_argument("parameter " + names[i] + " is not finite");
    free += o.fixed[i] ? 0 : 1;
    const bool outside = !o.fixed[i] && (x[i] < o.lower[i] || x[i] > o.upper[i]);
    if (o.use_bounds && (o.lower[i] > o.upper[i] || outside)) {
      std::ostringstream msg;
      msg << "bounds of " << names[i] << ": [" << o.lower[i] << ", " << o.upper[i]
          << "] are reversed or do not hold its initial value " << x[i];
      throw std::invalid_argument(msg.str());
    }
  }
  if (free == 0) throw std::invalid_argument("all parameters are fixed: nothing to estimate");
  if (3 * points.size() < free) {
    std::ostringstream msg;
    msg << "too few points: " << points.size() << " points give " << 3 * points.size()
        << " residuals for " << free << " free parameters";
    throw std::invalid_argument(msg.str());
  }
  for (Eigen::Index i = 0; i < points.size(); ++i) {
    const double h[3] = {points.hx[i], points.hy[i], points.hz[i]};
    double e[3];
    if (!Model::Residual(x, points.u[i], points.v[i], h, e)) {
      std::ostringstream msg;
      msg << "the initial parameters are not usable: calibration point " << i
          << " has no point on the laser plane";
      throw std::invalid_argument(msg.str());
    }
  }
  return free;
}

}  // namespace

template <class Model>
ceres::CostFunction* NewPointCost(double u, double v, const Eigen::Vector3d& h) {
  auto* cost = new ceres::DynamicAutoDiffCostFunction<PointResidual<Model>, 16>(
      new PointResidual<Model>{u, v, h});
  for (int p = 0; p < Model::kNumParams; ++p) cost->AddParameterBlock(1);
  cost->SetNumResiduals(3);
  return cost;
}

template <class Model>
void AddPointBlocks(ceres::Problem* problem, const CalibrationPoints& points, double* x,
                    ceres::LossFunction* loss, const PointLmOptions<Model::kNumParams>& o) {
  for (Eigen::Index i = 0; i < points.size(); ++i) {
    std::vector<double*> blocks;
    for (int p = 0; p < Model::kNumParams; ++p) blocks.push_back(&x[p]);
    problem->AddResidualBlock(
        NewPointCost<Model>(points.u[i], points.v[i], points.ReferenceInHand(i)), loss, blocks);
  }
  for (int i = 0; i < Model::kNumParams; ++i) {
    if (o.fixed[i]) {
      problem->SetParameterBlockConstant(&x[i]);
    } else if (o.use_bounds) {
      problem->SetParameterLowerBound(&x[i], 0, o.lower[i]);
      problem->SetParameterUpperBound(&x[i], 0, o.upper[i]);
    }
  }
}

template <class Model>
PointLmResult<Model::kNumParams> RunPointLm(
    const CalibrationPoints& points, const Eigen::Matrix<double, Model::kNumParams, 1>& initial,
    const PointLmOptions<Model::kNumParams>& o) {
  const auto start = std::chrono::steady_clock::now();
  const int free = CheckPointLmInput<Model>(points, initial.data(), o);
  PointLmResult<Model::kNumParams> result;
  result.params = initial;
  const std::unique_ptr<ceres::LossFunction> loss = MakeLoss(o.loss, o.loss_scale, "mm");
  ceres::Problem::Options popt;
  popt.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(popt);
  AddPointBlocks<Model>(&problem, points, result.params.data(), loss.get(), o);
  StopRules stop = o.stop;
  if (stop.max_iterations <= 0) stop.max_iterations = 300 * free;
  static_cast<SolveSummary&>(result) = SolveLm(&problem, stop, ceres::DENSE_QR, start);
  result.initial_cost = PointObjective<Model>(points, initial.data());
  result.final_cost = PointObjective<Model>(points, result.params.data());
  result.seconds = SecondsSince(start);
  return result;
}

#define HMLVS_POINT_LM(Model)                                                                \
  template ceres::CostFunction* NewPointCost<Model>(double, double, const Eigen::Vector3d&); \
  template void AddPointBlocks<Model>(ceres::Problem*, const CalibrationPoints&, double*,    \
                                      ceres::LossFunction*,                                  \
                                      const PointLmOptions<Model::kNumParams>&);             \
  template PointLmResult<Model::kNumParams> RunPointLm<Model>(                               \
      const CalibrationPoints&, const Eigen::Matrix<double, Model::kNumParams, 1>&,          \
      const PointLmOptions<Model::kNumParams>&);
HMLVS_POINT_LM(paper::Model)
HMLVS_POINT_LM(opencv::Model)
#undef HMLVS_POINT_LM

}  // namespace hmlvs::solvers
