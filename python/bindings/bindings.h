#pragma once

#include <pybind11/pybind11.h>

namespace hmlvs::python {

void BindModel(pybind11::module_& m);
void BindKinematics(pybind11::module_& m);
void BindSolvers(pybind11::module_& m);
void BindImage(pybind11::module_& m);
void BindGeneral(pybind11::module_& m);
void BindSim(pybind11::module_& m);
void BindMeasure(pybind11::module_& m);

}  // namespace hmlvs::python
