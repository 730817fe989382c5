#include <pybind11/pybind11.h>

#include "bindings.h"

namespace py = pybind11;

namespace hmlvs::python {

void BindImage(py::module_& /*m*/) {}

}  // namespace hmlvs::python
