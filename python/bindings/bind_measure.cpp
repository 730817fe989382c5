// Measurement (hmlvs.Measurer): a frame's stripe through a calibrated sensor of either model to
// its points, one call per frame with the GIL released.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <utility>

#include "bindings.h"
#include "hmlvs/measure/profile.h"
#include "image_arrays.h"

namespace py = pybind11;

namespace hmlvs::python {

namespace {

// (pixels, points, camera_points, status, stripe_status), the arrays moved, not copied.
py::tuple ProfileTuple(FrameProfile&& p) {
  return py::make_tuple(std::move(p.pixels), std::move(p.points), std::move(p.camera_points),
                        std::move(p.status), std::move(p.stripe_status));
}

template <typename T>
FrameProfile Measure(const py::array& on, const py::object& off, const FrameStripeOptions& o,
                     const LaserSensor& sensor, const Eigen::Matrix4d& base_from_hand) {
  const ImageView<T> a = ViewOf<T>(on, "the laser-on image");
  const ImageView<T> b = OptionalViewOf<T>(off, "the laser-off image");
  py::gil_scoped_release release;
  return MeasureFrames(a, b, o, sensor, base_from_hand);
}

}  // namespace

void BindMeasure(py::module_& m) {
  py::class_<LaserSensor>(m, "_LaserSensor")
      .def_static("paper", &LaserSensor::Paper, py::arg("params"))
      .def_static("opencv", &LaserSensor::OpenCv, py::arg("intrinsics"), py::arg("laser_plane"),
                  py::arg("hand_from_camera"), py::arg("width"), py::arg("height"));
  m.def(
      "_measure_frames",
      [](const py::array& on, const py::object& off, const FrameStripeOptions& options,
         const LaserSensor& sensor, const Eigen::Matrix4d& base_from_hand) {
        return ProfileTuple(FramesDepth(on, off) == Depth::kU8
                                ? Measure<std::uint8_t>(on, off, options, sensor, base_from_hand)
                                : Measure<std::uint16_t>(on, off, options, sensor, base_from_hand));
      },
      py::arg("on"), py::arg("off"), py::arg("options"), py::arg("sensor"),
      py::arg("base_from_hand"));
  m.def(
      "_measure_stripe",
      [](const LaserSensor& sensor, const Eigen::VectorXd& centre, const Mask& status,
         StripeDirection direction, const Eigen::Matrix4d& base_from_hand) {
        StripeResult stripe;
        stripe.centre = centre;
        stripe.status = status;
        FrameProfile p;
        {
          py::gil_scoped_release release;
          p = MeasureStripe(sensor, stripe, direction, base_from_hand);
        }
        return ProfileTuple(std::move(p));
      },
      py::arg("sensor"), py::arg("centre"), py::arg("status"), py::arg("direction"),
      py::arg("base_from_hand"));
  m.def(
      "_empty_profile",
      [](Eigen::Index scan_lines) { return ProfileTuple(EmptyProfile(scan_lines)); },
      py::arg("scan_lines"));
}

}  // namespace hmlvs::python
