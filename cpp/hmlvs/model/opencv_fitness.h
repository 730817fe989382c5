// The general model's calibration objective from reference points (the paper's protocol,
// section 4, with the general model): F(x) = 1/2 sum_i ||P_i - bP_i(x)||^2 over 18 parameters
//   x = [fx, fy, cx, cy, k1, k2, p1, p2, k3, alpha, beta, h, rx, ry, rz, tx, ty, tz]:
// the camera matrix and the five-term lens of opencv.h (its other distortion terms 0); the laser
// plane n . X = h (camera frame, mm) with n = (sin alpha, cos alpha cos beta, cos alpha sin beta),
// three degrees of freedom that hold the paper's two (its plane y + z tan(theta) = H is alpha = 0,
// beta = theta, h = H cos(theta)); hand_from_camera as a rotation vector (rad) and a translation
// (mm). Global searches (solvers/search.h) take it as they take the paper model's FitnessData.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>

#include "hmlvs/geometry/geometry.h"
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
/// The plane's normal is taken on the side where h >= 0. Throws std::invalid_argument when a
/// distortion term beyond the five-term lens is not 0.
Vector18d PointParams(const IntrinsicsVector& intrinsics, const Eigen::Vector4d& laser_plane,
                      const Eigen::Matrix4d& hand_from_camera);

/// The general model as a model trait (as paper::Model, paper.h): its 18 parameters and its
/// hand-frame residual on any scalar.
struct Model {
  static constexpr int kNumParams = kNumPointParams;
  static const std::array<std::string, kNumParams>& Names() { return PointParamNames(); }

  /// e = h - hP of pixel (u, v) whose reference point in its hand frame is h, with
  /// hP = R (rx, ry, rz) cP + t and cP the point where the pixel's ray meets the laser plane.
  /// Returns false when the pixel cannot be undistorted or its ray meets the plane behind the
  /// camera (or not at all).
  template <typename T>
  static bool Residual(const T* x, double u, double v, const double* h, T* e) {
    using std::cos;
    using std::sin;
    T in[kNumIntrinsics], xn, yn;
    for (int k = 0; k < kNumIntrinsics; ++k) in[k] = k < kNumClassicIntrinsics ? x[k] : T(0.0);
    if (!UndistortPoint(in, u, v, &xn, &yn)) return false;
    const T alpha = x[kPlaneAt], beta = x[kPlaneAt + 1];
    const T normal[3] = {sin(alpha), cos(alpha) * cos(beta), cos(alpha) * sin(beta)};
    T cp[3];
    if (!(RayPlanePoint(xn, yn, normal, T(-x[kPlaneAt + 2]), cp) > T(0.0))) return false;
    const geometry::Mat3<T> r = geometry::Rodrigues(x + kRotationAt);
    for (int k = 0; k < 3; ++k) {
      e[k] =
          T(h[k]) - (r(k, 0) * cp[0] + r(k, 1) * cp[1] + r(k, 2) * cp[2] + x[kTranslationAt + k]);
    }
    return true;
  }
};

/// The objective for the global searches: PointObjective<Model>.
class PointFitness final : public solvers::Fitness<kNumPointParams> {
 public:
  /// Validates shapes, finiteness and poses (std::invalid_argument on bad input).
  PointFitness(PixelsRef pixels, PosesRef base_from_hand, Points3Ref references);

  /// F(x); +inf where a pixel cannot be undistorted or its ray does not meet the laser plane in
  /// front of the camera.
  double Evaluate(const double* x) const override { return PointObjective<Model>(points_, x); }
  Eigen::Index size() const override { return points_.size(); }
  const std::string& ParameterName(int d) const override { return PointParamNames()[d]; }
  const CalibrationPoints& points() const { return points_; }

 private:
  CalibrationPoints points_;
};

}  // namespace hmlvs::opencv
