#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings.h"
#include "hmlvs/model/kinematics.h"

namespace py = pybind11;

namespace hmlvs::python {

void BindKinematics(py::module_& m) {
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
}

}  // namespace hmlvs::python
