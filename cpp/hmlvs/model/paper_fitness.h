// The paper model's calibration objective F(q) = 1/2 sum_i ||E_i||^2 over m reference points (paper
// Eq. 13), laid out for the optimizers' hot loop.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "hmlvs/model/paper.h"

namespace hmlvs::paper {

/// Calibration points precomputed once per data set. Each reference point is stored in its
/// hand frame, h_i = R_N^T (P_i - P_N); since R_N is a rotation, ||E_i|| = ||h_i - (R_C cP + t)||
/// and an evaluation never touches the poses. Structure-of-arrays for the evaluation loop.
class FitnessData {
 public:
  /// Validates shapes, finiteness and poses (std::invalid_argument on bad input).
  FitnessData(PixelsRef pixels, PosesRef base_from_hand, Points3Ref references);

  Eigen::Index size() const { return static_cast<Eigen::Index>(u_.size()); }

  /// F(q) = 1/2 sum ||E_i||^2; +inf if any pixel's ray misses the laser plane. No allocation.
  double Evaluate(const double* q) const;

  /// Per-point ||E_i|| (mm); NaN where the ray misses the laser plane.
  Eigen::VectorXd PointErrors(const double* q) const;

  double u(Eigen::Index i) const { return u_[i]; }
  double v(Eigen::Index i) const { return v_[i]; }
  Eigen::Vector3d ReferenceInHand(Eigen::Index i) const {
    return Eigen::Vector3d(hx_[i], hy_[i], hz_[i]);
  }

 private:
  std::vector<double> u_, v_, hx_, hy_, hz_;
};

}  // namespace hmlvs::paper
