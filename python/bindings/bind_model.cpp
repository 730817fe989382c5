#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings.h"
#include "hmlvs/geometry/geometry.h"
#include "hmlvs/model/paper.h"
#include "hmlvs/model/paper_cost.h"

namespace py = pybind11;

namespace hmlvs::python {

void BindModel(py::module_& m) {
  using namespace hmlvs::paper;
  m.attr("NUM_PARAMS") = kNumParams;
  m.def("_param_names", &ParamNames);
  m.def("_param_index", &ParamIndexFromName, py::arg("name"));

  py::class_<PointsResult>(m, "_PointsResult")
      .def_readonly("points", &PointsResult::points)
      .def_readonly("valid", &PointsResult::valid)
      .def_readonly("num_invalid", &PointsResult::num_invalid);
  py::class_<PixelsResult>(m, "_PixelsResult")
      .def_readonly("pixels", &PixelsResult::pixels)
      .def_readonly("valid", &PixelsResult::valid)
      .def_readonly("num_invalid", &PixelsResult::num_invalid);

  const auto release = py::call_guard<py::gil_scoped_release>();
  m.def("_validate_params", &ValidateParams, py::arg("params"));
  m.def("_validate_poses", &geometry::ValidatePoses, py::arg("poses"), release);
  m.attr("RIGID_TOLERANCE") = geometry::kRigidTolerance;
  m.attr("MIN_RAY_SINE") = kMinRaySine;
  m.def("_camera_points", &CameraPointsFromPixels, py::arg("params"), py::arg("pixels"),
        py::arg("throw_on_invalid"), py::arg("min_ray_sine") = 0.0, release);
  m.def("_base_points", &BasePointsFromPixels, py::arg("params"), py::arg("pixels"),
        py::arg("poses"), py::arg("throw_on_invalid"), py::arg("min_ray_sine") = 0.0, release);
  m.def("_residuals", &Residuals, py::arg("params"), py::arg("pixels"), py::arg("poses"),
        py::arg("references"), release);
  m.def("_objective", &Objective, py::arg("params"), py::arg("pixels"), py::arg("poses"),
        py::arg("references"), release);
  m.def("_pixels_from_camera", &PixelsFromCameraPoints, py::arg("params"), py::arg("camera_points"),
        release);
  m.def("_pixels_from_base", &PixelsFromBasePoints, py::arg("params"), py::arg("points"),
        py::arg("poses"), py::arg("plane_tolerance"), release);
  m.def("_laser_plane_distance", &LaserPlaneDistance, py::arg("params"), py::arg("points"),
        py::arg("poses"), release);
  m.def(
      "_residual_jacobian",
      [](const Vector14d& q, PixelsRef pixels, PosesRef poses, Points3Ref references) {
        Eigen::VectorXd r;
        Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor> j;
        ResidualJacobian(q, pixels, poses, references, &r, &j);
        return std::make_pair(r, j);
      },
      py::arg("params"), py::arg("pixels"), py::arg("poses"), py::arg("references"), release);
  m.def("_camera_rays", &CameraRaysFromPixels, py::arg("params"), py::arg("pixels"), release);
  m.def("_hand_from_camera", &HandFromCamera, py::arg("params"));
}

}  // namespace hmlvs::python
