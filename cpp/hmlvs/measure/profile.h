// A camera frame measured (hmlvs.Measurer, one call per frame): the stripe's centre on every
// scan line (image column) mapped through a calibrated sensor of either model to its point in
// the camera frame and in the robot base frame, and what became of each scan line.
//
// The point of a pixel is its model's own (paper::PixelToCamera with measurement's check of
// grazing rays, opencv::LaserPoint), so a profile holds the camera points of the models'
// batch functions (paper::CameraPointsFromPixels, opencv::LaserPointsInCamera) to the bit.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "hmlvs/image/frames.h"
#include "hmlvs/image/image.h"
#include "hmlvs/model/arrays.h"
#include "hmlvs/model/opencv.h"
#include "hmlvs/model/paper.h"

namespace hmlvs {

/// What a scan line of a measured frame gave (hmlvs.measurement.measurer.PointStatus).
enum class PointStatus : std::uint8_t {
  kMeasured = 0,  // a stripe centre, mapped to a 3D point
  kNoStripe = 1,  // no usable stripe centre on this scan line (see the stripe's status)
  kNoPoint = 2,   // a centre whose ray misses the laser plane (or meets it behind the camera)
};

/// A calibrated sensor of either model as measurement uses it: a stripe pixel to its point on
/// the laser plane in the camera frame, and the sensor's hand_from_camera transform. Read only
/// once built: one serves many threads.
class LaserSensor {
 public:
  /// The paper's model with parameters q (paper::ValidateParams): a pixel has a point when its
  /// ray meets the laser plane in front of the camera at 0.5 deg or more (kMinRaySine), as in
  /// paper::CameraPointsFromPixels(q, pixels, false, kMinRaySine).
  static LaserSensor Paper(const paper::Vector14d& q);

  /// The general model (opencv::ValidateIntrinsics, opencv::UnitPlane): a pixel has a point
  /// when it lies in the width x height image (u in [-0.5, width - 0.5], v likewise) and
  /// opencv::LaserPoint maps it. hand_from_camera must be finite.
  static LaserSensor OpenCv(const opencv::IntrinsicsVector& intrinsics,
                            const Eigen::Vector4d& laser_plane,
                            const Eigen::Matrix4d& hand_from_camera, int width, int height);

  /// Writes pixel (u, v)'s camera-frame point (mm) and returns true, or returns false when the
  /// pixel has none (`point` then meaningless).
  bool CameraPoint(double u, double v, double* point) const;

  const Eigen::Matrix4d& hand_from_camera() const { return hand_from_camera_; }

 private:
  LaserSensor() = default;

  bool paper_ = false;
  paper::Vector14d q_ = paper::Vector14d::Zero();
  double tan_theta_ = 0.0, cos_theta_ = 1.0, sin_theta_ = 0.0;
  opencv::IntrinsicsVector intrinsics_ = opencv::IntrinsicsVector::Zero();
  opencv::Untilt untilt_{intrinsics_.data()};
  Eigen::Vector4d unit_plane_ = Eigen::Vector4d::Zero();
  double width_ = 0.0, height_ = 0.0;
  Eigen::Matrix4d hand_from_camera_ = Eigen::Matrix4d::Identity();
};

/// One frame's measurement, one row per scan line (hmlvs.measurement.measurer.Profile).
struct FrameProfile {
  RowMatX2 pixels;         // the stripe centre (u, v) of the scan line, NaN where none
  RowMatX3 points;         // its point in the robot base frame (mm), NaN unless kMeasured
  RowMatX3 camera_points;  // the same point in the camera frame (mm), NaN unless kMeasured
  Mask status;             // PointStatus
  Mask stripe_status;      // the stripe's StripeStatus
};

/// A frame of `scan_lines` columns without a stripe: kNoStripe and StripeStatus::kNone
/// everywhere, every number NaN.
FrameProfile EmptyProfile(Eigen::Index scan_lines);

/// The stripe (scan lines along `direction`) measured at robot pose base_from_hand (4x4, mm):
/// every found centre, pixel (u, v) = (scan line, centre) (kColumns) or (centre, scan line)
/// (kRows), has its camera point c (LaserSensor::CameraPoint) and its base point
/// base_from_camera c, with base_from_camera = base_from_hand hand_from_camera, each product
/// summed left to right.
FrameProfile MeasureStripe(const LaserSensor& sensor, const StripeResult& stripe,
                           StripeDirection direction, const Eigen::Matrix4d& base_from_hand);

/// StripeFromFrames(on, off, options) without the residuals (a profile has none), then
/// MeasureStripe; when an automatic threshold leaves no pixel of the frame (no stripe),
/// EmptyProfile of the frame's scan lines.
template <typename T>
FrameProfile MeasureFrames(const ImageView<T>& on, const ImageView<T>& off,
                           const FrameStripeOptions& options, const LaserSensor& sensor,
                           const Eigen::Matrix4d& base_from_hand);

}  // namespace hmlvs
