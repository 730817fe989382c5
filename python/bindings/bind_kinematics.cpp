#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <utility>

#include "bindings.h"
#include "hmlvs/geometry/kinematics.h"
#include "hmlvs/solvers/ik.h"

namespace py = pybind11;

namespace hmlvs::python {

void BindKinematics(py::module_& m) {
  using namespace hmlvs::geometry;
  using namespace hmlvs::solvers;
  py::enum_<DHConvention>(m, "_DHConvention")
      .value("standard", DHConvention::kStandard)
      .value("modified", DHConvention::kModified);
  py::class_<DHJoint>(m, "_DHJoint")
      .def(py::init<>())
      .def_readwrite("a", &DHJoint::a)
      .def_readwrite("alpha", &DHJoint::alpha)
      .def_readwrite("d", &DHJoint::d)
      .def_readwrite("theta", &DHJoint::theta)
      .def_readwrite("offset", &DHJoint::offset)
      .def_readwrite("prismatic", &DHJoint::prismatic);
  py::class_<DHRobot>(m, "_DHRobot")
      .def(py::init<>())
      .def_readwrite("joints", &DHRobot::joints)
      .def_readwrite("convention", &DHRobot::convention)
      .def_readwrite("base_from_link0", &DHRobot::base_from_link0)
      .def_readwrite("flange_from_hand", &DHRobot::flange_from_hand);
  m.def("_forward_kinematics", &ForwardKinematics, py::arg("robot"), py::arg("joints"),
        py::call_guard<py::gil_scoped_release>());
  m.def(
      "_solve_look_at",
      [](const DHRobot& robot, const Eigen::Matrix4d& hand_from_camera,
         const Eigen::Vector3d& position, const Eigen::Vector3d& axis,
         const std::optional<Eigen::Vector3d>& x, const Eigen::VectorXd& start,
         const Eigen::VectorXd& lower, const Eigen::VectorXd& upper, double max_step,
         int iterations) {
        LookAtTarget target;
        target.hand_from_camera = hand_from_camera;
        target.position = position;
        target.axis = axis;
        target.has_x = x.has_value();
        if (x) target.x = *x;
        LookAtOptions options;
        options.max_step = max_step;
        options.iterations = iterations;
        LookAtResult r = SolveLookAt(robot, target, start, lower, upper, options);
        return std::make_pair(std::move(r.joints), r.error);
      },
      py::arg("robot"), py::arg("hand_from_camera"), py::arg("position"), py::arg("axis"),
      py::arg("x"), py::arg("start"), py::arg("lower"), py::arg("upper"), py::arg("max_step"),
      py::arg("iterations"), py::call_guard<py::gil_scoped_release>());
}

}  // namespace hmlvs::python
