// Calibration points as both models' objectives (paper_fitness.h, opencv_fitness.h) read them:
// stripe pixels with each reference point stored in its hand frame.
#pragma once

#include <Eigen/Core>
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

}  // namespace hmlvs
