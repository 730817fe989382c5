#include "hmlvs/model/opencv.h"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace hmlvs::opencv {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Distort and DistortionJacobian at once on doubles; without kWide the terms beyond the
// five-term lens are taken as 0 (the same values, for fewer operations).
template <bool kWide>
void DistortWithJacobian(const double* in, double x, double y, double* xd, double* yd, double* j) {
  const double r2 = x * x + y * y;
  const double num = 1.0 + r2 * (in[kK1] + r2 * (in[kK2] + r2 * in[kK3]));
  const double dnum = in[kK1] + r2 * (2.0 * in[kK2] + 3.0 * r2 * in[kK3]);  // d num / d r2
  double radial = num, dradial = dnum, sx = 0.0, sy = 0.0, dsx = 0.0, dsy = 0.0;
  if constexpr (kWide) {
    const double den = 1.0 + r2 * (in[kK4] + r2 * (in[kK5] + r2 * in[kK6]));
    const double dden = in[kK4] + r2 * (2.0 * in[kK5] + 3.0 * r2 * in[kK6]);
    radial = num / den;
    dradial = (dnum * den - num * dden) / (den * den);  // d radial / d r2
    sx = r2 * (in[kS1] + r2 * in[kS2]);
    sy = r2 * (in[kS3] + r2 * in[kS4]);
    dsx = in[kS1] + 2.0 * r2 * in[kS2];  // d sx / d r2
    dsy = in[kS3] + 2.0 * r2 * in[kS4];
  }
  *xd = x * radial + 2.0 * in[kP1] * x * y + in[kP2] * (r2 + 2.0 * x * x) + sx;
  *yd = y * radial + in[kP1] * (r2 + 2.0 * y * y) + 2.0 * in[kP2] * x * y + sy;
  j[0] = radial + 2.0 * x * (x * dradial + dsx) + 2.0 * in[kP1] * y + 6.0 * in[kP2] * x;
  j[1] = 2.0 * y * (x * dradial + dsx) + 2.0 * in[kP1] * x + 2.0 * in[kP2] * y;
  j[2] = 2.0 * x * (y * dradial + dsy) + 2.0 * in[kP1] * x + 2.0 * in[kP2] * y;
  j[3] = radial + 2.0 * y * (y * dradial + dsy) + 6.0 * in[kP1] * y + 2.0 * in[kP2] * x;
}

// Newton's method on distort(x, y) = (mx, my) from (mx, my) itself.
template <bool kWide>
bool Undistort(const double* in, double mx, double my, double* x, double* y, double* jacobian) {
  double px = mx, py = my;
  double j[4], xd, yd;
  bool converged = false;
  for (int iter = 0; iter < 50; ++iter) {
    DistortWithJacobian<kWide>(in, px, py, &xd, &yd, j);
    const double ex = xd - mx, ey = yd - my;
    const double det = j[0] * j[3] - j[1] * j[2];
    if (!(det > 1e-12)) return false;  // folded over: beyond the invertible region
    const double dx = (j[3] * ex - j[1] * ey) / det;
    const double dy = (-j[2] * ex + j[0] * ey) / det;
    px -= dx;
    py -= dy;
    if (std::abs(dx) + std::abs(dy) < 1e-14 * (1.0 + std::abs(px) + std::abs(py))) {
      converged = true;
      break;
    }
  }
  DistortWithJacobian<kWide>(in, px, py, &xd, &yd, j);
  converged = converged || (std::abs(xd - mx) + std::abs(yd - my) < 1e-12);
  if (!converged || !std::isfinite(px) || !std::isfinite(py)) return false;
  if (!(j[0] * j[3] - j[1] * j[2] > 1e-12)) return false;
  *x = px;
  *y = py;
  if (jacobian != nullptr) {
    for (int k = 0; k < 4; ++k) jacobian[k] = j[k];
  }
  return true;
}

}  // namespace

Untilt::Untilt(const double* in) : upright(in[kTauX] == 0.0 && in[kTauY] == 0.0) {
  if (!upright) TiltHomography(in[kTauX], in[kTauY], true, h);
}

bool UndistortNormalized(const double* in, double u, double v, double* x, double* y,
                         double* jacobian, const Untilt* untilt) {
  if (untilt == nullptr) {
    const Untilt own(in);
    return UndistortNormalized(in, u, v, x, y, jacobian, &own);
  }
  double mx, my;
  DistortedTarget(in, untilt->upright ? nullptr : untilt->h, u, v, &mx, &my);
  for (int k = kNumClassicIntrinsics; k < kTauX; ++k) {
    if (in[k] != 0.0) return Undistort<true>(in, mx, my, x, y, jacobian);
  }
  return Undistort<false>(in, mx, my, x, y, jacobian);
}

void ValidateIntrinsics(const IntrinsicsVector& in) {
  for (int i = 0; i < kNumIntrinsics; ++i) {
    if (!std::isfinite(in[i])) {
      throw std::invalid_argument(std::string("intrinsic ") + kIntrinsicNames[i] +
                                  " is not finite");
    }
  }
  if (!(in[kFx] > 0.0) || !(in[kFy] > 0.0)) {
    std::ostringstream msg;
    msg << "the focal lengths must be > 0, got fx = " << in[kFx] << ", fy = " << in[kFy];
    throw std::invalid_argument(msg.str());
  }
}

Eigen::Vector4d UnitPlane(const Eigen::Vector4d& plane) {
  const double n = plane.head<3>().norm();
  if (!std::isfinite(n) || !(n > 0.0) || !std::isfinite(plane[3])) {
    throw std::invalid_argument("the laser plane (a, b, c, d) needs a finite, non-zero normal");
  }
  return plane / n;
}

namespace {

// Pixels of `rows` inputs with a validity mask: `pixel_of(i, pixel)` writes input i's two
// numbers and says whether they are valid; invalid rows hold NaN.
template <typename PixelOf>
PixelsResult MapToPixels(Eigen::Index rows, PixelOf pixel_of) {
  PixelsResult out;
  out.pixels.resize(rows, 2);
  out.valid.resize(rows);
  for (Eigen::Index i = 0; i < rows; ++i) {
    double px[2];
    const bool ok = pixel_of(i, px);
    out.valid[i] = ok ? 1 : 0;
    if (ok) {
      out.pixels.row(i) << px[0], px[1];
    } else {
      out.pixels.row(i).setConstant(kNaN);
      ++out.num_invalid;
    }
  }
  return out;
}

}  // namespace

PixelsResult ProjectCameraPoints(const IntrinsicsVector& in, Points3Ref points) {
  ValidateIntrinsics(in);
  RequireFinite(points.data(), points.rows(), 3, "camera points");
  // a five-term lens on an upright sensor reads none of the other terms (as UndistortNormalized)
  if (in.tail<kNumIntrinsics - kNumClassicIntrinsics>().isZero(0.0)) {
    return MapToPixels(points.rows(), [&](Eigen::Index i, double* px) {
      return ProjectPoint<false>(in.data(), points.row(i).data(), px);
    });
  }
  double tilt[9];  // once for all points
  TiltHomography(in[kTauX], in[kTauY], false, tilt);
  return MapToPixels(points.rows(), [&](Eigen::Index i, double* px) {
    return ProjectPoint(in.data(), points.row(i).data(), px, tilt);
  });
}

PixelsResult UndistortPixels(const IntrinsicsVector& in, PixelsRef pixels) {
  ValidateIntrinsics(in);
  RequireFinite(pixels.data(), pixels.rows(), 2, "pixels");
  const Untilt untilt(in.data());
  return MapToPixels(pixels.rows(), [&](Eigen::Index i, double* xy) {
    return UndistortNormalized(in.data(), pixels(i, 0), pixels(i, 1), &xy[0], &xy[1], nullptr,
                               &untilt);
  });
}

bool LaserPoint(const IntrinsicsVector& in, const Eigen::Vector4d& plane, double u, double v,
                double* point, const char** why, const Untilt* untilt) {
  double x, y;
  if (!UndistortNormalized(in.data(), u, v, &x, &y, nullptr, untilt)) {
    *why = "lies beyond the region where the lens distortion can be inverted";
    return false;
  }
  const double normal[3] = {plane[0], plane[1], plane[2]};
  const double depth = RayPlanePoint(x, y, normal, plane[3], point);
  if (!(depth > 0.0) || !std::isfinite(depth)) {
    *why = "has a ray that misses the laser plane (it meets it behind the camera or not at all)";
    return false;
  }
  const double sine = std::abs(normal[0] * x + normal[1] * y + normal[2]) /
                      std::sqrt(x * x + y * y + 1.0);  // |normal| = 1 (UnitPlane)
  if (sine < kMinRaySine) {
    *why =
        "has a ray that meets the laser plane at a grazing angle (< 0.5 deg), too far away "
        "to be measured";
    return false;
  }
  return true;
}

namespace {

template <typename ToOutput>
PointsResult MapLaserPixels(const IntrinsicsVector& in, const Eigen::Vector4d& laser_plane,
                            PixelsRef pixels, bool throw_on_invalid, ToOutput to_output) {
  ValidateIntrinsics(in);
  RequireFinite(pixels.data(), pixels.rows(), 2, "pixels");
  const Eigen::Vector4d plane = UnitPlane(laser_plane);
  const Untilt untilt(in.data());
  PointsResult out;
  out.points.resize(pixels.rows(), 3);
  out.valid.resize(pixels.rows());
  for (Eigen::Index i = 0; i < pixels.rows(); ++i) {
    double p[3];
    const char* why = "";
    if (LaserPoint(in, plane, pixels(i, 0), pixels(i, 1), p, &why, &untilt)) {
      out.points.row(i) = to_output(i, Eigen::Vector3d(p[0], p[1], p[2]));
      out.valid[i] = 1;
    } else {
      if (throw_on_invalid) {
        std::ostringstream msg;
        msg << "pixel " << i << " (u=" << pixels(i, 0) << ", v=" << pixels(i, 1) << ") " << why
            << ", so it has no measurement";
        throw std::invalid_argument(msg.str());
      }
      out.points.row(i).setConstant(kNaN);
      out.valid[i] = 0;
      ++out.num_invalid;
    }
  }
  return out;
}

}  // namespace

PointsResult LaserPointsInCamera(const IntrinsicsVector& in, const Eigen::Vector4d& laser_plane,
                                 PixelsRef pixels, bool throw_on_invalid) {
  return MapLaserPixels(in, laser_plane, pixels, throw_on_invalid,
                        [](Eigen::Index, const Eigen::Vector3d& p) { return p; });
}

PointsResult LaserPointsInBase(const IntrinsicsVector& in, const Eigen::Vector4d& laser_plane,
                               const Eigen::Matrix4d& hand_from_camera, PixelsRef pixels,
                               PosesRef base_from_hand, bool throw_on_invalid) {
  RequireSameRows(pixels.rows(), "pixels", base_from_hand.rows(), "poses");
  geometry::ValidatePoses(base_from_hand);
  const Eigen::Matrix3d r_hc = hand_from_camera.topLeftCorner<3, 3>();
  const Eigen::Vector3d t_hc = hand_from_camera.topRightCorner<3, 1>();
  return MapLaserPixels(
      in, laser_plane, pixels, throw_on_invalid, [&](Eigen::Index i, const Eigen::Vector3d& p) {
        return Eigen::Vector3d(geometry::PoseRotation(base_from_hand, i) * (r_hc * p + t_hc) +
                               geometry::PosePosition(base_from_hand, i));
      });
}

}  // namespace hmlvs::opencv
