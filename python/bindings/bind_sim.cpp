// Simulator bindings: the board's shading for the image renderer.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>
#include <tuple>

#include "bindings.h"
#include "hmlvs/sim/render.h"

namespace py = pybind11;

namespace hmlvs::python {

void BindSim(py::module_& m) {
  py::class_<BoardShading>(m, "_BoardShading")
      .def(py::init<>())
      .def_readwrite("supersample", &BoardShading::supersample)
      .def_readwrite("rows", &BoardShading::rows)
      .def_readwrite("cols", &BoardShading::cols)
      .def_readwrite("square", &BoardShading::square)
      .def_readwrite("margin", &BoardShading::margin)
      .def_readwrite("white", &BoardShading::white)
      .def_readwrite("black", &BoardShading::black)
      .def_readwrite("table", &BoardShading::table)
      .def_readwrite("ambient", &BoardShading::ambient)
      .def_readwrite("laser", &BoardShading::laser)
      .def_readwrite("stripe_sigma", &BoardShading::stripe_sigma)
      .def_readwrite("spurious", &BoardShading::spurious)
      .def_readwrite("spurious_offset", &BoardShading::spurious_offset)
      .def_readwrite("spurious_lo", &BoardShading::spurious_lo)
      .def_readwrite("spurious_hi", &BoardShading::spurious_hi);
  m.def(
      "_shade_board",
      [](const py::array_t<double, py::array::c_style | py::array::forcecast>& rays,
         const Eigen::Matrix4d& board_from_camera, const Eigen::Vector4d& plane,
         const BoardShading& shading) {
        if (rays.ndim() != 3 || rays.shape(2) != 3) {
          throw std::invalid_argument(
              "rays must be a (rows, cols, 3) array of camera-frame rays, got " +
              std::to_string(rays.ndim()) + " dimensions");
        }
        const double* data = rays.data();
        const int rows = static_cast<int>(rays.shape(0));
        const int cols = static_cast<int>(rays.shape(1));
        BoardExposure e;
        {
          py::gil_scoped_release release;
          e = ShadeBoard(data, rows, cols, board_from_camera, plane, shading);
        }
        return std::make_tuple(std::move(e.ambient), std::move(e.laser), std::move(e.distance));
      },
      py::arg("rays"), py::arg("board_from_camera"), py::arg("plane"), py::arg("shading"));
}

}  // namespace hmlvs::python
