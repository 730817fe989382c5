// Calibration points as both models' objectives (paper_fitness.h, opencv_fitness.h) read them:
// stripe pixels with each reference point stored in its hand frame.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <vector>

#include "hmlvs/model/arrays.h"

namespace hmlvs {

/// Stripe pixel i (u, v) seen at robot pose base_from_hand_i, and its reference point P_i in
/// the base, stored in its hand frame, h_i = R_N^T (P_i - P_N): since R_N is a rotation, a
/// residual taken in the hand frame, h_i - hP_i, has the norm of the base-frame residual
/// P_i - bP_i, and an evaluation never touches the poses. Structure of arrays, for the
/// evaluation loops.
struct CalibrationPoints {
  /// Validates shapes, finiteness and poses (std::invalid_argument on bad input).
  CalibrationPoints(PixelsRef pixels, PosesRef base_from_hand, Points3Ref references);

  Eigen::Index size() const { return static_cast<Eigen::Index>(u.size()); }
  Eigen::Vector3d ReferenceInHand(Eigen::Index i) const {
    return Eigen::Vector3d(hx[i], hy[i], hz[i]);
  }

  std::vector<double> u, v, hx, hy, hz;
};

/// The objective F(x) = 1/2 sum_i ||h_i - hP_i(x)||^2 (= 1/2 sum_i ||P_i - bP_i(x)||^2) of a
/// model trait (paper::Model, opencv::Model) over the points; +inf where a point has no
/// residual (its ray misses the laser plane).
template <class Model>
double PointObjective(const CalibrationPoints& points, const double* x) {
  double sum = 0.0;
  for (Eigen::Index i = 0; i < points.size(); ++i) {
    const double h[3] = {points.hx[i], points.hy[i], points.hz[i]};
    double e[3];
    if (!Model::Residual(x, points.u[i], points.v[i], h, e)) {
      return std::numeric_limits<double>::infinity();
    }
    sum += e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
  }
  return 0.5 * sum;
}

}  // namespace hmlvs
