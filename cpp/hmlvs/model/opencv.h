// The general sensor model (model "opencv", namespace hmlvs::opencv): OpenCV's pinhole camera
// with its distortion (Brown-Conrady, the rational model's denominator, the thin prism and the
// tilted sensor), a laser plane with three degrees of freedom and a hand-eye transform with any
// rotation.
//
// Units: mm and pixels; pixel centres at integer coordinates (u = column, v = row), as in
// cv2.projectPoints. Intrinsics are 18 numbers [fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6,
// s1, s2, s3, s4, taux, tauy]: OpenCV's fourteen distortion coefficients in its order, the last
// two the tilted (Scheimpflug) sensor's angles in radians (a lens of five terms on an upright
// sensor has the last nine 0). The laser plane is n . X + d = 0 in the camera frame, with n a unit
// vector.
//
// As in paper.h, the single-point functions are templates on the scalar, so that one
// formulation serves plain evaluation, calibration (ceres::Jet) and measurement.
#pragma once

#include <ceres/jet.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "hmlvs/geometry/geometry.h"
#include "hmlvs/model/arrays.h"

namespace hmlvs::opencv {

constexpr int kNumIntrinsics = 18;
enum Intrinsic : int {
  kFx = 0,
  kFy,
  kCx,
  kCy,
  kK1,
  kK2,
  kP1,
  kP2,
  kK3,
  kK4,
  kK5,
  kK6,
  kS1,
  kS2,
  kS3,
  kS4,
  kTauX,
  kTauY
};
/// The intrinsics' names, in order (OpenCV's).
inline constexpr const char* kIntrinsicNames[kNumIntrinsics] = {
    "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2",   "k3",
    "k4", "k5", "k6", "s1", "s2", "s3", "s4", "taux", "tauy"};
/// The first kNumClassicIntrinsics are the camera matrix and the five-term Brown-Conrady lens.
constexpr int kNumClassicIntrinsics = 9;

using IntrinsicsVector = Eigen::Matrix<double, kNumIntrinsics, 1>;

/// OpenCV's distortion of a normalised image point (x, y) = (X/Z, Y/Z) (cv2.projectPoints
/// with 12 coefficients): r2 = x^2 + y^2,
///   radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3),
///   xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2) + s1 r2 + s2 r2^2,
///   yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y + s3 r2 + s4 r2^2.
/// Without kWide the terms beyond the five-term lens (k4 to s4) are taken as 0 unread: the
/// same values for a lens without them, for fewer operations (on Jets above all).
template <bool kWide = true, typename T, typename S>
void Distort(const T* in, const S& x, const S& y, T* xd, T* yd) {
  const S r2 = x * x + y * y;
  T radial = T(1.0) + r2 * (in[kK1] + r2 * (in[kK2] + r2 * in[kK3]));
  if constexpr (kWide) radial /= T(1.0) + r2 * (in[kK4] + r2 * (in[kK5] + r2 * in[kK6]));
  *xd = x * radial + T(2.0) * in[kP1] * x * y + in[kP2] * (r2 + T(2.0) * x * x);
  *yd = y * radial + in[kP1] * (r2 + T(2.0) * y * y) + T(2.0) * in[kP2] * x * y;
  if constexpr (kWide) {
    *xd += r2 * (in[kS1] + r2 * in[kS2]);
    *yd += r2 * (in[kS3] + r2 * in[kS4]);
  }
}

/// The inverse of the tilted sensor's homography of some intrinsics (TiltHomography), computed
/// once for many pixels: `upright` when taux = tauy = 0, with nothing to apply.
struct Untilt {
  explicit Untilt(const double* intrinsics);
  bool upright = true;
  double h[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
};

/// Inverts the distortion of one pixel in plain doubles: the normalised point (x, y) whose
/// distorted image is the pixel, by Newton's method from the pixel's own normalised position
/// (DistortedTarget). Returns false when it does not converge to 1e-12 (the pixel lies beyond
/// the distortion's invertible region) or the Jacobian is singular. `jacobian` (row-major 2x2,
/// optional) receives d(xd, yd)/d(x, y) at the solution. `untilt`: the intrinsics' Untilt,
/// computed here when not given.
bool UndistortNormalized(const double* in, double u, double v, double* x, double* y,
                         double* jacobian = nullptr, const Untilt* untilt = nullptr);

/// The value of a scalar: a double itself, a Jet's real part.
inline double ValueOf(double v) { return v; }
template <typename S, int N>
double ValueOf(const ceres::Jet<S, N>& v) {
  return v.a;
}

/// OpenCV's tilted sensor (computeTiltProjectionMatrix): with R = Ry(tauy) Rx(taux), the
/// homography H = [[R22, 0, -R02], [0, R22, -R12], [0, 0, 1]] R takes a distorted point
/// (xd, yd, 1) to the tilted sensor (its inverse, up to scale, R^T [[1, 0, R02], [0, 1, R12],
/// [0, 0, R22]]). Writes H (or, with `inverse`, H^-1) row-major.
template <typename T>
void TiltHomography(const T& tau_x, const T& tau_y, bool inverse, T* h) {
  using std::cos;
  using std::sin;
  const T cx = cos(tau_x), sx = sin(tau_x), cy = cos(tau_y), sy = sin(tau_y);
  const T r[9] = {cy, sy * sx, -sy * cx, T(0.0), cx, sx, sy, -cy * sx, cy * cx};
  for (int j = 0; j < 3; ++j) {
    if (inverse) {  // row j of R^T Q: column j of R, then its dot with (R02, R12, R22)
      h[3 * j] = r[j];
      h[3 * j + 1] = r[3 + j];
      h[3 * j + 2] = r[j] * r[2] + r[3 + j] * r[5] + r[6 + j] * r[8];
    } else {
      h[j] = r[8] * r[j] - r[2] * r[6 + j];
      h[3 + j] = r[8] * r[3 + j] - r[5] * r[6 + j];
      h[6 + j] = r[6 + j];
    }
  }
}

/// (x, y) through the homography h (row-major 3x3), in place.
template <typename T>
void ApplyHomography(const T* h, T* x, T* y) {
  const T w = h[6] * *x + h[7] * *y + h[8];
  const T xo = (h[0] * *x + h[1] * *y + h[2]) / w;
  *y = (h[3] * *x + h[4] * *y + h[5]) / w;
  *x = xo;
}

/// A camera-frame point to its pixel (cv2.projectPoints). Returns false for a point that is not
/// in front of the camera (Z <= 0); the pixel is then meaningless. Without kWide the terms
/// beyond the five-term lens (k4 to tauy) are taken as 0 unread (Distort). `tilt`: the tilted
/// sensor's homography (TiltHomography) when already computed for many points.
template <bool kWide = true, typename T>
bool ProjectPoint(const T* in, const T* camera_point, T* pixel, const T* tilt = nullptr) {
  const T x = camera_point[0] / camera_point[2];
  const T y = camera_point[1] / camera_point[2];
  T xd, yd;
  Distort<kWide>(in, x, y, &xd, &yd);
  if constexpr (kWide) {
    T h[9];
    if (tilt == nullptr) {
      TiltHomography(in[kTauX], in[kTauY], false, h);
      tilt = h;
    }
    ApplyHomography(tilt, &xd, &yd);
  }
  pixel[0] = in[kFx] * xd + in[kCx];
  pixel[1] = in[kFy] * yd + in[kCy];
  return camera_point[2] > T(0.0);
}

/// The point the lens's distortion must reach for pixel (u, v): ((u - cx) / fx, (v - cy) / fy),
/// taken back through `untilt`, the inverse of the tilted sensor's homography (TiltHomography;
/// nullptr: an upright sensor, taux = tauy = 0).
template <typename T>
void DistortedTarget(const T* in, const T* untilt, double u, double v, T* mx, T* my) {
  *mx = (T(u) - in[kCx]) / in[kFx];
  *my = (T(v) - in[kCy]) / in[kFy];
  if (untilt != nullptr) ApplyHomography(untilt, mx, my);
}

/// UndistortNormalized on any scalar: the Newton iteration in plain doubles, then, on a Jet,
/// one Newton step on the Jet from its solution, which changes no value there and carries the
/// exact derivatives (those of the implicit function distort(x, y) = m(intrinsics)). On doubles
/// the solution itself.
template <typename T>
bool UndistortPoint(const T* in, double u, double v, T* x, T* y) {
  double values[kNumIntrinsics], x0, y0, jd[4];
  for (int k = 0; k < kNumIntrinsics; ++k) values[k] = ValueOf(in[k]);
  if (!UndistortNormalized(values, u, v, &x0, &y0, jd)) return false;
  if constexpr (std::is_same_v<T, double>) {
    *x = x0;
    *y = y0;
  } else {
    T xd, yd, mx, my, untilt[9];
    Distort(in, x0, y0, &xd, &yd);
    TiltHomography(in[kTauX], in[kTauY], true, untilt);
    DistortedTarget(in, untilt, u, v, &mx, &my);
    const T ex = xd - mx;
    const T ey = yd - my;
    const double det = jd[0] * jd[3] - jd[1] * jd[2];
    *x = T(x0) - (jd[3] * ex - jd[1] * ey) / det;
    *y = T(y0) - (jd[0] * ey - jd[2] * ex) / det;
  }
  return true;
}

/// The point where the ray through normalised image point (x, y) meets the plane
/// n . X + d = 0 (camera frame). Returns the depth Z = -d / (n . (x, y, 1)); the ray meets the
/// plane in front of the camera iff it is > 0.
template <typename T, typename S>
T RayPlanePoint(const S& x, const S& y, const T* normal, const T& offset, T* point) {
  const T depth = -offset / (normal[0] * x + normal[1] * y + normal[2]);
  point[0] = depth * x;
  point[1] = depth * y;
  point[2] = depth;
  return depth;
}

/// The camera_from_board transform of one view, from the chain
///   camera_from_board = inv(hand_from_camera) inv(base_from_hand) base_from_board,
/// with the two unknown transforms as (unit quaternion [x, y, z, w], translation) and the
/// robot's base_from_hand given. Writes the rotation (3x3) and the translation.
template <typename T>
void CameraFromBoard(const T* hand_from_camera_q, const T* hand_from_camera_t,
                     const Eigen::Matrix3d& base_from_hand_r,
                     const Eigen::Vector3d& base_from_hand_t, const T* base_from_board_q,
                     const T* base_from_board_t, Eigen::Matrix<T, 3, 3>* rotation,
                     Eigen::Matrix<T, 3, 1>* translation) {
  using Mat3 = Eigen::Matrix<T, 3, 3>;
  using Vec3 = Eigen::Matrix<T, 3, 1>;
  const Mat3 r_hc = geometry::QuaternionRotation(hand_from_camera_q);
  const Mat3 r_bb = geometry::QuaternionRotation(base_from_board_q);
  const Mat3 r_hand_base = base_from_hand_r.transpose().cast<T>();
  const Vec3 t_hc(hand_from_camera_t[0], hand_from_camera_t[1], hand_from_camera_t[2]);
  const Vec3 t_bb(base_from_board_t[0], base_from_board_t[1], base_from_board_t[2]);
  // hand_from_board = inv(base_from_hand) base_from_board
  const Mat3 r_hb = r_hand_base * r_bb;
  const Vec3 t_hb = r_hand_base * (t_bb - base_from_hand_t.cast<T>());
  *rotation = r_hc.transpose() * r_hb;
  *translation = r_hc.transpose() * (t_hb - t_hc);
}

// ---------------------------------------------------------------------------------------------
// Batch evaluation on plain doubles (intrinsics as an 18-vector; see the top of the file).

/// Throws std::invalid_argument unless the intrinsics are finite with fx, fy > 0.
void ValidateIntrinsics(const IntrinsicsVector& intrinsics);

/// Camera-frame points -> pixels (cv2.projectPoints). Points with Z <= 0 are invalid (NaN).
PixelsResult ProjectCameraPoints(const IntrinsicsVector& intrinsics, Points3Ref camera_points);

/// Pixels -> undistorted normalised image points (x, y) (cv2.undistortPoints without R/P, but
/// solved to convergence). Pixels where the inversion fails are invalid (NaN).
PixelsResult UndistortPixels(const IntrinsicsVector& intrinsics, PixelsRef pixels);

/// The laser plane (a, b, c, d) scaled to a unit normal. Throws std::invalid_argument unless
/// its normal is finite and non-zero and d finite.
Eigen::Vector4d UnitPlane(const Eigen::Vector4d& laser_plane);

/// Stripe pixel (u, v) -> its camera-frame point on the laser plane `unit_plane` (UnitPlane):
/// false, with the reason in `why`, when the pixel's undistortion fails or its ray meets the
/// plane behind the camera, not at all or at a grazing angle (sine below kMinRaySine). The
/// step of LaserPointsInCamera for one pixel. `untilt`: as in UndistortNormalized.
bool LaserPoint(const IntrinsicsVector& intrinsics, const Eigen::Vector4d& unit_plane, double u,
                double v, double* point, const char** why, const Untilt* untilt = nullptr);

/// Stripe pixels -> camera-frame points on the laser plane (a, b, c, d). A pixel whose ray
/// meets the plane behind the camera (or not at all), or whose undistortion fails, is invalid;
/// with `throw_on_invalid` the first one raises std::invalid_argument naming it.
PointsResult LaserPointsInCamera(const IntrinsicsVector& intrinsics,
                                 const Eigen::Vector4d& laser_plane, PixelsRef pixels,
                                 bool throw_on_invalid);

/// Stripe pixels seen at base_from_hand poses -> base-frame points:
///   bP = base_from_hand hand_from_camera cP.
PointsResult LaserPointsInBase(const IntrinsicsVector& intrinsics,
                               const Eigen::Vector4d& laser_plane,
                               const Eigen::Matrix4d& hand_from_camera, PixelsRef pixels,
                               PosesRef base_from_hand, bool throw_on_invalid);

}  // namespace hmlvs::opencv
