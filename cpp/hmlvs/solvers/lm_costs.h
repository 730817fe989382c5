// The residual blocks of the LM solves (RunLm), one per calibration point. Each evaluates the
// model's HandResidual (model/model.h); they differ in parametrisation and differentiation.
// Exposed so that their Jacobians can be tested; the caller owns the returned object.
#pragma once

#include <ceres/cost_function.h>

#include <Eigen/Core>

namespace hmlvs {

/// Paper mode: the scalar residual ||E_i|| over one 14-parameter block (paper order), Jacobian
/// by forward differences (Ceres' default relative step).
ceres::CostFunction* NewPaperCost(double u, double v, const Eigen::Vector3d& reference_in_hand);

/// Modern mode: the three components of E_h, Jacobian by automatic differentiation. Twelve
/// blocks: f, Su, Sv, Cu, Cv, k, H, theta (1 each), the hand_from_camera rotation as an Eigen
/// quaternion [x, y, z, w] (4, solved on ceres::EigenQuaternionManifold), tx, ty, tz (1 each).
ceres::CostFunction* NewModernQuaternionCost(double u, double v,
                                             const Eigen::Vector3d& reference_in_hand);

/// Modern mode when an Euler angle is held fixed: the three components of E_h over 14 scalar
/// blocks (paper order), Jacobian by automatic differentiation.
ceres::CostFunction* NewModernEulerCost(double u, double v,
                                        const Eigen::Vector3d& reference_in_hand);

}  // namespace hmlvs
