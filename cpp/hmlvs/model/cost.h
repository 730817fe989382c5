// Per-point residual functors shared by the Ceres solves and the Jacobian/identifiability code.
#pragma once

#include <Eigen/Core>

#include "hmlvs/model/model.h"

namespace hmlvs {

/// Hand-frame data of one calibration point, precomputed once per data set:
/// the pixel and the reference point expressed in the hand frame, h = R_N^T (P - P_N).
/// Since R_N is a rotation, ||P - bP|| = ||h - (R_C cP + t)||, so the hot loops never touch
/// the pose again.
struct HandPoint {
  double u = 0.0;
  double v = 0.0;
  Eigen::Vector3d reference_in_hand = Eigen::Vector3d::Zero();
};

/// Residual of one point with the 14 parameters, E = P - bP (base frame, 3 components).
struct PointResidualFunctor {
  double u, v;
  Eigen::Matrix3d base_from_hand_rot;
  Eigen::Vector3d base_from_hand_pos;
  Eigen::Vector3d reference;

  template <typename T>
  bool operator()(const T* q, T* residual) const {
    using std::tan;
    const Eigen::Matrix<T, 3, 3> rc = RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
    const T tan_theta = tan(q[kTheta]);
    return PointResidual(q, rc, tan_theta, u, v, base_from_hand_rot, base_from_hand_pos, reference,
                         residual);
  }
};

/// Residuals (3m) and their Jacobian d E / d q (3m x 14) by automatic differentiation.
/// Throws std::invalid_argument if a pixel's ray misses the laser plane.
void ResidualJacobian(const Vector14d& q, PixelsRef pixels, PosesRef base_from_hand,
                      Points3Ref references, Eigen::VectorXd* residuals,
                      Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor>* jacobian);

}  // namespace hmlvs
