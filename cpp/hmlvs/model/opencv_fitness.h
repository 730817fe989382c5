// The general model's calibration objective from reference points (the paper's protocol,
// section 4, with the general model): F(x) = 1/2 sum_i ||P_i - bP_i(x)||^2 over 18 parameters
//   x = [fx, fy, cx, cy, k1, k2, p1, p2, k3, alpha, beta, h, rx, ry, rz, tx, ty, tz]:
// the intrinsics (opencv.h); the laser plane n . X = h (camera frame, mm) with
// n = (sin alpha, cos alpha cos beta, cos alpha sin beta), three degrees of freedom that hold
// the paper's two (its plane y + z tan(theta) = H is alpha = 0, beta = theta,
// h = H cos(theta)); hand_from_camera as a rotation vector (rad) and a translation (mm).
// Global searches (solvers/search.h) take it as they take the paper model's FitnessData.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>

#include "hmlvs/model/calibration_points.h"
#include "hmlvs/model/opencv.h"
#include "hmlvs/solvers/fitness.h"

namespace hmlvs::opencv {

constexpr int kNumPointParams = 18;
constexpr int kPlaneAt = 9;         ///< alpha, beta, h
constexpr int kRotationAt = 12;     ///< rx, ry, rz
constexpr int kTranslationAt = 15;  ///< tx, ty, tz

using Vector18d = Eigen::Matrix<double, kNumPointParams, 1>;

/// The names of the 18 parameters, in order.
const std::array<std::string, kNumPointParams>& PointParamNames();

/// The plane (a, b, c, d), a X + b Y + c Z + d = 0 with a unit normal, of (alpha, beta, h).
Eigen::Vector4d PlaneFromAngles(double alpha, double beta, double h);

/// The 18 parameters of intrinsics, a laser plane (a, b, c, d) (any scale) and hand_from_camera.
/// The plane's normal is taken on the side where h >= 0.
Vector18d PointParams(const Vector9d& intrinsics, const Eigen::Vector4d& laser_plane,
                      const Eigen::Matrix4d& hand_from_camera);

class PointFitness final : public solvers::Fitness<kNumPointParams> {
 public:
  /// Validates shapes, finiteness and poses (std::invalid_argument on bad input).
  PointFitness(PixelsRef pixels, PosesRef base_from_hand, Points3Ref references);

  /// F(x); +inf where a pixel cannot be undistorted or its ray does not meet the laser plane in
  /// front of the camera.
  double Evaluate(const double* x) const override;
  Eigen::Index size() const override { return points_.size(); }
  const std::string& ParameterName(int d) const override { return PointParamNames()[d]; }

 private:
  CalibrationPoints points_;
};

}  // namespace hmlvs::opencv
