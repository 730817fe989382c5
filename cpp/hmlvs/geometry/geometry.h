// Rotations and rigid transforms, written once for both sensor models and the solvers: ZYZ
// Euler angles (the paper's hand-eye rotation), unit quaternions and rotation vectors (the
// general model's), poses stored as rows of 16 numbers, and the one rigidity check.
//
// The templates take the scalar as a parameter, so that the same code serves plain doubles and
// Ceres' automatic differentiation (ceres::Jet).
#pragma once

#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

#include "hmlvs/model/arrays.h"

namespace hmlvs::geometry {

template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

/// R = Rz(omega) Ry(phi) Rz(varphi) (ZYZ Euler angles; the paper's R_C, Eq. 6).
template <typename T>
Mat3<T> RotationZYZ(const T& omega, const T& phi, const T& varphi) {
  using std::cos;
  using std::sin;
  const T co = cos(omega), so = sin(omega);
  const T cp = cos(phi), sp = sin(phi);
  const T cw = cos(varphi), sw = sin(varphi);
  Mat3<T> r;
  r(0, 0) = co * cp * cw - so * sw;
  r(0, 1) = -co * cp * sw - so * cw;
  r(0, 2) = co * sp;
  r(1, 0) = so * cp * cw + co * sw;
  r(1, 1) = -so * cp * sw + co * cw;
  r(1, 2) = so * sp;
  r(2, 0) = -sp * cw;
  r(2, 1) = sp * sw;
  r(2, 2) = cp;
  return r;
}

/// ZYZ Euler angles of a rotation, choosing among the two equivalent solutions (and, at gimbal
/// lock, the split of omega + varphi) the one closest to `hint`.
Eigen::Vector3d EulerZYZFromRotation(const Eigen::Matrix3d& r, const Eigen::Vector3d& hint);

/// The rotation of a quaternion stored as Eigen stores it, [x, y, z, w], normalised first.
template <typename T>
Mat3<T> QuaternionRotation(const T* q) {
  return Eigen::Quaternion<T>(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
}

/// A rigid transform given as a quaternion [x, y, z, w] and a translation: its rotation and
/// translation.
template <typename T>
void QuaternionPose(const T* q, const T* t, Mat3<T>* r, Vec3<T>* v) {
  *r = QuaternionRotation(q);
  *v = Vec3<T>(t[0], t[1], t[2]);
}

/// The rotation vector (axis times angle, rad) of a rotation matrix (Ceres' conversion).
template <typename T>
Vec3<T> RotationVector(const Mat3<T>& r) {
  Vec3<T> w;
  ceres::RotationMatrixToAngleAxis(r.data(), w.data());
  return w;
}

/// The rotation of a rotation vector (axis times angle, rad): Rodrigues' formula.
template <typename T>
Mat3<T> Rodrigues(const T* rotation_vector) {
  Mat3<T> r;
  ceres::AngleAxisToRotationMatrix(rotation_vector, r.data());
  return r;
}

/// The 4x4 transform of a rotation and a translation.
Eigen::Matrix4d Transform(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation);

/// The rotation and the position of pose i of a (m, 16) row-major array of 4x4 transforms.
inline Eigen::Matrix3d PoseRotation(PosesRef poses, Eigen::Index i) {
  Eigen::Matrix3d r;
  const double* p = poses.row(i).data();
  r << p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10];
  return r;
}

inline Eigen::Vector3d PosePosition(PosesRef poses, Eigen::Index i) {
  const double* p = poses.row(i).data();
  return Eigen::Vector3d(p[3], p[7], p[11]);
}

/// How far a rotation may be from orthonormal: the largest entry of |R^T R - I|.
constexpr double kRigidTolerance = 1e-6;

/// The largest entry of |R^T R - I|.
double OrthonormalityError(const Eigen::Matrix3d& r);

/// Whether r is a proper rotation: orthonormal within kRigidTolerance, determinant not negative.
bool IsRotation(const Eigen::Matrix3d& r);

/// Throws std::invalid_argument naming the first pose that is not finite, whose rotation is not
/// a proper rotation (IsRotation) or whose last row is not [0 0 0 1].
void ValidatePoses(PosesRef base_from_hand);

/// Throws std::invalid_argument "<name> is not a rigid transform ..." unless m is finite, its
/// rotation a proper rotation (IsRotation) and its last row [0 0 0 1] (within 1e-12).
void CheckTransform(const Eigen::Matrix4d& m, const std::string& name);

}  // namespace hmlvs::geometry
