#include "hmlvs/geometry/geometry.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace hmlvs::geometry {

namespace {

constexpr double kPi = 3.14159265358979323846;

double WrapNear(double angle, double reference) {
  return angle + 2.0 * kPi * std::round((reference - angle) / (2.0 * kPi));
}

}  // namespace

Eigen::Vector3d EulerZYZFromRotation(const Eigen::Matrix3d& r, const Eigen::Vector3d& hint) {
  const double sphi = std::hypot(r(0, 2), r(1, 2));
  if (sphi < 1e-12) {
    // Gimbal lock (phi = 0 or pi): only omega +- varphi is defined; keep omega at the hint.
    const double phi = r(2, 2) > 0 ? 0.0 : kPi;
    const double sum = std::atan2(r(1, 0), r(0, 0));  // omega + varphi (phi = 0)
    const double omega = hint[0];
    const double varphi = phi == 0.0 ? sum - omega : omega - std::atan2(-r(1, 0), -r(0, 0));
    return Eigen::Vector3d(omega, WrapNear(phi, hint[1]), WrapNear(varphi, hint[2]));
  }
  Eigen::Vector3d best;
  double best_dist = 1e300;
  for (int sign : {1, -1}) {
    const double phi = std::atan2(sign * sphi, r(2, 2));
    const double omega = std::atan2(sign * r(1, 2), sign * r(0, 2));
    const double varphi = std::atan2(sign * r(2, 1), -sign * r(2, 0));
    const Eigen::Vector3d e(WrapNear(omega, hint[0]), phi, WrapNear(varphi, hint[2]));
    const double dist = (e - hint).squaredNorm();
    if (dist < best_dist) {
      best_dist = dist;
      best = e;
    }
  }
  return best;
}

Eigen::Matrix4d Transform(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = rotation;
  t.topRightCorner<3, 1>() = translation;
  return t;
}

double OrthonormalityError(const Eigen::Matrix3d& r) {
  return (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
}

bool IsRotation(const Eigen::Matrix3d& r) {
  return !(OrthonormalityError(r) > kRigidTolerance || r.determinant() < 0.0);
}

void ValidatePoses(PosesRef poses) {
  RequireFinite(poses.data(), poses.rows(), 16, "poses");
  for (Eigen::Index i = 0; i < poses.rows(); ++i) {
    const double* p = poses.row(i).data();
    if (p[12] != 0.0 || p[13] != 0.0 || p[14] != 0.0 || p[15] != 1.0) {
      std::ostringstream msg;
      msg << "pose " << i << " is not a homogeneous transform: its last row is [" << p[12] << " "
          << p[13] << " " << p[14] << " " << p[15] << "], expected [0 0 0 1]";
      throw std::invalid_argument(msg.str());
    }
    const Eigen::Matrix3d r = PoseRotation(poses, i);
    if (!IsRotation(r)) {
      std::ostringstream msg;
      msg << "pose " << i << " has a rotation part that is not a proper rotation (|R^T R - I| = "
          << OrthonormalityError(r) << ", det = " << r.determinant()
          << "); poses must be base_from_hand transforms";
      throw std::invalid_argument(msg.str());
    }
  }
}

void CheckTransform(const Eigen::Matrix4d& m, const std::string& name) {
  if (!m.allFinite() || !IsRotation(m.topLeftCorner<3, 3>()) ||
      (m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-12) {
    throw std::invalid_argument(name +
                                " is not a rigid transform (finite, orthonormal rotation "
                                "with determinant +1, last row [0 0 0 1])");
  }
}

}  // namespace hmlvs::geometry
