#include "hmlvs/model/paper.h"

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace hmlvs::paper {

using geometry::PosePosition;
using geometry::PoseRotation;
using geometry::RotationZYZ;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A pixel whose ray misses the laser plane; `plane` is PixelToCamera's test value D s.
[[noreturn]] void ThrowMissedPlane(const Vector14d& q, Eigen::Index i, double u, double v,
                                   double plane) {
  // Yu + f tan(theta) = D / s = (D s) / s^2, the number docs/model.md step 3 names.
  double xd, yd;
  const double s = DistortedSensorPoint(q.data(), u, v, &xd, &yd);
  std::ostringstream msg;
  msg << "pixel " << i << " (u=" << u << ", v=" << v
      << ") has a ray that misses the laser plane: Yu + f tan(theta) = " << plane / (s * s)
      << " mm <= 0, so it has no measurement";
  throw std::invalid_argument(msg.str());
}

[[noreturn]] void ThrowGrazing(Eigen::Index i, double u, double v, double sine, double min_sine) {
  std::ostringstream msg;
  msg << "pixel " << i << " (u=" << u << ", v=" << v
      << ") has a ray that meets the laser plane at a grazing angle of "
      << std::asin(std::min(1.0, sine)) * 180.0 / M_PI << " deg (< "
      << std::asin(min_sine) * 180.0 / M_PI
      << " deg), too far away to be measured; it has no measurement";
  throw std::invalid_argument(msg.str());
}

}  // namespace

const std::array<std::string, kNumParams>& ParamNames() {
  static const std::array<std::string, kNumParams> names = {
      "f", "Su", "Sv", "Cu", "Cv", "k", "H", "theta", "omega", "phi", "varphi", "tx", "ty", "tz"};
  return names;
}

int ParamIndexFromName(const std::string& name) {
  const auto& names = ParamNames();
  for (int i = 0; i < kNumParams; ++i) {
    if (names[i] == name) return i;
  }
  std::ostringstream msg;
  msg << "'" << name << "' is not a parameter; the parameters are";
  for (const auto& n : names) msg << " " << n;
  throw std::invalid_argument(msg.str());
}

void ValidateParams(const Vector14d& q) {
  const auto& names = ParamNames();
  for (int i = 0; i < kNumParams; ++i) {
    if (!std::isfinite(q[i])) {
      throw std::invalid_argument("parameter " + names[i] + " is not finite");
    }
  }
  for (int i : {kF, kSu, kSv, kH}) {
    if (!(q[i] > 0.0)) {
      std::ostringstream msg;
      msg << "parameter " << names[i] << " must be > 0, got " << q[i];
      throw std::invalid_argument(msg.str());
    }
  }
  if (!(std::abs(q[kTheta]) < M_PI / 2)) {
    std::ostringstream msg;
    msg << "parameter theta must lie in (-pi/2, pi/2), got " << q[kTheta];
    throw std::invalid_argument(msg.str());
  }
}

double RayPlaneSine(const double* q, double cos_theta, double sin_theta, double u, double v) {
  double xd, yd;
  const double s = DistortedSensorPoint(q, u, v, &xd, &yd);
  const double xu = xd / s, yu = yd / s;
  return std::abs(yu * cos_theta + q[kF] * sin_theta) /
         std::sqrt(xu * xu + yu * yu + q[kF] * q[kF]);
}

namespace {

// Pixels -> points with a validity mask: `point_of(i, u, v, point)` writes pixel i's point and
// returns the laser-plane test (> 0 where the ray meets the plane in front of the camera).
template <typename PointOf>
PointsResult MapPixels(const Vector14d& q, PixelsRef pixels, bool throw_on_invalid,
                       double min_ray_sine, PointOf point_of) {
  const Eigen::Index m = pixels.rows();
  PointsResult out;
  out.points.resize(m, 3);
  out.valid.resize(m);
  const double cos_theta = std::cos(q[kTheta]), sin_theta = std::sin(q[kTheta]);
  for (Eigen::Index i = 0; i < m; ++i) {
    double point[3];
    const double u = pixels(i, 0), v = pixels(i, 1);
    const double plane = point_of(i, u, v, point);
    const double grazing = RayPlaneSine(q.data(), cos_theta, sin_theta, u, v);
    if (plane > 0.0 && grazing >= min_ray_sine) {
      out.points.row(i) << point[0], point[1], point[2];
      out.valid[i] = 1;
    } else {
      if (throw_on_invalid && plane > 0.0) ThrowGrazing(i, u, v, grazing, min_ray_sine);
      if (throw_on_invalid) ThrowMissedPlane(q, i, u, v, plane);
      out.points.row(i).setConstant(kNaN);
      out.valid[i] = 0;
      ++out.num_invalid;
    }
  }
  return out;
}

}  // namespace

PointsResult CameraPointsFromPixels(const Vector14d& q, PixelsRef pixels, bool throw_on_invalid,
                                    double min_ray_sine) {
  ValidateParams(q);
  RequireFinite(pixels.data(), pixels.rows(), 2, "pixels");
  const double tan_theta = std::tan(q[kTheta]);
  return MapPixels(q, pixels, throw_on_invalid, min_ray_sine,
                   [&](Eigen::Index, double u, double v, double* point) {
                     return PixelToCamera(q.data(), tan_theta, u, v, point);
                   });
}

PointsResult BasePointsFromPixels(const Vector14d& q, PixelsRef pixels, PosesRef poses,
                                  bool throw_on_invalid, double min_ray_sine) {
  RequireSameRows(pixels.rows(), "pixels", poses.rows(), "poses");
  geometry::ValidatePoses(poses);
  ValidateParams(q);
  RequireFinite(pixels.data(), pixels.rows(), 2, "pixels");
  const Eigen::Matrix3d hand_from_camera_rot = RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  const double tan_theta = std::tan(q[kTheta]);
  return MapPixels(q, pixels, throw_on_invalid, min_ray_sine,
                   [&](Eigen::Index i, double u, double v, double* point) {
                     return PixelToBase(q.data(), hand_from_camera_rot, tan_theta, u, v,
                                        PoseRotation(poses, i), PosePosition(poses, i), point);
                   });
}

RowMatX3 Residuals(const Vector14d& q, PixelsRef pixels, PosesRef poses, Points3Ref references) {
  RequireSameRows(pixels.rows(), "pixels", references.rows(), "reference points");
  RequireFinite(references.data(), references.rows(), 3, "reference points");
  const PointsResult base = BasePointsFromPixels(q, pixels, poses, /*throw_on_invalid=*/true);
  return references - base.points;
}

double Objective(const Vector14d& q, PixelsRef pixels, PosesRef poses, Points3Ref references) {
  RequireSameRows(pixels.rows(), "pixels", references.rows(), "reference points");
  const PointsResult base = BasePointsFromPixels(q, pixels, poses, /*throw_on_invalid=*/false);
  if (base.num_invalid > 0) return std::numeric_limits<double>::infinity();
  return 0.5 * (references - base.points).squaredNorm();
}

RowMatX3 CameraRaysFromPixels(const Vector14d& q, PixelsRef pixels) {
  ValidateParams(q);
  RequireFinite(pixels.data(), pixels.rows(), 2, "pixels");
  RowMatX3 rays(pixels.rows(), 3);
  for (Eigen::Index i = 0; i < pixels.rows(); ++i) {
    double xd, yd;
    const double s = DistortedSensorPoint(q.data(), pixels(i, 0), pixels(i, 1), &xd, &yd);
    rays.row(i) << xd / s, yd / s, q[kF];  // (Xu, Yu, f)
  }
  return rays;
}

Eigen::Matrix4d HandFromCamera(const Vector14d& q) {
  return geometry::Transform(RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]),
                             Eigen::Vector3d(q[kTx], q[kTy], q[kTz]));
}

PixelsResult PixelsFromCameraPoints(const Vector14d& q, Points3Ref camera_points) {
  ValidateParams(q);
  RequireFinite(camera_points.data(), camera_points.rows(), 3, "camera points");
  const Eigen::Index m = camera_points.rows();
  PixelsResult out;
  out.pixels.resize(m, 2);
  out.valid.resize(m);
  const double f = q[kF], k = q[kK];
  for (Eigen::Index i = 0; i < m; ++i) {
    const double z = camera_points(i, 2);
    bool ok = z > 0.0;
    double xd = 0.0, yd = 0.0;
    if (ok) {
      const double xu = f * camera_points(i, 0) / z;
      const double yu = f * camera_points(i, 1) / z;
      const double ru = std::hypot(xu, yu);
      // Division model: ru = rd / (1 + k rd^2)  =>  k ru rd^2 - rd + ru = 0; take the root that
      // tends to rd = ru as k -> 0: rd = 2 ru / (1 + sqrt(1 - 4 k ru^2)).
      const double disc = 1.0 - 4.0 * k * ru * ru;
      if (disc < 0.0) {
        ok = false;
      } else {
        const double scale = 2.0 / (1.0 + std::sqrt(disc));  // rd / ru
        xd = xu * scale;
        yd = yu * scale;
      }
    }
    if (ok) {
      out.pixels(i, 0) = xd / q[kSu] + q[kCu];
      out.pixels(i, 1) = yd / q[kSv] + q[kCv];
      out.valid[i] = 1;
    } else {
      out.pixels.row(i).setConstant(kNaN);
      out.valid[i] = 0;
      ++out.num_invalid;
    }
  }
  return out;
}

namespace {

RowMatX3 CameraFromBase(const Vector14d& q, Points3Ref base_points, PosesRef poses) {
  RequireSameRows(base_points.rows(), "points", poses.rows(), "poses");
  RequireFinite(base_points.data(), base_points.rows(), 3, "points");
  geometry::ValidatePoses(poses);
  const Eigen::Matrix4d hfc = HandFromCamera(q);
  const Eigen::Matrix3d rc = hfc.topLeftCorner<3, 3>();
  const Eigen::Vector3d tc = hfc.topRightCorner<3, 1>();
  RowMatX3 cam(base_points.rows(), 3);
  for (Eigen::Index i = 0; i < base_points.rows(); ++i) {
    const Eigen::Vector3d hand = PoseRotation(poses, i).transpose() *
                                 (base_points.row(i).transpose() - PosePosition(poses, i));
    cam.row(i) = (rc.transpose() * (hand - tc)).transpose();
  }
  return cam;
}

// Signed distances (mm) of camera-frame points from the laser plane y + z tan(theta) = H.
Eigen::VectorXd PlaneDistances(const Vector14d& q, const RowMatX3& cam) {
  const double t = std::tan(q[kTheta]);
  const double norm = std::sqrt(1.0 + t * t);
  Eigen::VectorXd d(cam.rows());
  for (Eigen::Index i = 0; i < cam.rows(); ++i) {
    d[i] = (cam(i, 1) + cam(i, 2) * t - q[kH]) / norm;
  }
  return d;
}

}  // namespace

Eigen::VectorXd LaserPlaneDistance(const Vector14d& q, Points3Ref base_points, PosesRef poses) {
  ValidateParams(q);
  return PlaneDistances(q, CameraFromBase(q, base_points, poses));
}

PixelsResult PixelsFromBasePoints(const Vector14d& q, Points3Ref base_points, PosesRef poses,
                                  double plane_tolerance) {
  ValidateParams(q);
  if (!(plane_tolerance >= 0.0)) {
    throw std::invalid_argument("plane_tolerance must be >= 0");
  }
  const RowMatX3 cam = CameraFromBase(q, base_points, poses);
  PixelsResult out = PixelsFromCameraPoints(q, cam);
  if (std::isfinite(plane_tolerance)) {
    const Eigen::VectorXd d = PlaneDistances(q, cam);
    for (Eigen::Index i = 0; i < cam.rows(); ++i) {
      if (out.valid[i] && std::abs(d[i]) > plane_tolerance) {
        out.valid[i] = 0;
        out.pixels.row(i).setConstant(kNaN);
        ++out.num_invalid;
      }
    }
  }
  return out;
}

}  // namespace hmlvs::paper
