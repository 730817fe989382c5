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

// Runs solve(progress callback) with the GIL released, then re-raises the callable's error.
template <typename Fn>
auto SolveWithProgress(py::object progress, Fn solve) {
  PyProgress wrapper(std::move(progress));
  ProgressCallback cb = wrapper.callback();
  decltype(solve(cb)) r;
  {
    py::gil_scoped_release release;
    r = solve(cb);
  }
  wrapper.rethrow();
  return r;
}

// The paper model's searches (N = 14).
using Pso = PsoOptions<kNumParams>;
using PsoRun14 = PsoRun<kNumParams>;
using PsoResult14 = PsoResult<kNumParams>;
using RandomSearch = RandomSearchOptions<kNumParams>;
using RandomSearchResult14 = RandomSearchResult<kNumParams>;

void BindFitness(py::module_& m) {
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
}

void BindPso(py::module_& m) {
  py::class_<Pso>(m, "_PsoOptions")
      .def(py::init<>())
      .def_readwrite("swarm_size", &Pso::swarm_size)
      .def_readwrite("iterations", &Pso::iterations)
      .def_readwrite("w_max", &Pso::w_max)
      .def_readwrite("w_min", &Pso::w_min)
      .def_readwrite("c1", &Pso::c1)
      .def_readwrite("c2", &Pso::c2)
      .def_readwrite("vmax", &Pso::vmax)
      .def_readwrite("target_fitness", &Pso::target_fitness)
      .def_readwrite("runs", &Pso::runs)
      .def_readwrite("threads", &Pso::threads)
      .def_readwrite("seed", &Pso::seed)
      .def_readwrite("lower", &Pso::lower)
      .def_readwrite("upper", &Pso::upper)
      .def_readwrite("init_lower", &Pso::init_lower)
      .def_readwrite("init_upper", &Pso::init_upper)
      .def_readwrite("progress_every", &Pso::progress_every);
  py::class_<PsoRun14>(m, "_PsoRun")
      .def_readonly("best", &PsoRun14::best)
      .def_readonly("best_fitness", &PsoRun14::best_fitness)
      .def_readonly("iterations", &PsoRun14::iterations)
      .def_readonly("termination", &PsoRun14::termination)
      .def_readonly("history", &PsoRun14::history);
  py::class_<PsoResult14>(m, "_PsoResult")
      .def_readonly("runs", &PsoResult14::runs)
      .def_readonly("best_run", &PsoResult14::best_run)
      .def_readonly("threads", &PsoResult14::threads)
      .def_readonly("seconds", &PsoResult14::seconds)
      .def_readonly("cancelled", &PsoResult14::cancelled);
  m.def(
      "_run_pso",
      [](const FitnessData& data, const Pso& o, py::object progress) {
        return SolveWithProgress(std::move(progress),
                                 [&](const ProgressCallback& cb) { return RunPso(data, o, cb); });
      },
      py::arg("data"), py::arg("options"), py::arg("progress") = py::none());
}

void BindRandomSearch(py::module_& m) {
  py::class_<RandomSearch>(m, "_RandomSearchOptions")
      .def(py::init<>())
      .def_readwrite("evaluations", &RandomSearch::evaluations)
      .def_readwrite("threads", &RandomSearch::threads)
      .def_readwrite("seed", &RandomSearch::seed)
      .def_readwrite("lower", &RandomSearch::lower)
      .def_readwrite("upper", &RandomSearch::upper);
  py::class_<RandomSearchResult14>(m, "_RandomSearchResult")
      .def_readonly("best", &RandomSearchResult14::best)
      .def_readonly("best_fitness", &RandomSearchResult14::best_fitness)
      .def_readonly("evaluations", &RandomSearchResult14::evaluations)
      .def_readonly("best_index", &RandomSearchResult14::best_index)
      .def_readonly("threads", &RandomSearchResult14::threads)
      .def_readonly("seconds", &RandomSearchResult14::seconds)
      .def_readonly("cancelled", &RandomSearchResult14::cancelled);
  m.def(
      "_run_random_search",
      [](const FitnessData& data, const RandomSearch& o, py::object progress) {
        return SolveWithProgress(std::move(progress), [&](const ProgressCallback& cb) {
          return RunRandomSearch(data, o, cb);
        });
      },
      py::arg("data"), py::arg("options"), py::arg("progress") = py::none());
}

void BindLm(py::module_& m) {
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
        MultiStartResult r = SolveWithProgress(
            std::move(progress),
            [&](const ProgressCallback& cb) { return RunLmMany(data, initials, o, threads, cb); });
        return std::make_pair(std::move(r.results), std::move(r.errors));
      },
      py::arg("data"), py::arg("initials"), py::arg("options"), py::arg("threads") = 0,
      py::arg("progress") = py::none());
}

}  // namespace

void BindSolvers(py::module_& m) {
  BindFitness(m);
  BindPso(m);
  BindRandomSearch(m);
  BindLm(m);
}

}  // namespace hmlvs::python
