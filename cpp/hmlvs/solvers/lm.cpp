#include "hmlvs/solvers/lm.h"

#include <ceres/ceres.h>

#include <Eigen/Geometry>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "hmlvs/solvers/lm_costs.h"
#include "hmlvs/solvers/point_lm.h"

namespace hmlvs::solvers {

using namespace hmlvs::paper;

namespace {

// Throws std::invalid_argument for a start or options RunLm refuses (lm.h); returns the number
// of free parameters.
int CheckLmInput(const FitnessData& data, const Vector14d& initial, const LmOptions& o) {
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
  if (paper || !o.use_bounds) return free;
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
  return free;
}

// Holds the parameters of a block [first, first + size) that are fixed (the whole block when all
// are, else a SubsetManifold) and bounds the free ones.
void HoldAndBound(ceres::Problem* problem, double* block, int first, int size, const LmOptions& o) {
  std::vector<int> fixed;
  for (int i = 0; i < size; ++i)
    if (o.fixed[first + i]) fixed.push_back(i);
  if (!HoldEntries(problem, block, size, fixed) || !o.use_bounds) return;
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

// The Ceres problem of one solve: the parameter blocks of the mode (lm.h) and how they map to the
// 14 parameters. Not copyable: the problem points into it.
class LmProblem {
 public:
  LmProblem(const FitnessData& data, const Vector14d& initial, const LmOptions& o)
      : data_(data), o_(o), q_(initial) {
    const bool paper = o.mode == LmMode::kPaper;
    // One robust loss shared by all residual blocks, owned here.
    if (!paper) loss_ = MakeLoss(o.loss, o.loss_scale, "mm");
    ceres::Problem::Options popt;
    popt.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_ = std::make_unique<ceres::Problem>(popt);
    quaternion_ = !paper && !o.fixed[kOmega] && !o.fixed[kPhi] && !o.fixed[kVarphi];
    if (paper) {
      AddPaperBlocks();
    } else if (quaternion_) {
      AddQuaternionBlocks();
    } else {
      AddEulerBlocks();
    }
  }
  LmProblem(const LmProblem&) = delete;
  LmProblem& operator=(const LmProblem&) = delete;

  ceres::Problem* problem() { return problem_.get(); }

  // The 14 parameters from the blocks' values (after the solve), the Euler angles nearest the
  // start's when the rotation was solved as a quaternion.
  Vector14d Params() const {
    Vector14d q = q_;
    if (packed_) {
      for (std::size_t k = 0; k < packed_intrinsics_.size(); ++k)
        q[kF + packed_intrinsics_[k]] = intrinsics_[k];
      for (std::size_t k = 0; k < packed_translation_.size(); ++k)
        q[kTx + packed_translation_[k]] = translation_[k];
    }
    if (quaternion_) {
      const Eigen::Quaterniond rq(quat_[3], quat_[0], quat_[1], quat_[2]);
      const Eigen::Vector3d euler = geometry::EulerZYZFromRotation(
          rq.normalized().toRotationMatrix(), Eigen::Vector3d(q_[kOmega], q_[kPhi], q_[kVarphi]));
      q[kOmega] = euler[0];
      q[kPhi] = euler[1];
      q[kVarphi] = euler[2];
    }
    return q;
  }

 private:
  // Paper mode: the scalar residual of each point over the 14-vector.
  void AddPaperBlocks() {
    for (Eigen::Index i = 0; i < data_.size(); ++i) {
      problem_->AddResidualBlock(NewPaperCost(data_.u(i), data_.v(i), data_.ReferenceInHand(i),
                                              o_.paper_fast_cost ? &trig_ : nullptr),
                                 nullptr, q_.data());
    }
    std::vector<int> fixed_idx;
    for (int i = 0; i < kNumParams; ++i)
      if (o_.fixed[i]) fixed_idx.push_back(i);
    HoldEntries(problem_.get(), q_.data(), kNumParams, fixed_idx);  // not all: CheckLmInput
  }

  // Modern mode with the rotation free: intrinsics, quaternion and translation blocks.
  void AddQuaternionBlocks() {
    const Eigen::Quaterniond rq(geometry::RotationZYZ(q_[kOmega], q_[kPhi], q_[kVarphi]));
    quat_ = {rq.x(), rq.y(), rq.z(), rq.w()};
    if (loss_ == nullptr) {
      // The intrinsics and translation blocks hold their free parameters only (packed in
      // `intrinsics_` and `translation_`); the held ones are the cost's constants.
      packed_ = true;
      packed_intrinsics_ = PackedEntries(o_.fixed, kF, kTheta + 1);
      packed_translation_ = PackedEntries(o_.fixed, kTx, 3);
      ceres::CostFunction* cost = NewModernBatchCost(data_, q_, o_.fixed);
      for (std::size_t k = 0; k < packed_intrinsics_.size(); ++k)
        intrinsics_[k] = q_[kF + packed_intrinsics_[k]];
      for (std::size_t k = 0; k < packed_translation_.size(); ++k)
        translation_[k] = q_[kTx + packed_translation_[k]];
      problem_->AddResidualBlock(cost, nullptr, intrinsics_.data(), quat_.data(),
                                 translation_.data());
      PackedHoldAndBound(problem_.get(), intrinsics_.data(), kF, packed_intrinsics_, o_);
      PackedHoldAndBound(problem_.get(), translation_.data(), kTx, packed_translation_, o_);
    } else {  // the robust loss applies per point: one residual block each
      for (Eigen::Index i = 0; i < data_.size(); ++i) {
        ceres::CostFunction* cost =
            NewModernQuaternionCost(data_.u(i), data_.v(i), data_.ReferenceInHand(i));
        problem_->AddResidualBlock(cost, loss_.get(), &q_[kF], quat_.data(), &q_[kTx]);
      }
      HoldAndBound(problem_.get(), &q_[kF], kF, kTheta + 1, o_);
      HoldAndBound(problem_.get(), &q_[kTx], kTx, 3, o_);
    }
    problem_->SetManifold(quat_.data(), new ceres::EigenQuaternionManifold());
  }

  // Modern mode with an Euler angle held: the point problem of either model (point_lm.h) on
  // the paper model, 14 scalar blocks, each held or bounded.
  void AddEulerBlocks() {
    PointLmOptions<kNumParams> po;
    po.fixed = o_.fixed;
    po.use_bounds = o_.use_bounds;
    po.lower = o_.lower;
    po.upper = o_.upper;
    AddPointBlocks<Model>(problem_.get(), data_.points(), q_.data(), loss_.get(), po);
  }

  const FitnessData& data_;
  const LmOptions& o_;
  Vector14d q_;
  std::unique_ptr<ceres::LossFunction> loss_;
  PaperTrigCache trig_;  // shared by the paper-mode costs; the solve runs on one thread
  std::unique_ptr<ceres::Problem> problem_;
  bool quaternion_ = false, packed_ = false;
  std::array<double, 4> quat_{};                 // Eigen order x, y, z, w
  std::array<double, kTheta + 1> intrinsics_{};  // the packed blocks (modern mode, no loss)
  std::array<double, 3> translation_{};
  std::vector<int> packed_intrinsics_, packed_translation_;
};

}  // namespace

LmResult RunLm(const FitnessData& data, const Vector14d& initial, const LmOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  const int free = CheckLmInput(data, initial, o);
  LmProblem lm(data, initial, o);
  const StopRules stop{o.max_iterations > 0 ? o.max_iterations : 300 * free, o.function_tolerance,
                       o.parameter_tolerance, o.gradient_tolerance};
  LmResult result;
  static_cast<SolveSummary&>(result) = SolveLm(lm.problem(), stop, ceres::DENSE_QR, start);
  result.params = lm.Params();
  // F before and after, without the robust loss.
  result.initial_cost = data.Evaluate(initial.data());
  result.final_cost = data.Evaluate(result.params.data());
  result.seconds = SecondsSince(start);
  return result;
}

}  // namespace hmlvs::solvers
