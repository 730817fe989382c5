// The general sensor model (model "opencv") and its joint calibration.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <utility>
#include <vector>

#include "bindings.h"
#include "hmlvs/geometry/hand_eye.h"
#include "hmlvs/model/opencv.h"
#include "hmlvs/solvers/joint.h"

namespace py = pybind11;

namespace hmlvs::python {

void BindGeneral(py::module_& m) {
  using namespace hmlvs::opencv;
  using namespace hmlvs::solvers;
  const auto release = py::call_guard<py::gil_scoped_release>();
  m.def("_general_project", &ProjectCameraPoints, py::arg("intrinsics"), py::arg("points"),
        release);
  m.def("_general_undistort", &UndistortPixels, py::arg("intrinsics"), py::arg("pixels"), release);
  m.def("_general_laser_camera", &LaserPointsInCamera, py::arg("intrinsics"),
        py::arg("laser_plane"), py::arg("pixels"), py::arg("throw_on_invalid"), release);
  m.def("_general_laser_base", &LaserPointsInBase, py::arg("intrinsics"), py::arg("laser_plane"),
        py::arg("hand_from_camera"), py::arg("pixels"), py::arg("poses"),
        py::arg("throw_on_invalid"), release);

  py::class_<JointView>(m, "_JointView")
      .def(py::init([](const Eigen::Matrix4d& base_from_hand, const RowMatX2& corner_pixels,
                       const RowMatX3& corner_points, const RowMatX2& laser_pixels) {
             return JointView{base_from_hand, corner_pixels, corner_points, laser_pixels};
           }),
           py::arg("base_from_hand"), py::arg("corner_pixels"), py::arg("corner_points"),
           py::arg("laser_pixels"))
      .def_readonly("base_from_hand", &JointView::base_from_hand)
      .def_readonly("corner_pixels", &JointView::corner_pixels)
      .def_readonly("corner_points", &JointView::corner_points)
      .def_readonly("laser_pixels", &JointView::laser_pixels);
  py::class_<JointState>(m, "_JointState")
      .def(py::init<>())
      .def_readwrite("intrinsics", &JointState::intrinsics)
      .def_readwrite("laser_plane", &JointState::laser_plane)
      .def_readwrite("hand_from_camera", &JointState::hand_from_camera)
      .def_readwrite("base_from_board", &JointState::base_from_board)
      .def_readwrite("camera_from_board", &JointState::camera_from_board);
  py::class_<JointOptions>(m, "_JointOptions")
      .def(py::init<>())
      .def_readwrite("chain", &JointOptions::chain)
      .def_readwrite("board_pose_known", &JointOptions::board_pose_known)
      .def_readwrite("hand_eye_known", &JointOptions::hand_eye_known)
      .def_readwrite("laser", &JointOptions::laser)
      .def_readwrite("plane_known", &JointOptions::plane_known)
      .def_readwrite("pose_sigma_t", &JointOptions::pose_sigma_t)
      .def_readwrite("pose_sigma_r", &JointOptions::pose_sigma_r)
      .def_readwrite("fixed", &JointOptions::fixed)
      .def_readwrite("corner_sigma", &JointOptions::corner_sigma)
      .def_readwrite("laser_sigma", &JointOptions::laser_sigma)
      .def_readwrite("loss", &JointOptions::loss)
      .def_readwrite("loss_scale", &JointOptions::loss_scale)
      .def_readwrite("max_iterations", &JointOptions::max_iterations)
      .def_readwrite("function_tolerance", &JointOptions::function_tolerance)
      .def_readwrite("parameter_tolerance", &JointOptions::parameter_tolerance)
      .def_readwrite("gradient_tolerance", &JointOptions::gradient_tolerance);
  // _SolveSummary: bound by BindSolvers, which runs first (main.cpp)
  py::class_<JointResult, SolveSummary>(m, "_JointResult")
      .def_readonly("state", &JointResult::state);
  m.def("_solve_joint", &SolveJoint, py::arg("views"), py::arg("initial"), py::arg("options"),
        release);
  m.def(
      "_evaluate_joint",
      [](const std::vector<JointView>& views, const JointState& state, const JointOptions& o) {
        JointResiduals r = EvaluateJoint(views, state, o);
        return std::make_pair(std::move(r.corners), std::move(r.laser));
      },
      py::arg("views"), py::arg("state"), py::arg("options"), release);
  m.def(
      "_joint_pose_errors",
      [](const std::vector<JointView>& views, const JointState& state, const JointOptions& o) {
        return EvaluateJoint(views, state, o).pose;
      },
      py::arg("views"), py::arg("state"), py::arg("options"), release);
  m.def(
      "_joint_jacobian",
      [](const std::vector<JointView>& views, const JointState& state, const JointOptions& o) {
        std::vector<std::string> names;
        Eigen::MatrixXd j = JointJacobian(views, state, o, &names);
        return std::make_pair(std::move(j), std::move(names));
      },
      py::arg("views"), py::arg("state"), py::arg("options"), release);
  m.def("_hand_eye_park_martin", &geometry::HandEyeParkMartin, py::arg("base_from_hand"),
        py::arg("camera_from_board"), py::arg("min_angle") = 0.05, release);
  m.def("_mean_transform", &geometry::MeanTransform, py::arg("transforms"), release);
}

}  // namespace hmlvs::python
