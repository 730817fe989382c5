// Module entry of hmlvs._core: one Bind<Area> function per area, each in its own file.
#include <pybind11/pybind11.h>

#include "bindings.h"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() = "hmlvs C++ core: sensor model, kinematics, solvers and stripe extraction.";
#ifdef HMLVS_VERSION
  m.attr("__version__") = HMLVS_VERSION;
#endif
  hmlvs::python::BindModel(m);
  hmlvs::python::BindKinematics(m);
  hmlvs::python::BindSolvers(m);
  hmlvs::python::BindImage(m);
  hmlvs::python::BindGeneral(m);
  hmlvs::python::BindSim(m);
  hmlvs::python::BindMeasure(m);
}
