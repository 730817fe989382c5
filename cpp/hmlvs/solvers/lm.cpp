#include "hmlvs/solvers/lm.h"

#include <ceres/ceres.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "hmlvs/solvers/lm_costs.h"

namespace hmlvs::solvers {

using namespace hmlvs::paper;

namespace {

ceres::LossFunction* MakeLoss(const LmOptions& o) {
  if (o.loss != LossKind::kNone && !(o.loss_scale > 0.0)) {
    throw std::invalid_argument("the robust loss scale must be > 0 mm");
  }
  switch (o.loss) {
    case LossKind::kHuber:
      return new ceres::HuberLoss(o.loss_scale);
    case LossKind::kCauchy:
      return new ceres::CauchyLoss(o.loss_scale);
    default:
      return nullptr;
  }
}

// Holds the parameters of a block [first, first + size) that are fixed (the whole block when all
// are, else a SubsetManifold) and bounds the free ones.
void HoldAndBound(ceres::Problem* problem, double* block, int first, int size, const LmOptions& o) {
  std::vector<int> fixed;
  for (int i = 0; i < size; ++i)
    if (o.fixed[first + i]) fixed.push_back(i);
  if (static_cast<int>(fixed.size()) == size) {
    problem->SetParameterBlockConstant(block);
    return;
  }
  if (!fixed.empty()) problem->SetManifold(block, new ceres::SubsetManifold(size, fixed));
  if (!o.use_bounds) return;
  for (int i = 0; i < size; ++i) {
    if (o.fixed[first + i]) continue;
    problem->SetParameterLowerBound(block, i, o.lower[first + i]);
    problem->SetParameterUpperBound(block, i, o.upper[first + i]);
  }
}

// HoldAndBound for a block that holds the group's parameters `entries` (0-based within the group
// that starts at `first`) only: constant when they are all held, else their bounds.
void PackedHoldAndBound(ceres::Problem* problem, double* block, int first,
                        const std::vector<int>& entries, const LmOptions& o) {
  bool all_held = true;
  for (int e : entries) all_held = all_held && o.fixed[first + e];
  if (all_held) {
    problem->SetParameterBlockConstant(block);
    return;
  }
  if (!o.use_bounds) return;
  for (std::size_t k = 0; k < entries.size(); ++k) {
    const int i = first + entries[k];
    problem->SetParameterLowerBound(block, static_cast<int>(k), o.lower[i]);
    problem->SetParameterUpperBound(block, static_cast<int>(k), o.upper[i]);
  }
}

}  // namespace

LmResult RunLm(const FitnessData& data, const Vector14d& initial, const LmOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  ValidateParams(initial);
  const auto& names = ParamNames();
  const Eigen::VectorXd e0 = data.PointErrors(initial.data());
  for (Eigen::Index i = 0; i < e0.size(); ++i) {
    if (std::isnan(e0[i])) {
      std::ostringstream msg;
      msg << "the initial parameters are not usable: the ray of calibration point " << i
          << " misses the laser plane";
      throw std::invalid_argument(msg.str());
    }
  }
  int free = 0;
  for (int i = 0; i < kNumParams; ++i) free += o.fixed[i] ? 0 : 1;
  const bool paper = o.mode == LmMode::kPaper;
  const Eigen::Index residuals = paper ? data.size() : 3 * data.size();
  if (free == 0) throw std::invalid_argument("all parameters are fixed: nothing to estimate");
  if (residuals < free) {
    std::ostringstream msg;
    msg << "too few points: " << data.size() << " points give " << residuals << " residuals for "
        << free << " free parameters";
    throw std::invalid_argument(msg.str());
  }
  if (!paper && o.use_bounds) {
    for (int i = 0; i < kNumParams; ++i) {
      if (o.lower[i] > o.upper[i]) {
        throw std::invalid_argument("bounds of " + names[i] + ": lower > upper");
      }
      const bool euler = i == kOmega || i == kPhi || i == kVarphi;
      if (!euler && !o.fixed[i] && (initial[i] < o.lower[i] || initial[i] > o.upper[i])) {
        std::ostringstream msg;
        msg << "initial " << names[i] << " = " << initial[i] << " lies outside its bounds ["
            << o.lower[i] << ", " << o.upper[i] << "]";
        throw std::invalid_argument(msg.str());
      }
    }
  }

  Vector14d q = initial;
  // One robust loss shared by all residual blocks, owned here.
  std::unique_ptr<ceres::LossFunction> loss(paper ? nullptr : MakeLoss(o));
  PaperTrigCache trig;  // shared by the paper-mode costs; the solve runs on one thread
  ceres::Problem::Options popt;
  popt.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(popt);
  std::array<double, 4> quat{};                 // Eigen order x, y, z, w
  std::array<double, kTheta + 1> intrinsics{};  // modern mode without a loss: the packed blocks
  std::array<double, 3> translation{};
  bool packed = false;
  const std::vector<int> packed_intrinsics = PackedEntries(o.fixed, kF, kTheta + 1);
  const std::vector<int> packed_translation = PackedEntries(o.fixed, kTx, 3);
  const bool use_quaternion = !paper && !o.fixed[kOmega] && !o.fixed[kPhi] && !o.fixed[kVarphi];

  if (paper) {
    for (Eigen::Index i = 0; i < data.size(); ++i) {
      problem.AddResidualBlock(NewPaperCost(data.u(i), data.v(i), data.ReferenceInHand(i),
                                            o.paper_fast_cost ? &trig : nullptr),
                               nullptr, q.data());
    }
    std::vector<int> fixed_idx;
    for (int i = 0; i < kNumParams; ++i)
      if (o.fixed[i]) fixed_idx.push_back(i);
    if (!fixed_idx.empty()) {
      problem.SetManifold(q.data(), new ceres::SubsetManifold(kNumParams, fixed_idx));
    }
  } else if (use_quaternion) {
    const Eigen::Quaterniond rq(geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]));
    quat = {rq.x(), rq.y(), rq.z(), rq.w()};
    if (loss == nullptr) {
      // The intrinsics and translation blocks hold their free parameters only (packed in
      // `intrinsics` and `translation`); the held ones are the cost's constants.
      ceres::CostFunction* cost = NewModernBatchCost(data, q, o.fixed);
      for (std::size_t k = 0; k < packed_intrinsics.size(); ++k)
        intrinsics[k] = q[kF + packed_intrinsics[k]];
      for (std::size_t k = 0; k < packed_translation.size(); ++k)
        translation[k] = q[kTx + packed_translation[k]];
      problem.AddResidualBlock(cost, nullptr, intrinsics.data(), quat.data(), translation.data());
      PackedHoldAndBound(&problem, intrinsics.data(), kF, packed_intrinsics, o);
      PackedHoldAndBound(&problem, translation.data(), kTx, packed_translation, o);
      packed = true;
    } else {  // the robust loss applies per point: one residual block each
      for (Eigen::Index i = 0; i < data.size(); ++i) {
        ceres::CostFunction* cost =
            NewModernQuaternionCost(data.u(i), data.v(i), data.ReferenceInHand(i));
        problem.AddResidualBlock(cost, loss.get(), &q[kF], quat.data(), &q[kTx]);
      }
      HoldAndBound(&problem, &q[kF], kF, kTheta + 1, o);
      HoldAndBound(&problem, &q[kTx], kTx, 3, o);
    }
    problem.SetManifold(quat.data(), new ceres::EigenQuaternionManifold());
  } else {
    for (Eigen::Index i = 0; i < data.size(); ++i) {
      std::vector<double*> blocks;
      for (int p = 0; p < kNumParams; ++p) blocks.push_back(&q[p]);
      problem.AddResidualBlock(NewModernEulerCost(data.u(i), data.v(i), data.ReferenceInHand(i)),
                               loss.get(), blocks);
    }
  }
  if (!paper && !use_quaternion) {
    for (int i = 0; i < kNumParams; ++i) {
      double* block = &q[i];
      if (o.fixed[i]) {
        problem.SetParameterBlockConstant(block);
      } else if (o.use_bounds) {
        problem.SetParameterLowerBound(block, 0, o.lower[i]);
        problem.SetParameterUpperBound(block, 0, o.upper[i]);
      }
    }
  }

  ceres::Solver::Options sopt;
  sopt.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  sopt.linear_solver_type = ceres::DENSE_QR;
  sopt.max_num_iterations = o.max_iterations > 0 ? o.max_iterations : 300 * free;
  sopt.function_tolerance = o.function_tolerance;
  sopt.parameter_tolerance = o.parameter_tolerance;
  sopt.gradient_tolerance = o.gradient_tolerance;
  sopt.num_threads = 1;
  sopt.logging_type = ceres::SILENT;
  sopt.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(sopt, &problem, &summary);

  if (packed) {
    for (std::size_t k = 0; k < packed_intrinsics.size(); ++k)
      q[kF + packed_intrinsics[k]] = intrinsics[k];
    for (std::size_t k = 0; k < packed_translation.size(); ++k)
      q[kTx + packed_translation[k]] = translation[k];
  }
  if (use_quaternion) {
    const Eigen::Quaterniond rq(quat[3], quat[0], quat[1], quat[2]);
    const Eigen::Vector3d euler = geometry::EulerZYZFromRotation(
        rq.normalized().toRotationMatrix(),
        Eigen::Vector3d(initial[kOmega], initial[kPhi], initial[kVarphi]));
    q[kOmega] = euler[0];
    q[kPhi] = euler[1];
    q[kVarphi] = euler[2];
  }
  LmResult result;
  result.params = q;
  result.initial_cost = data.Evaluate(initial.data());
  result.final_cost = data.Evaluate(q.data());
  result.iterations = static_cast<int>(summary.iterations.size()) - 1;
  result.termination = ceres::TerminationTypeToString(summary.termination_type);
  result.message = summary.message;
  result.usable = summary.IsSolutionUsable();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace hmlvs::solvers
