#include "hmlvs/model/paper_cost.h"

#include <ceres/autodiff_cost_function.h>

#include <sstream>
#include <stdexcept>

namespace hmlvs::paper {

void ResidualJacobian(
    const Vector14d& q, PixelsRef pixels, PosesRef poses, Points3Ref references,
    Eigen::VectorXd* residuals,
    Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor>* jacobian) {
  // Shape, finiteness and the laser-plane check, with the model's error messages.
  const RowMatX3 e = Residuals(q, pixels, poses, references);
  const Eigen::Index m = pixels.rows();
  residuals->resize(3 * m);
  jacobian->resize(3 * m, kNumParams);
  for (Eigen::Index i = 0; i < m; ++i) {
    const PointResidualFunctor f{pixels(i, 0), pixels(i, 1), geometry::PoseRotation(poses, i),
                                 geometry::PosePosition(poses, i), references.row(i).transpose()};
    ceres::AutoDiffCostFunction<PointResidualFunctor, 3, kNumParams> cost(
        new PointResidualFunctor(f));
    const double* params[] = {q.data()};
    double* jac[] = {jacobian->data() + 3 * i * kNumParams};
    if (!cost.Evaluate(params, residuals->data() + 3 * i, jac)) {
      std::ostringstream msg;
      msg << "pixel " << i << " has a ray that misses the laser plane";
      throw std::invalid_argument(msg.str());
    }
  }
}

}  // namespace hmlvs::paper
