#include "hmlvs/measure/profile.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

namespace hmlvs {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// a b for rigid transforms (last rows 0 0 0 1), each entry summed left to right over k.
Eigen::Matrix4d Compose(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) {
  Eigen::Matrix4d out;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      out(i, j) = a(i, 0) * b(0, j) + a(i, 1) * b(1, j) + a(i, 2) * b(2, j) + a(i, 3) * b(3, j);
    }
  }
  return out;
}

}  // namespace

LaserSensor LaserSensor::Paper(const paper::Vector14d& q) {
  paper::ValidateParams(q);
  LaserSensor s;
  s.paper_ = true;
  s.q_ = q;
  s.tan_theta_ = std::tan(q[paper::kTheta]);
  s.cos_theta_ = std::cos(q[paper::kTheta]);
  s.sin_theta_ = std::sin(q[paper::kTheta]);
  s.hand_from_camera_ = paper::HandFromCamera(q);
  return s;
}

LaserSensor LaserSensor::OpenCv(const opencv::IntrinsicsVector& intrinsics,
                                const Eigen::Vector4d& laser_plane,
                                const Eigen::Matrix4d& hand_from_camera, int width, int height) {
  opencv::ValidateIntrinsics(intrinsics);
  if (!hand_from_camera.allFinite()) {
    throw std::invalid_argument("hand_from_camera must be a finite 4 x 4 transform");
  }
  if (width <= 0 || height <= 0) {
    throw std::invalid_argument("the image size must be positive");
  }
  LaserSensor s;
  s.intrinsics_ = intrinsics;
  s.untilt_ = opencv::Untilt(intrinsics.data());
  s.unit_plane_ = opencv::UnitPlane(laser_plane);
  s.width_ = width;
  s.height_ = height;
  s.hand_from_camera_ = hand_from_camera;
  return s;
}

bool LaserSensor::CameraPoint(double u, double v, double* point) const {
  if (paper_) {
    const double plane = paper::PixelToCamera(q_.data(), tan_theta_, u, v, point);
    return plane > 0.0 &&
           paper::RayPlaneSine(q_.data(), cos_theta_, sin_theta_, u, v) >= kMinRaySine;
  }
  const bool inside = u >= -0.5 && u <= width_ - 0.5 && v >= -0.5 && v <= height_ - 0.5;
  const char* why = "";
  return inside && opencv::LaserPoint(intrinsics_, unit_plane_, u, v, point, &why, &untilt_);
}

FrameProfile EmptyProfile(Eigen::Index scan_lines) {
  FrameProfile out;
  out.pixels.setConstant(scan_lines, 2, kNaN);
  out.points.setConstant(scan_lines, 3, kNaN);
  out.camera_points.setConstant(scan_lines, 3, kNaN);
  out.status.setConstant(scan_lines, static_cast<std::uint8_t>(PointStatus::kNoStripe));
  out.stripe_status.setConstant(scan_lines, static_cast<std::uint8_t>(StripeStatus::kNone));
  return out;
}

FrameProfile MeasureStripe(const LaserSensor& sensor, const StripeResult& stripe,
                           StripeDirection direction, const Eigen::Matrix4d& base_from_hand) {
  const bool rows = direction == StripeDirection::kRows;
  const Eigen::Index n = stripe.status.size();
  if (stripe.centre.size() != n) {
    throw std::invalid_argument("the stripe's centre and status differ in length");
  }
  FrameProfile out = EmptyProfile(n);
  out.stripe_status = stripe.status;
  const Eigen::Matrix4d bfc = Compose(base_from_hand, sensor.hand_from_camera());
  const auto found = static_cast<std::uint8_t>(StripeStatus::kFound);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (stripe.status[i] != found) continue;
    const double line = static_cast<double>(i);
    const double u = rows ? stripe.centre[i] : line, v = rows ? line : stripe.centre[i];
    out.pixels(i, 0) = u;
    out.pixels(i, 1) = v;
    double c[3];
    if (!sensor.CameraPoint(u, v, c)) {
      out.status[i] = static_cast<std::uint8_t>(PointStatus::kNoPoint);
      continue;
    }
    out.status[i] = static_cast<std::uint8_t>(PointStatus::kMeasured);
    for (int k = 0; k < 3; ++k) {
      out.camera_points(i, k) = c[k];
      out.points(i, k) = bfc(k, 0) * c[0] + bfc(k, 1) * c[1] + bfc(k, 2) * c[2] + bfc(k, 3);
    }
  }
  return out;
}

template <typename T>
FrameProfile MeasureFrames(const ImageView<T>& on, const ImageView<T>& off,
                           const FrameStripeOptions& options, const LaserSensor& sensor,
                           const Eigen::Matrix4d& base_from_hand) {
  FrameStripeOptions o = options;
  o.residual = false;  // a profile has none
  const FrameStripe r = StripeFromFrames(on, off, o);
  if (r.no_pixel) {
    return EmptyProfile(options.stripe.direction == StripeDirection::kRows ? on.rows : on.cols);
  }
  return MeasureStripe(sensor, r.stripe, options.stripe.direction, base_from_hand);
}

template FrameProfile MeasureFrames(const ImageView<std::uint8_t>&, const ImageView<std::uint8_t>&,
                                    const FrameStripeOptions&, const LaserSensor&,
                                    const Eigen::Matrix4d&);
template FrameProfile MeasureFrames(const ImageView<std::uint16_t>&,
                                    const ImageView<std::uint16_t>&, const FrameStripeOptions&,
                                    const LaserSensor&, const Eigen::Matrix4d&);

}  // namespace hmlvs
