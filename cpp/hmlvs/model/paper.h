// The paper's sensor model (model "paper", namespace hmlvs::paper; see docs/model.md): the
// division-model camera, a laser plane with two degrees of freedom (H, theta) and a hand-eye
// transform with ZYZ Euler angles.
//
// Units: mm, rad, pixels. Parameter order is the paper's (Eq. 10):
//   q = [f, Su, Sv, Cu, Cv, k, H, theta, omega, phi, varphi, tx, ty, tz]
// The single-point functions are templated on the scalar so that the same code serves plain
// evaluation (double), the vectorised fitness kernel and Ceres automatic differentiation
// (ceres::Jet); the batch functions below them loop over those.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>

#include "hmlvs/geometry/geometry.h"
#include "hmlvs/model/arrays.h"

namespace hmlvs::paper {

constexpr int kNumParams = 14;

enum Param : int {
  kF = 0,
  kSu = 1,
  kSv = 2,
  kCu = 3,
  kCv = 4,
  kK = 5,
  kH = 6,
  kTheta = 7,
  kOmega = 8,
  kPhi = 9,
  kVarphi = 10,
  kTx = 11,
  kTy = 12,
  kTz = 13,
};

/// Names of the parameters in paper order.
const std::array<std::string, kNumParams>& ParamNames();

/// Index of a parameter by name; throws std::invalid_argument for an unknown name.
int ParamIndexFromName(const std::string& name);

using Vector14d = Eigen::Matrix<double, kNumParams, 1>;

// ---------------------------------------------------------------------------------------------
// The one formulation of docs/model.md steps 1-5. Every evaluation of the model (the batch
// functions below, the residual functors of cost.h, the LM functors and the fitness kernel of
// solvers/) goes through these functions.
//
// Each returns the laser-plane test `D s` (see PixelToCamera): the pixel has a measurement iff it
// is > 0. The outputs are always written; when the test fails they are meaningless (inf, NaN or
// a point behind the camera), so that the hot loops stay branch-free and vectorise.

/// docs/model.md steps 1-2: the distorted sensor-plane point Xd = Su (u - Cu), Yd = Sv (v - Cv)
/// (mm) of pixel (u = column, v = row), and the radial factor s = 1 + k (Xd^2 + Yd^2) that is
/// returned. The undistorted point of the division model (paper Eq. 1) is (Xu, Yu) = (Xd, Yd) / s.
template <typename T>
T DistortedSensorPoint(const T* q, const T& u, const T& v, T* xd, T* yd) {
  *xd = q[kSu] * (u - q[kCu]);
  *yd = q[kSv] * (v - q[kCv]);
  return T(1.0) + q[kK] * (*xd * *xd + *yd * *yd);
}

/// docs/model.md steps 1-3: stripe pixel (u, v) to a point in the camera frame (paper Eq. 1-3),
///   cP = rho [Xu, Yu, f],  rho = H / (Yu + f tan(theta)).
/// It is computed with a single division: with D = Yd + f tan(theta) s, Yu + f tan(theta) = D / s
/// and cP = (H / D) [Xd, Yd, f s].
///
/// Returns D s, which has the sign of Yu + f tan(theta): when it is <= 0 the pixel's ray never
/// meets the laser plane in front of the camera and `camera_point` is meaningless.
template <typename T>
T PixelToCamera(const T* q, const T& tan_theta, const T& u, const T& v, T* camera_point) {
  T xd, yd;
  const T s = DistortedSensorPoint(q, u, v, &xd, &yd);
  const T d = yd + q[kF] * tan_theta * s;
  const T g = q[kH] / d;
  camera_point[0] = g * xd;
  camera_point[1] = g * yd;
  camera_point[2] = g * q[kF] * s;
  return d * s;
}

/// docs/model.md step 4 and the hand part of step 5 (paper Eq. 5-6): a camera-frame point in the
/// hand frame, R_C cP + t, with R_C from geometry::RotationZYZ and t = (q[kTx], q[kTy], q[kTz]),
/// written out term by term and summed left to right.
template <typename T>
Eigen::Matrix<T, 3, 1> CameraToHand(const T* q, const Eigen::Matrix<T, 3, 3>& hand_from_camera_rot,
                                    const T* camera_point) {
  const Eigen::Matrix<T, 3, 3>& r = hand_from_camera_rot;
  const T* c = camera_point;
  return Eigen::Matrix<T, 3, 1>(r(0, 0) * c[0] + r(0, 1) * c[1] + r(0, 2) * c[2] + q[kTx],
                                r(1, 0) * c[0] + r(1, 1) * c[1] + r(1, 2) * c[2] + q[kTy],
                                r(2, 0) * c[0] + r(2, 1) * c[1] + r(2, 2) * c[2] + q[kTz]);
}

/// The same with R_C as a unit quaternion (the LM's SO(3) parametrisation).
template <typename T>
Eigen::Matrix<T, 3, 1> CameraToHand(const T* q, const Eigen::Quaternion<T>& hand_from_camera_rot,
                                    const T* camera_point) {
  return hand_from_camera_rot *
             Eigen::Matrix<T, 3, 1>(camera_point[0], camera_point[1], camera_point[2]) +
         Eigen::Matrix<T, 3, 1>(q[kTx], q[kTy], q[kTz]);
}

/// Stripe pixel seen at hand pose (R_N, P_N) to a point in the robot base frame (paper Eq. 9,
/// docs/model.md step 5): bP = R_N (R_C cP + t) + P_N. Returns the laser-plane test D s.
template <typename T>
T PixelToBase(const T* q, const Eigen::Matrix<T, 3, 3>& hand_from_camera_rot, const T& tan_theta,
              double u, double v, const Eigen::Matrix3d& base_from_hand_rot,
              const Eigen::Vector3d& base_from_hand_pos, T* base_point) {
  T cp[3];
  const T plane = PixelToCamera(q, tan_theta, T(u), T(v), cp);
  const Eigen::Matrix<T, 3, 1> base =
      base_from_hand_rot.cast<T>() * CameraToHand(q, hand_from_camera_rot, cp) +
      base_from_hand_pos.cast<T>();
  base_point[0] = base[0];
  base_point[1] = base[1];
  base_point[2] = base[2];
  return plane;
}

/// Residual E = P - bP(q) of one reference point P (base frame, paper Eq. 14), in all three
/// components. Returns the laser-plane test D s.
template <typename T>
T PointResidual(const T* q, const Eigen::Matrix<T, 3, 3>& hand_from_camera_rot, const T& tan_theta,
                double u, double v, const Eigen::Matrix3d& base_from_hand_rot,
                const Eigen::Vector3d& base_from_hand_pos, const Eigen::Vector3d& reference,
                T* residual) {
  T bp[3];
  const T plane = PixelToBase(q, hand_from_camera_rot, tan_theta, u, v, base_from_hand_rot,
                              base_from_hand_pos, bp);
  residual[0] = T(reference[0]) - bp[0];
  residual[1] = T(reference[1]) - bp[1];
  residual[2] = T(reference[2]) - bp[2];
  return plane;
}

/// The same residual rotated into the hand frame: E_h = R_N^T E = h - (R_C cP + t), with the
/// reference point precomputed in its hand frame, h = R_N^T (P - P_N) (`reference_in_hand`, 3
/// numbers). Since R_N is a rotation, ||E_h|| = ||E||, and the optimizers' loops never touch the
/// poses. `hand_from_camera_rot` is a 3x3 matrix or a quaternion (see CameraToHand). Returns the
/// laser-plane test D s.
template <typename T, typename Rotation>
T HandResidual(const T* q, const Rotation& hand_from_camera_rot, const T& tan_theta, double u,
               double v, const double* reference_in_hand, T* residual) {
  T cp[3];
  const T plane = PixelToCamera(q, tan_theta, T(u), T(v), cp);
  const Eigen::Matrix<T, 3, 1> hand = CameraToHand(q, hand_from_camera_rot, cp);
  residual[0] = T(reference_in_hand[0]) - hand[0];
  residual[1] = T(reference_in_hand[1]) - hand[1];
  residual[2] = T(reference_in_hand[2]) - hand[2];
  return plane;
}

/// The paper model as a model trait (the general model's: opencv::Model, opencv_fitness.h): its
/// parameters and its hand-frame residual on any scalar. The point LM (solvers/point_lm.h) and
/// the point objective (calibration_points.h) are written once over such a trait.
struct Model {
  static constexpr int kNumParams = paper::kNumParams;
  static const std::array<std::string, kNumParams>& Names() { return ParamNames(); }

  /// HandResidual with R_C from the Euler angles: e = h - (R_C cP + t) of pixel (u, v) whose
  /// reference point in its hand frame is h. Returns false when the ray misses the laser plane.
  template <typename T>
  static bool Residual(const T* q, double u, double v, const double* h, T* e) {
    using std::tan;
    return HandResidual(q, geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]), tan(q[kTheta]), u,
                        v, h, e) > T(0.0);
  }
};

// ---------------------------------------------------------------------------------------------
// Batch evaluation on plain doubles (the array types of arrays.h).

/// Throws std::invalid_argument unless q is finite and physically meaningful
/// (f, Su, Sv, H > 0, |theta| < pi/2).
void ValidateParams(const Vector14d& q);

/// The sine of the angle between pixel (u, v)'s ray (Xu, Yu, f) and the laser plane, whose normal
/// is (0, cos theta, sin theta): the batch functions below refuse a pixel whose sine is below
/// their `min_ray_sine`.
double RayPlaneSine(const double* q, double cos_theta, double sin_theta, double u, double v);

/// Stripe pixels -> camera-frame points (mm), docs/model.md steps 1-3. Pixels whose ray misses the
/// laser plane are marked invalid; with `throw_on_invalid` the first one raises
/// std::invalid_argument.
/// Pixels whose ray meets the plane at an angle whose sine is below `min_ray_sine` (e.g.
/// kMinRaySine) are invalid too.
PointsResult CameraPointsFromPixels(const Vector14d& q, PixelsRef pixels, bool throw_on_invalid,
                                    double min_ray_sine = 0.0);

/// Stripe pixels + base_from_hand poses -> base-frame points (mm), paper Eq. 9.
PointsResult BasePointsFromPixels(const Vector14d& q, PixelsRef pixels, PosesRef base_from_hand,
                                  bool throw_on_invalid, double min_ray_sine = 0.0);

/// Residuals E_i = P_i - bP_i(q) (m x 3). Throws if a pixel's ray misses the laser plane.
RowMatX3 Residuals(const Vector14d& q, PixelsRef pixels, PosesRef base_from_hand,
                   Points3Ref references);

/// The paper's objective F(q) = 1/2 sum_i ||E_i||^2 (Eq. 13); +inf if a ray misses the plane.
double Objective(const Vector14d& q, PixelsRef pixels, PosesRef base_from_hand,
                 Points3Ref references);

/// Camera-frame points -> pixels: pinhole projection and the inverse of the division-model
/// distortion. Points behind the camera, or beyond the distortion model's invertible radius,
/// are invalid. This is the plain camera projection; it does not check the laser plane.
PixelsResult PixelsFromCameraPoints(const Vector14d& q, Points3Ref camera_points);

/// Base-frame points on the laser plane + poses -> stripe pixels (the inverse of
/// BasePointsFromPixels). A point farther than `plane_tolerance` mm from the laser plane is
/// invalid (pass +inf to project any point, e.g. checkerboard corners for rendering).
PixelsResult PixelsFromBasePoints(const Vector14d& q, Points3Ref base_points,
                                  PosesRef base_from_hand, double plane_tolerance);

/// Signed distance (mm) of base-frame points from the laser plane, y + z tan(theta) - H in
/// the camera frame scaled to a true distance.
Eigen::VectorXd LaserPlaneDistance(const Vector14d& q, Points3Ref base_points,
                                   PosesRef base_from_hand);

/// Pixels -> viewing rays in the camera frame: the undistorted image point (Xu, Yu, f) in mm
/// (not normalised). Every pixel has a ray; whether it meets the laser plane is separate.
RowMatX3 CameraRaysFromPixels(const Vector14d& q, PixelsRef pixels);

/// The hand_from_camera transform (4x4) of parameters q.
Eigen::Matrix4d HandFromCamera(const Vector14d& q);

}  // namespace hmlvs::paper
