#include "hmlvs/model/opencv_fitness.h"

#include <cmath>
#include <stdexcept>

#include "hmlvs/geometry/geometry.h"

namespace hmlvs::opencv {

const std::array<std::string, kNumPointParams>& PointParamNames() {
  static const std::array<std::string, kNumPointParams> names = {
      "fx",          "fy",         "cx",      "cy", "k1", "k2", "p1", "p2", "k3",
      "plane_alpha", "plane_beta", "plane_h", "rx", "ry", "rz", "tx", "ty", "tz"};
  return names;
}

Eigen::Vector4d PlaneFromAngles(double alpha, double beta, double h) {
  return Eigen::Vector4d(std::sin(alpha), std::cos(alpha) * std::cos(beta),
                         std::cos(alpha) * std::sin(beta), -h);
}

Vector18d PointParams(const IntrinsicsVector& intrinsics, const Eigen::Vector4d& laser_plane,
                      const Eigen::Matrix4d& hand_from_camera) {
  if (!intrinsics.tail<kNumIntrinsics - kNumClassicIntrinsics>().isZero(0.0)) {
    throw std::invalid_argument(
        "the point objective's lens has five distortion terms (k1, k2, p1, p2, k3) on an upright "
        "sensor; k4 to tauy must be 0");
  }
  Eigen::Vector4d p = laser_plane / laser_plane.head<3>().norm();
  if (p[3] > 0.0) p = -p;  // n . X = h with h = -d >= 0
  Vector18d x;
  x.head<kNumClassicIntrinsics>() = intrinsics.head<kNumClassicIntrinsics>();
  x[kPlaneAt] = std::asin(p[0]);
  x[kPlaneAt + 1] = std::atan2(p[2], p[1]);
  x[kPlaneAt + 2] = -p[3];
  const Eigen::Matrix3d r = hand_from_camera.topLeftCorner<3, 3>();
  x.segment<3>(kRotationAt) = geometry::RotationVector(r);
  x.segment<3>(kTranslationAt) = hand_from_camera.topRightCorner<3, 1>();
  return x;
}

PointFitness::PointFitness(PixelsRef pixels, PosesRef poses, Points3Ref references)
    : points_(pixels, poses, references) {}

}  // namespace hmlvs::opencv
