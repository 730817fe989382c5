// Numpy images as the core's ImageView (read in place, any strides), shared by the image and
// the measurement bindings.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>

#include "hmlvs/image/image.h"

namespace hmlvs::python {

enum class Depth { kU8, kU16 };

inline Depth DepthOf(const pybind11::array& a, const char* name) {
  namespace py = pybind11;
  if (py::isinstance<py::array_t<std::uint8_t>>(a)) return Depth::kU8;
  if (py::isinstance<py::array_t<std::uint16_t>>(a)) return Depth::kU16;
  std::ostringstream msg;
  msg << name << " must be an 8- or 16-bit grayscale image (uint8 or uint16), got dtype "
      << std::string(py::str(a.dtype()));
  throw std::invalid_argument(msg.str());
}

template <typename T>
ImageView<T> ViewOf(const pybind11::array& a, const char* name) {
  if (a.ndim() != 2) {
    std::ostringstream msg;
    msg << name << " must be a 2D (rows x cols) grayscale array, got " << a.ndim() << " dimensions";
    throw std::invalid_argument(msg.str());
  }
  const auto item = static_cast<pybind11::ssize_t>(sizeof(T));
  if (a.strides(0) % item != 0 || a.strides(1) % item != 0) {
    throw std::invalid_argument(std::string(name) +
                                " has strides that are not a multiple of "
                                "its pixel size");
  }
  ImageView<T> v;
  v.data = static_cast<const T*>(a.data());
  v.rows = static_cast<int>(a.shape(0));
  v.cols = static_cast<int>(a.shape(1));
  v.row_stride = a.strides(0) / item;
  v.col_stride = a.strides(1) / item;
  return v;
}

/// ViewOf an image that may be None (then a view without data).
template <typename T>
ImageView<T> OptionalViewOf(const pybind11::object& a, const char* name) {
  return a.is_none() ? ImageView<T>() : ViewOf<T>(a.cast<pybind11::array>(), name);
}

/// The frames' common bit depth (the laser-off frame may be None).
inline Depth FramesDepth(const pybind11::array& on, const pybind11::object& off) {
  namespace py = pybind11;
  const Depth d = DepthOf(on, "the laser-on image");
  if (!off.is_none() && DepthOf(off.cast<py::array>(), "the laser-off image") != d) {
    throw std::invalid_argument("the laser-on and laser-off images have different bit depths (" +
                                std::string(py::str(on.dtype())) + " and " +
                                std::string(py::str(off.attr("dtype"))) + ")");
  }
  return d;
}

}  // namespace hmlvs::python
