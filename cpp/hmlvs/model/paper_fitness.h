// The paper model's calibration objective F(q) = 1/2 sum_i ||E_i||^2 over m reference points (paper
// Eq. 13), laid out for the optimizers' hot loop.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "hmlvs/model/calibration_points.h"
#include "hmlvs/model/paper.h"
#include "hmlvs/solvers/fitness.h"

namespace hmlvs::paper {

/// F over calibration points precomputed once per data set (calibration_points.h: reference
/// points in their hand frames, ||E_i|| = ||h_i - (R_C cP + t)||). The objective of the global
/// searches (solvers/search.h) for this model.
class FitnessData final : public solvers::Fitness<kNumParams> {
 public:
  /// Validates shapes, finiteness and poses (std::invalid_argument on bad input).
  FitnessData(PixelsRef pixels, PosesRef base_from_hand, Points3Ref references);

  Eigen::Index size() const override { return points_.size(); }

  /// F(q) = 1/2 sum ||E_i||^2; +inf if any pixel's ray misses the laser plane. No allocation.
  double Evaluate(const double* q) const override;

  const std::string& ParameterName(int d) const override { return ParamNames()[d]; }

  /// Per-point ||E_i|| (mm); NaN where the ray misses the laser plane.
  Eigen::VectorXd PointErrors(const double* q) const;

  double u(Eigen::Index i) const { return points_.u[i]; }
  double v(Eigen::Index i) const { return points_.v[i]; }
  Eigen::Vector3d ReferenceInHand(Eigen::Index i) const { return points_.ReferenceInHand(i); }
  const CalibrationPoints& points() const { return points_; }

 private:
  CalibrationPoints points_;
};

}  // namespace hmlvs::paper
