// Image pipeline bindings: numpy buffers are read in place (any strides), the GIL is released
// while the core works.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <stdexcept>
#include <string>

#include "bindings.h"
#include "hmlvs/image/frames.h"
#include "hmlvs/image/image.h"
#include "image_arrays.h"

namespace py = pybind11;

namespace hmlvs::python {

namespace {

template <typename T>
py::array Difference(const py::array& on, const py::array& off, const DifferenceOptions& o) {
  const ImageView<T> a = ViewOf<T>(on, "the laser-on image");
  const ImageView<T> b = ViewOf<T>(off, "the laser-off image");
  py::array_t<T> out({static_cast<py::ssize_t>(a.rows), static_cast<py::ssize_t>(a.cols)});
  T* dst = out.mutable_data();
  {
    py::gil_scoped_release release;
    DifferenceImage(a, b, dst, o);
  }
  return std::move(out);
}

template <typename T>
StripeResult Extract(const py::array& image, const StripeOptions& options) {
  const ImageView<T> v = ViewOf<T>(image, "the image");
  py::gil_scoped_release release;
  return ExtractStripe(v, options);
}

template <typename T>
py::tuple FromFrames(const py::array& on, const py::object& off, const FrameStripeOptions& o,
                     bool want_background) {
  const ImageView<T> a = ViewOf<T>(on, "the laser-on image");
  const ImageView<T> b = OptionalViewOf<T>(off, "the laser-off image");
  py::object background = py::none();
  T* bg = nullptr;
  if (want_background && off.is_none()) {
    py::array_t<T> out({static_cast<py::ssize_t>(a.rows), static_cast<py::ssize_t>(a.cols)});
    bg = out.mutable_data();
    background = std::move(out);
  }
  FrameStripe r;
  {
    py::gil_scoped_release release;
    r = StripeFromFrames(a, b, o, bg);
  }
  return py::make_tuple(r.stripe, r.offset_fitted, r.albedo_offset, r.no_pixel, r.image_max,
                        r.refined, background);
}

// AssessStripe of a stripe's image and its frames (either may be None): the new statuses.
Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1> AssessFrames(
    const py::array& image, const py::object& on, const py::object& off, StripeDirection direction,
    const StripeQualityOptions& options, const Eigen::VectorXd& centre,
    const Eigen::VectorXd& width, const Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>& status,
    double threshold) {
  StripeResult out;
  out.centre = centre;
  out.width = width;
  out.status = status;
  out.threshold = threshold;
  const Depth d = DepthOf(image, "the image");
  for (const py::object* o : {&on, &off}) {
    if (!o->is_none() && DepthOf(o->cast<py::array>(), "a frame") != d) {
      throw std::invalid_argument("the frames and the stripe's image differ in bit depth");
    }
  }
  auto run = [&](auto tag) {
    using T = decltype(tag);
    const ImageView<T> v = ViewOf<T>(image, "the image");
    const ImageView<T> a = OptionalViewOf<T>(on, "the laser-on image");
    const ImageView<T> b = OptionalViewOf<T>(off, "the laser-off image");
    py::gil_scoped_release release;
    AssessStripe(v, a, b, direction, options, &out);
  };
  if (d == Depth::kU8) {
    run(std::uint8_t{});
  } else {
    run(std::uint16_t{});
  }
  return out.status;
}

void BindStripeTypes(py::module_& m) {
  py::enum_<StripeDirection>(m, "_StripeDirection")
      .value("columns", StripeDirection::kColumns)
      .value("rows", StripeDirection::kRows);
  py::enum_<StripeMethod>(m, "_StripeMethod")
      .value("centroid", StripeMethod::kCentroid)
      .value("gaussian", StripeMethod::kGaussian)
      .value("steger", StripeMethod::kSteger);
  py::class_<StripeOptions>(m, "_StripeOptions")
      .def(py::init<>())
      .def_readwrite("direction", &StripeOptions::direction)
      .def_readwrite("method", &StripeOptions::method)
      .def_readwrite("threshold", &StripeOptions::threshold)
      .def_readwrite("min_width", &StripeOptions::min_width)
      .def_readwrite("max_width", &StripeOptions::max_width)
      .def_readwrite("noise", &StripeOptions::noise)
      .def_readwrite("steger_sigma", &StripeOptions::steger_sigma)
      .def_readwrite("steger_sigma_along", &StripeOptions::steger_sigma_along)
      .def_readwrite("dominance", &StripeOptions::dominance)
      .def_readwrite("detect_sigma_along", &StripeOptions::detect_sigma_along);
  py::class_<StripeResult>(m, "_StripeResult")
      .def_readonly("centre", &StripeResult::centre)
      .def_readonly("intensity", &StripeResult::intensity)
      .def_readonly("width", &StripeResult::width)
      .def_readonly("sigma", &StripeResult::sigma)
      .def_readonly("status", &StripeResult::status)
      .def_readonly("num_peaks", &StripeResult::num_peaks)
      .def_readonly("residual", &StripeResult::residual)
      .def_readonly("threshold", &StripeResult::threshold)
      .def_readonly("noise", &StripeResult::noise);
}

void BindWholeImages(py::module_& m) {
  m.def(
      "_difference_image",
      [](const py::array& on, const py::array& off, bool normalize, double scale, double floor,
         double offset) -> py::array {
        DifferenceOptions o;
        o.normalize = normalize;
        o.scale = scale;
        o.floor = floor;
        o.offset = offset;
        const Depth d = DepthOf(on, "the laser-on image");
        if (DepthOf(off, "the laser-off image") != d) {
          throw std::invalid_argument(
              "the laser-on and laser-off images have different bit depths (" +
              std::string(py::str(on.dtype())) + " and " + std::string(py::str(off.dtype())) + ")");
        }
        return d == Depth::kU8 ? Difference<std::uint8_t>(on, off, o)
                               : Difference<std::uint16_t>(on, off, o);
      },
      py::arg("on"), py::arg("off"), py::arg("normalize") = false, py::arg("scale") = -1.0,
      py::arg("floor") = -1.0, py::arg("offset") = 0.0);
  m.def(
      "_column_peaks",
      [](const py::array& image, int half_width) {
        ColumnPeaks p;
        if (DepthOf(image, "the image") == Depth::kU8) {
          const auto v = ViewOf<std::uint8_t>(image, "the image");
          py::gil_scoped_release release;
          p = FindColumnPeaks(v, half_width);
        } else {
          const auto v = ViewOf<std::uint16_t>(image, "the image");
          py::gil_scoped_release release;
          p = FindColumnPeaks(v, half_width);
        }
        return py::make_tuple(p.row, p.sum);
      },
      py::arg("image"), py::arg("half_width"));
  m.def(
      "_extract_stripe",
      [](const py::array& image, const StripeOptions& options) {
        return DepthOf(image, "the image") == Depth::kU8 ? Extract<std::uint8_t>(image, options)
                                                         : Extract<std::uint16_t>(image, options);
      },
      py::arg("image"), py::arg("options"));
  m.def(
      "_estimate_difference_noise",
      [](const py::array& image) {
        if (DepthOf(image, "the image") == Depth::kU8) {
          const auto v = ViewOf<std::uint8_t>(image, "the image");
          py::gil_scoped_release release;
          return EstimateDifferenceNoise(v);
        }
        const auto v = ViewOf<std::uint16_t>(image, "the image");
        py::gil_scoped_release release;
        return EstimateDifferenceNoise(v);
      },
      py::arg("image"));
}

void BindQuality(py::module_& m) {
  py::class_<StripeQualityOptions>(m, "_StripeQualityOptions")
      .def(py::init<>())
      .def_readwrite("albedo_step", &StripeQualityOptions::albedo_step)
      .def_readwrite("albedo_offset", &StripeQualityOptions::albedo_offset)
      .def_readwrite("hump", &StripeQualityOptions::hump)
      .def_readwrite("dip", &StripeQualityOptions::dip);
  m.def("_assess_stripe", &AssessFrames, py::arg("image"), py::arg("on"), py::arg("off"),
        py::arg("direction"), py::arg("options"), py::arg("centre"), py::arg("width"),
        py::arg("status"), py::arg("threshold"));
  py::class_<StripeRefineOptions>(m, "_StripeRefineOptions")
      .def(py::init<>())
      .def_readwrite("speckle", &StripeRefineOptions::speckle)
      .def_readwrite("noise_floor", &StripeRefineOptions::noise_floor)
      .def_readwrite("max_iterations", &StripeRefineOptions::max_iterations)
      .def_readwrite("tolerance", &StripeRefineOptions::tolerance);
  m.def(
      "_refine_stripe",
      [](const py::array& image, StripeDirection direction, const Eigen::VectorXd& noise,
         const StripeRefineOptions& options, const Eigen::VectorXd& centre,
         const Eigen::VectorXd& width, const Eigen::VectorXd& sigma,
         const Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>& status) {
        if (!py::isinstance<py::array_t<float>>(image)) {
          throw std::invalid_argument("the image must be a float32 array");
        }
        StripeResult out;
        out.centre = centre;
        out.width = width;
        out.sigma = sigma;
        out.status = status;
        const ImageView<float> v = ViewOf<float>(image, "the image");
        {
          py::gil_scoped_release release;
          RefineStripeCentres(v, direction, noise, options, &out);
        }
        return py::make_tuple(out.centre, out.sigma, out.status);
      },
      py::arg("image"), py::arg("direction"), py::arg("noise"), py::arg("options"),
      py::arg("centre"), py::arg("width"), py::arg("sigma"), py::arg("status"));
}

void BindFrames(py::module_& m) {
  py::class_<FrameStripeOptions>(m, "_FrameStripeOptions")
      .def(py::init<>())
      .def_readwrite("stripe", &FrameStripeOptions::stripe)
      .def_readwrite("method_given", &FrameStripeOptions::method_given)
      .def_readwrite("steger_sigma_given", &FrameStripeOptions::steger_sigma_given)
      .def_readwrite("steger_sigma_along_given", &FrameStripeOptions::steger_sigma_along_given)
      .def_readwrite("detect_sigma_along_given", &FrameStripeOptions::detect_sigma_along_given)
      .def_readwrite("dominance_given", &FrameStripeOptions::dominance_given)
      .def_readwrite("normalize", &FrameStripeOptions::normalize)
      .def_readwrite("albedo_offset", &FrameStripeOptions::albedo_offset)
      .def_readwrite("assess", &FrameStripeOptions::assess)
      .def_readwrite("albedo_step", &FrameStripeOptions::albedo_step)
      .def_readwrite("blur_var", &FrameStripeOptions::blur_var)
      .def_readwrite("smooth_along", &FrameStripeOptions::smooth_along)
      .def_readonly_static("detect_along", &FrameStripeOptions::kDetectAlong);
  m.def(
      "_stripe_from_frames",
      [](const py::array& on, const py::object& off, const FrameStripeOptions& options,
         bool want_background) {
        return FramesDepth(on, off) == Depth::kU8
                   ? FromFrames<std::uint8_t>(on, off, options, want_background)
                   : FromFrames<std::uint16_t>(on, off, options, want_background);
      },
      py::arg("on"), py::arg("off"), py::arg("options"), py::arg("want_background") = false);
  m.def(
      "_estimate_background",
      [](const py::array& on, double width) -> py::array {
        auto run = [&](auto tag) -> py::array {
          using T = decltype(tag);
          const ImageView<T> a = ViewOf<T>(on, "the laser-on image");
          py::array_t<T> out({static_cast<py::ssize_t>(a.rows), static_cast<py::ssize_t>(a.cols)});
          T* dst = out.mutable_data();
          {
            py::gil_scoped_release release;
            EstimateBackground(a, width, dst);
          }
          return std::move(out);
        };
        return DepthOf(on, "the laser-on image") == Depth::kU8 ? run(std::uint8_t{})
                                                               : run(std::uint16_t{});
      },
      py::arg("on"), py::arg("width"));
  m.def(
      "_fit_albedo_offset",
      [](const py::array& on, const py::array& off, StripeDirection direction) {
        double offset = 0.0, noise = 0.0;
        auto run = [&](auto tag) {
          using T = decltype(tag);
          const ImageView<T> a = ViewOf<T>(on, "the laser-on image");
          const ImageView<T> b = ViewOf<T>(off, "the laser-off image");
          py::gil_scoped_release release;
          offset = FitAlbedoOffset(a, b, direction, &noise);
        };
        if (FramesDepth(on, off) == Depth::kU8) {
          run(std::uint8_t{});
        } else {
          run(std::uint16_t{});
        }
        return py::make_tuple(offset, noise);
      },
      py::arg("on"), py::arg("off"), py::arg("direction"));
  m.def(
      "_drop_jumps",
      [](const Eigen::VectorXd& centre,
         const Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>& status) {
        if (centre.size() != status.size()) {
          throw std::invalid_argument("centre and status differ in length");
        }
        StripeResult r;
        r.centre = centre;
        r.status = status;
        DropJumps(&r);
        return r.status;
      },
      py::arg("centre"), py::arg("status"));
  m.def("_smoothing_noise_gain", &SmoothingNoiseGain, py::arg("sigma"));
}

}  // namespace

void BindImage(py::module_& m) {
  BindStripeTypes(m);
  BindWholeImages(m);
  BindQuality(m);
  BindFrames(m);
}

}  // namespace hmlvs::python
