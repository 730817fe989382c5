// The paper model: the per-point base-frame residual as a Ceres functor, and the residual Jacobian
// of a data set by automatic differentiation (used by the identifiability and uncertainty
// analyses). The LM solves (solvers/lm.cpp, solvers/lm_costs.cpp) use the hand-frame form of the
// same residual, HandResidual.
#pragma once

#include <Eigen/Core>

#include "hmlvs/model/paper.h"

namespace hmlvs::paper {

/// Residual of one point with the 14 parameters, E = P - bP (base frame, 3 components).
/// Returns false when the pixel's ray misses the laser plane.
struct PointResidualFunctor {
  double u, v;
  Eigen::Matrix3d base_from_hand_rot;
  Eigen::Vector3d base_from_hand_pos;
  Eigen::Vector3d reference;

  template <typename T>
  bool operator()(const T* q, T* residual) const {
    using std::tan;
    const Eigen::Matrix<T, 3, 3> rc = geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
    const T tan_theta = tan(q[kTheta]);
    return PointResidual(q, rc, tan_theta, u, v, base_from_hand_rot, base_from_hand_pos, reference,
                         residual) > T(0.0);
  }
};

/// Residuals (3m) and their Jacobian d E / d q (3m x 14) by automatic differentiation.
/// Throws std::invalid_argument if a pixel's ray misses the laser plane.
void ResidualJacobian(const Vector14d& q, PixelsRef pixels, PosesRef base_from_hand,
                      Points3Ref references, Eigen::VectorXd* residuals,
                      Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor>* jacobian);

}  // namespace hmlvs::paper
