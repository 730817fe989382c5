#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "bindings.h"
#include "hmlvs/model/paper_fitness.h"
#include "hmlvs/solvers/lm.h"
#include "hmlvs/solvers/multistart.h"
#include "hmlvs/solvers/search.h"

namespace py = pybind11;

namespace hmlvs::python {

using namespace hmlvs::paper;
using namespace hmlvs::solvers;

namespace {

// Wraps an optional Python progress callable for use from C++ with the GIL released. The
// callback runs on the caller's thread (team member 0); it takes the GIL, checks for Ctrl-C,
// and stops the solve when the callable returns False or raises. The Python error is kept and
// re-raised after the solve.
class PyProgress {
 public:
  explicit PyProgress(py::object fn) : fn_(std::move(fn)) {}

  ProgressCallback callback() {
    if (fn_.is_none()) {
      // No callable: still check for Ctrl-C at every progress point, so that a long solve
      // started from Python stops promptly (KeyboardInterrupt is raised after it stops).
      return [this](const Progress&) {
        py::gil_scoped_acquire gil;
        if (error_) return false;
        if (PyErr_CheckSignals() != 0) {
          error_ = std::make_unique<py::error_already_set>();
          return false;
        }
        return true;
      };
    }
    return [this](const Progress& p) {
      py::gil_scoped_acquire gil;
      if (error_) return false;
      try {
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
        py::object r = fn_(p.done, p.total, p.best_fitness);
        return r.is_none() || r.cast<bool>();
      } catch (py::error_already_set& e) {
        error_ = std::make_unique<py::error_already_set>(std::move(e));
        return false;
      }
    };
  }

  void rethrow() {
    if (error_) {
      py::error_already_set e = std::move(*error_);
      error_.reset();
      throw e;
    }
  }

  ~PyProgress() {
    if (error_) {
      py::gil_scoped_acquire gil;
      error_.reset();
    }
  }

 private:
  py::object fn_;
  std::unique_ptr<py::error_already_set> error_;
};

template <typename Result, typename Options, typename Fn>
Result SolveWithProgress(const FitnessData& data, const Options& options, py::object progress,
                         Fn solve) {
  PyProgress wrapper(std::move(progress));
  ProgressCallback cb = wrapper.callback();
  Result r;
  {
    py::gil_scoped_release release;
    r = solve(data, options, cb);
  }
  wrapper.rethrow();
  return r;
}

}  // namespace

void BindSolvers(py::module_& m) {
  py::class_<FitnessData>(m, "_FitnessData")
      .def(py::init<PixelsRef, PosesRef, Points3Ref>(), py::arg("pixels"), py::arg("poses"),
           py::arg("references"))
      .def("__len__", &FitnessData::size)
      .def("evaluate",
           [](const FitnessData& d, const Vector14d& q) { return d.Evaluate(q.data()); })
      .def("point_errors",
           [](const FitnessData& d, const Vector14d& q) { return d.PointErrors(q.data()); })
      .def(
          "evaluate_many",
          [](const FitnessData& d,
             const Eigen::Ref<
                 const Eigen::Matrix<double, Eigen::Dynamic, kNumParams, Eigen::RowMajor>>& qs) {
            Eigen::VectorXd out(qs.rows());
            {
              py::gil_scoped_release release;
              for (Eigen::Index i = 0; i < qs.rows(); ++i) out[i] = d.Evaluate(qs.row(i).data());
            }
            return out;
          },
          py::arg("params"));

  py::class_<PsoOptions>(m, "_PsoOptions")
      .def(py::init<>())
      .def_readwrite("swarm_size", &PsoOptions::swarm_size)
      .def_readwrite("iterations", &PsoOptions::iterations)
      .def_readwrite("w_max", &PsoOptions::w_max)
      .def_readwrite("w_min", &PsoOptions::w_min)
      .def_readwrite("c1", &PsoOptions::c1)
      .def_readwrite("c2", &PsoOptions::c2)
      .def_readwrite("vmax", &PsoOptions::vmax)
      .def_readwrite("target_fitness", &PsoOptions::target_fitness)
      .def_readwrite("runs", &PsoOptions::runs)
      .def_readwrite("threads", &PsoOptions::threads)
      .def_readwrite("seed", &PsoOptions::seed)
      .def_readwrite("lower", &PsoOptions::lower)
      .def_readwrite("upper", &PsoOptions::upper)
      .def_readwrite("init_lower", &PsoOptions::init_lower)
      .def_readwrite("init_upper", &PsoOptions::init_upper)
      .def_readwrite("progress_every", &PsoOptions::progress_every);
  py::class_<PsoRun>(m, "_PsoRun")
      .def_readonly("best", &PsoRun::best)
      .def_readonly("best_fitness", &PsoRun::best_fitness)
      .def_readonly("iterations", &PsoRun::iterations)
      .def_readonly("termination", &PsoRun::termination)
      .def_readonly("history", &PsoRun::history);
  py::class_<PsoResult>(m, "_PsoResult")
      .def_readonly("runs", &PsoResult::runs)
      .def_readonly("best_run", &PsoResult::best_run)
      .def_readonly("threads", &PsoResult::threads)
      .def_readonly("seconds", &PsoResult::seconds)
      .def_readonly("cancelled", &PsoResult::cancelled);
  m.def(
      "_run_pso",
      [](const FitnessData& data, const PsoOptions& o, py::object progress) {
        return SolveWithProgress<PsoResult>(
            data, o, std::move(progress),
            [](const FitnessData& d, const PsoOptions& opt, const ProgressCallback& cb) {
              return RunPso(d, opt, cb);
            });
      },
      py::arg("data"), py::arg("options"), py::arg("progress") = py::none());

  py::class_<RandomSearchOptions>(m, "_RandomSearchOptions")
      .def(py::init<>())
      .def_readwrite("evaluations", &RandomSearchOptions::evaluations)
      .def_readwrite("threads", &RandomSearchOptions::threads)
      .def_readwrite("seed", &RandomSearchOptions::seed)
      .def_readwrite("lower", &RandomSearchOptions::lower)
      .def_readwrite("upper", &RandomSearchOptions::upper);
  py::class_<RandomSearchResult>(m, "_RandomSearchResult")
      .def_readonly("best", &RandomSearchResult::best)
      .def_readonly("best_fitness", &RandomSearchResult::best_fitness)
      .def_readonly("evaluations", &RandomSearchResult::evaluations)
      .def_readonly("best_index", &RandomSearchResult::best_index)
      .def_readonly("threads", &RandomSearchResult::threads)
      .def_readonly("seconds", &RandomSearchResult::seconds)
      .def_readonly("cancelled", &RandomSearchResult::cancelled);
  m.def(
      "_run_random_search",
      [](const FitnessData& data, const RandomSearchOptions& o, py::object progress) {
        return SolveWithProgress<RandomSearchResult>(
            data, o, std::move(progress),
            [](const FitnessData& d, const RandomSearchOptions& opt, const ProgressCallback& cb) {
              return RunRandomSearch(d, opt, cb);
            });
      },
      py::arg("data"), py::arg("options"), py::arg("progress") = py::none());

  py::enum_<LmMode>(m, "_LmMode").value("modern", LmMode::kModern).value("paper", LmMode::kPaper);
  py::enum_<LossKind>(m, "_LossKind")
      .value("none", LossKind::kNone)
      .value("huber", LossKind::kHuber)
      .value("cauchy", LossKind::kCauchy);
  py::class_<LmOptions>(m, "_LmOptions")
      .def(py::init<>())
      .def_readwrite("mode", &LmOptions::mode)
      .def_readwrite("max_iterations", &LmOptions::max_iterations)
      .def_readwrite("fixed", &LmOptions::fixed)
      .def_readwrite("use_bounds", &LmOptions::use_bounds)
      .def_readwrite("lower", &LmOptions::lower)
      .def_readwrite("upper", &LmOptions::upper)
      .def_readwrite("loss", &LmOptions::loss)
      .def_readwrite("loss_scale", &LmOptions::loss_scale)
      .def_readwrite("function_tolerance", &LmOptions::function_tolerance)
      .def_readwrite("parameter_tolerance", &LmOptions::parameter_tolerance)
      .def_readwrite("gradient_tolerance", &LmOptions::gradient_tolerance);
  // The summary of a Ceres solve, the base of _LmResult and of _JointResult (bind_general.cpp,
  // bound after this).
  py::class_<SolveSummary>(m, "_SolveSummary")
      .def_readonly("initial_cost", &SolveSummary::initial_cost)
      .def_readonly("final_cost", &SolveSummary::final_cost)
      .def_readonly("iterations", &SolveSummary::iterations)
      .def_readonly("termination", &SolveSummary::termination)
      .def_readonly("message", &SolveSummary::message)
      .def_readonly("usable", &SolveSummary::usable)
      .def_readonly("seconds", &SolveSummary::seconds);
  py::class_<LmResult, SolveSummary>(m, "_LmResult").def_readonly("params", &LmResult::params);
  m.def("_run_lm", &RunLm, py::arg("data"), py::arg("initial"), py::arg("options"),
        py::call_guard<py::gil_scoped_release>());
  m.def(
      "_run_lm_many",
      [](const FitnessData& data, StartsRef initials, const LmOptions& o, int threads,
         py::object progress) {
        // RunLmMany (multistart.h); the progress callable (done, total, best_cost) may stop it.
        PyProgress wrapper(std::move(progress));
        ProgressCallback cb = wrapper.callback();
        MultiStartResult r;
        {
          py::gil_scoped_release release;
          r = RunLmMany(data, initials, o, threads, cb);
        }
        wrapper.rethrow();
        return std::make_pair(std::move(r.results), std::move(r.errors));
      },
      py::arg("data"), py::arg("initials"), py::arg("options"), py::arg("threads") = 0,
      py::arg("progress") = py::none());
}

}  // namespace hmlvs::python
