#include "hmlvs/solvers/lm.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "hmlvs/solvers/lm_costs.h"

namespace hmlvs {

namespace {

constexpr double kPi = 3.14159265358979323846;

double WrapNear(double angle, double reference) {
  return angle + 2.0 * kPi * std::round((reference - angle) / (2.0 * kPi));
}

// The three residual functors below all evaluate the model's HandResidual (model/model.h):
// E_h = h - (R_C cP + t) in the hand frame, which has the norm of the base-frame E.

// Intrinsics and translation as 11 scalar blocks (f..theta, tx, ty, tz) and the rotation as an
// Eigen quaternion [x, y, z, w].
struct ModernResidual {
  double u, v;
  Eigen::Vector3d h;

  template <typename T>
  bool operator()(const T* f, const T* su, const T* sv, const T* cu, const T* cv, const T* k,
                  const T* hh, const T* theta, const T* quat, const T* tx, const T* ty, const T* tz,
                  T* residual) const {
    using std::tan;
    T q[kNumParams];  // the Euler angles are not read: the rotation is the quaternion
    q[kF] = *f;
    q[kSu] = *su;
    q[kSv] = *sv;
    q[kCu] = *cu;
    q[kCv] = *cv;
    q[kK] = *k;
    q[kH] = *hh;
    q[kTheta] = *theta;
    q[kOmega] = q[kPhi] = q[kVarphi] = T(0.0);
    q[kTx] = *tx;
    q[kTy] = *ty;
    q[kTz] = *tz;
    const Eigen::Quaternion<T> rot(quat[3], quat[0], quat[1], quat[2]);
    return HandResidual(q, rot, tan(q[kTheta]), u, v, h.data(), residual) > T(0.0);
  }
};

// Euler-angle variant for when an Euler angle is held fixed (14 scalar blocks).
struct EulerResidual {
  double u, v;
  Eigen::Vector3d h;

  template <typename T>
  bool operator()(const T* const* p, T* residual) const {
    using std::tan;
    T q[kNumParams];
    for (int i = 0; i < kNumParams; ++i) q[i] = p[i][0];
    return HandResidual(q, RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]), tan(q[kTheta]), u, v,
                        h.data(), residual) > T(0.0);
  }
};

// The paper's scalar residual ||E_i|| over the 14-vector (forward differences).
struct PaperResidual {
  double u, v;
  Eigen::Vector3d h;

  bool operator()(const double* q, double* residual) const {
    double e[3];
    if (!(HandResidual(q, RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]), std::tan(q[kTheta]), u, v,
                       h.data(), e) > 0.0)) {
      return false;
    }
    residual[0] = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    return true;
  }
};

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

}  // namespace

ceres::CostFunction* NewPaperCost(double u, double v, const Eigen::Vector3d& reference_in_hand) {
  return new ceres::NumericDiffCostFunction<PaperResidual, ceres::FORWARD, 1, kNumParams>(
      new PaperResidual{u, v, reference_in_hand});
}

ceres::CostFunction* NewModernQuaternionCost(double u, double v,
                                             const Eigen::Vector3d& reference_in_hand) {
  return new ceres::AutoDiffCostFunction<ModernResidual, 3, 1, 1, 1, 1, 1, 1, 1, 1, 4, 1, 1, 1>(
      new ModernResidual{u, v, reference_in_hand});
}

ceres::CostFunction* NewModernEulerCost(double u, double v,
                                        const Eigen::Vector3d& reference_in_hand) {
  auto* cost = new ceres::DynamicAutoDiffCostFunction<EulerResidual, 16>(
      new EulerResidual{u, v, reference_in_hand});
  for (int p = 0; p < kNumParams; ++p) cost->AddParameterBlock(1);
  cost->SetNumResiduals(3);
  return cost;
}

Eigen::Vector3d EulerZYZFromRotation(const Eigen::Matrix3d& r, const Eigen::Vector3d& hint) {
  const double sphi = std::hypot(r(0, 2), r(1, 2));
  if (sphi < 1e-12) {
    // Gimbal lock (phi = 0 or pi): only omega +- varphi is defined; keep omega at the hint.
    const double phi = r(2, 2) > 0 ? 0.0 : kPi;
    const double sum = std::atan2(r(1, 0), r(0, 0));  // omega + varphi (phi = 0)
    const double omega = hint[0];
    const double varphi = phi == 0.0 ? sum - omega : omega - std::atan2(-r(1, 0), -r(0, 0));
    return Eigen::Vector3d(omega, WrapNear(phi, hint[1]), WrapNear(varphi, hint[2]));
  }
  Eigen::Vector3d best;
  double best_dist = 1e300;
  for (int sign : {1, -1}) {
    const double phi = std::atan2(sign * sphi, r(2, 2));
    const double omega = std::atan2(sign * r(1, 2), sign * r(0, 2));
    const double varphi = std::atan2(sign * r(2, 1), -sign * r(2, 0));
    const Eigen::Vector3d e(WrapNear(omega, hint[0]), phi, WrapNear(varphi, hint[2]));
    const double dist = (e - hint).squaredNorm();
    if (dist < best_dist) {
      best_dist = dist;
      best = e;
    }
  }
  return best;
}

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
  ceres::Problem::Options popt;
  popt.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(popt);
  std::array<double, 4> quat{};  // Eigen order x, y, z, w
  const bool use_quaternion = !paper && !o.fixed[kOmega] && !o.fixed[kPhi] && !o.fixed[kVarphi];

  if (paper) {
    for (Eigen::Index i = 0; i < data.size(); ++i) {
      problem.AddResidualBlock(NewPaperCost(data.u(i), data.v(i), data.ReferenceInHand(i)), nullptr,
                               q.data());
    }
    std::vector<int> fixed_idx;
    for (int i = 0; i < kNumParams; ++i)
      if (o.fixed[i]) fixed_idx.push_back(i);
    if (!fixed_idx.empty()) {
      problem.SetManifold(q.data(), new ceres::SubsetManifold(kNumParams, fixed_idx));
    }
  } else if (use_quaternion) {
    const Eigen::Quaterniond rq(RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]));
    quat = {rq.x(), rq.y(), rq.z(), rq.w()};
    for (Eigen::Index i = 0; i < data.size(); ++i) {
      ceres::CostFunction* cost =
          NewModernQuaternionCost(data.u(i), data.v(i), data.ReferenceInHand(i));
      problem.AddResidualBlock(cost, loss.get(), &q[kF], &q[kSu], &q[kSv], &q[kCu], &q[kCv], &q[kK],
                               &q[kH], &q[kTheta], quat.data(), &q[kTx], &q[kTy], &q[kTz]);
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
  if (!paper) {
    for (int i = 0; i < kNumParams; ++i) {
      const bool euler = i == kOmega || i == kPhi || i == kVarphi;
      if (euler && use_quaternion) continue;
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

  if (use_quaternion) {
    const Eigen::Quaterniond rq(quat[3], quat[0], quat[1], quat[2]);
    const Eigen::Vector3d euler =
        EulerZYZFromRotation(rq.normalized().toRotationMatrix(),
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

}  // namespace hmlvs
