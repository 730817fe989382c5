#include "hmlvs/solvers/lm_costs.h"

#include <ceres/ceres.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

namespace hmlvs::solvers {

using namespace hmlvs::paper;

namespace {

// The residual functors below and the cost functions after them all evaluate the model's
// HandResidual (model/model.h): E_h = h - (R_C cP + t) in the hand frame, which has the norm of the
// base-frame E.

// The paper's scalar residual ||E_i|| over the 14-vector (forward differences).
struct PaperResidual {
  double u, v;
  Eigen::Vector3d h;

  bool operator()(const double* q, double* residual) const {
    double e[3];
    if (!(HandResidual(q, geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]),
                       std::tan(q[kTheta]), u, v, h.data(), e) > 0.0)) {
      return false;
    }
    residual[0] = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    return true;
  }
};

}  // namespace

double PaperDifferenceStep(double x) {
  static const double kRelative = ceres::NumericDiffOptions().relative_step_size;
  static const double kMin = std::sqrt(std::numeric_limits<double>::epsilon());
  return std::max(kMin, std::abs(x) * kRelative);
}

const PaperTrigCache::Entry& PaperTrigCache::Get(const double* x, bool steps) {
  const std::array<double, 4> key{x[kOmega], x[kPhi], x[kVarphi], x[kTheta]};
  Entry* e = nullptr;
  for (int n = 0; n < size_ && e == nullptr; ++n) {  // newest first
    Entry& c = entries_[(newest_ - n + kSize) % kSize];
    if (std::memcmp(c.key.data(), key.data(), sizeof(key)) == 0) e = &c;
  }
  if (e == nullptr) {
    newest_ = (newest_ + 1) % kSize;
    size_ = std::min(size_ + 1, kSize);
    e = &entries_[newest_];
    e->key = key;
    e->rotation = geometry::RotationZYZ(x[kOmega], x[kPhi], x[kVarphi]);
    e->tan_theta = std::tan(x[kTheta]);
    e->has_steps = false;
  }
  if (steps && !e->has_steps) {
    for (int a = 0; a < 3; ++a) {
      double angle[3] = {x[kOmega], x[kPhi], x[kVarphi]};
      angle[a] = angle[a] + PaperDifferenceStep(angle[a]);
      e->rotation_step[a] = geometry::RotationZYZ(angle[0], angle[1], angle[2]);
    }
    e->tan_theta_step = std::tan(x[kTheta] + PaperDifferenceStep(x[kTheta]));
    e->has_steps = true;
  }
  return *e;
}

namespace {

// ||E_h|| of a camera point, as PaperResidual computes it from HandResidual.
double HandErrorNorm(const double* q, const Eigen::Matrix3d& rot, const double* camera_point,
                     const Eigen::Vector3d& h) {
  const Eigen::Vector3d hand = CameraToHand(q, rot, camera_point);
  const double e[3] = {h[0] - hand[0], h[1] - hand[1], h[2] - hand[2]};
  return std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
}

// PaperResidual with its forward differences computed from the parts that change: the camera
// point depends on f..theta only, the rotation on omega, phi, varphi only.
class PaperCost final : public ceres::SizedCostFunction<1, kNumParams> {
 public:
  PaperCost(double u, double v, const Eigen::Vector3d& h, PaperTrigCache* cache)
      : u_(u), v_(v), h_(h), cache_(cache) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double* x = parameters[0];
    const bool jacobian = jacobians != nullptr && jacobians[0] != nullptr;
    const PaperTrigCache::Entry& t = cache_->Get(x, jacobian);
    double cp[3];
    if (!(PixelToCamera(x, t.tan_theta, u_, v_, cp) > 0.0)) return false;
    const double r0 = HandErrorNorm(x, t.rotation, cp, h_);
    residuals[0] = r0;
    if (!jacobian) return true;
    double xp[kNumParams];
    std::copy(x, x + kNumParams, xp);
    for (int j = 0; j < kNumParams; ++j) {
      const double delta = PaperDifferenceStep(x[j]);
      xp[j] = x[j] + delta;
      double r;
      if (j <= kTheta) {  // the camera point moves
        double cpj[3];
        if (!(PixelToCamera(xp, j == kTheta ? t.tan_theta_step : t.tan_theta, u_, v_, cpj) > 0.0)) {
          return false;
        }
        r = HandErrorNorm(xp, t.rotation, cpj, h_);
      } else if (j <= kVarphi) {  // the rotation moves
        r = HandErrorNorm(xp, t.rotation_step[j - kOmega], cp, h_);
      } else {  // the translation moves
        r = HandErrorNorm(xp, t.rotation, cp, h_);
      }
      xp[j] = x[j];
      jacobians[0][j] = (r - r0) * (1.0 / delta);
    }
    return true;
  }

 private:
  double u_, v_;
  Eigen::Vector3d h_;
  PaperTrigCache* cache_;
};

}  // namespace

ceres::CostFunction* NewPaperCost(double u, double v, const Eigen::Vector3d& reference_in_hand,
                                  PaperTrigCache* cache) {
  if (cache != nullptr) return new PaperCost(u, v, reference_in_hand, cache);
  return new ceres::NumericDiffCostFunction<PaperResidual, ceres::FORWARD, 1, kNumParams>(
      new PaperResidual{u, v, reference_in_hand});
}

namespace {

// ModernResidual with an analytic Jacobian: the residual is computed as HandResidual computes it
// (the same value to the bit), the derivatives by the chain rule through the camera point
// cP = (H / D) [Xd, Yd, f s] (model.h PixelToCamera) and Eigen's quaternion rotation
// v' = p + w uv + qv x uv, uv = 2 qv x p, differentiated as written (the manifold projects out
// the component off the unit sphere).
class ModernCost final : public ceres::SizedCostFunction<3, 8, 4, 3> {
 public:
  ModernCost(double u, double v, const Eigen::Vector3d& h) : u_(u), v_(v), h_(h) {}

  // What all points of one evaluation share: the parameters in paper order, the rotation as a
  // matrix (Eigen's quaternion rotation of the unit vectors) and tan(theta).
  struct Shared {
    double q[kNumParams];
    const double* quat;
    Eigen::Matrix3d m;
    double tan_theta;
  };

  static Shared Prepare(double const* const* p) { return Prepare(p[0], p[1], p[2]); }

  // The same from the 8 intrinsics, the quaternion and the 3 translations.
  static Shared Prepare(const double* intrinsics, const double* quat, const double* translation) {
    Shared sh;
    for (int i = 0; i <= kTheta; ++i) sh.q[i] = intrinsics[i];
    sh.q[kOmega] = sh.q[kPhi] = sh.q[kVarphi] = 0.0;
    sh.q[kTx] = translation[0];
    sh.q[kTy] = translation[1];
    sh.q[kTz] = translation[2];
    sh.quat = quat;
    const Eigen::Quaterniond rot(sh.quat[3], sh.quat[0], sh.quat[1], sh.quat[2]);
    for (int c = 0; c < 3; ++c) sh.m.col(c) = rot * Eigen::Vector3d::Unit(c);
    sh.tan_theta = std::tan(sh.q[kTheta]);
    return sh;
  }

  bool Evaluate(double const* const* p, double* residual, double** jac) const override {
    return EvaluateWith(Prepare(p), residual, jac);
  }

  // E_h = h - (R_C cP + t) with R_C = m, and its Jacobian.
  bool EvaluateWith(const Shared& sh, double* residual, double** jac) const {
    const double* q = sh.q;
    const double* quat = sh.quat;
    const double tan_theta = sh.tan_theta;
    const Eigen::Matrix3d& m = sh.m;
    double camera[3];
    if (!(PixelToCamera(q, tan_theta, u_, v_, camera) > 0.0)) return false;
    const Eigen::Vector3d hand = m * Eigen::Vector3d(camera[0], camera[1], camera[2]) +
                                 Eigen::Vector3d(q[kTx], q[kTy], q[kTz]);
    for (int r = 0; r < 3; ++r) residual[r] = h_[r] - hand[r];
    if (jac == nullptr) return true;

    double xd, yd;
    const double s = DistortedSensorPoint(q, u_, v_, &xd, &yd);
    const double f = q[kF], k = q[kK];
    const double d = yd + f * tan_theta * s;
    const double g = q[kH] / d;
    const Eigen::Vector3d cp(g * xd, g * yd, g * f * s);
    // dcP for a change (dxd, dyd, df, dk, dtan, dh) of the camera model's inputs.
    auto camera_derivative = [&](double dxd, double dyd, double df, double dk, double dtan,
                                 double dh) {
      const double ds = 2.0 * k * (xd * dxd + yd * dyd) + dk * (xd * xd + yd * yd);
      const double dd = dyd + df * tan_theta * s + f * dtan * s + f * tan_theta * ds;
      const double dg = dh / d - g * dd / d;
      return Eigen::Vector3d(dg * xd + g * dxd, dg * yd + g * dyd,
                             dg * f * s + g * (df * s + f * ds));
    };
    const double dtan = 1.0 + tan_theta * tan_theta;
    const Eigen::Vector3d dcp[8] = {camera_derivative(0, 0, 1, 0, 0, 0),            // f
                                    camera_derivative(u_ - q[kCu], 0, 0, 0, 0, 0),  // Su
                                    camera_derivative(0, v_ - q[kCv], 0, 0, 0, 0),  // Sv
                                    camera_derivative(-q[kSu], 0, 0, 0, 0, 0),      // Cu
                                    camera_derivative(0, -q[kSv], 0, 0, 0, 0),      // Cv
                                    camera_derivative(0, 0, 0, 1, 0, 0),            // k
                                    camera_derivative(0, 0, 0, 0, 0, 1),            // H
                                    camera_derivative(0, 0, 0, 0, dtan, 0)};        // theta
    if (jac[0] != nullptr) {  // 3 x 8, row-major
      for (int i = 0; i < 8; ++i) {
        const Eigen::Vector3d de = -(m * dcp[i]);
        for (int r = 0; r < 3; ++r) jac[0][8 * r + i] = de[r];
      }
    }
    if (jac[1] != nullptr) {  // 3 x 4, row-major, quaternion order x, y, z, w
      const Eigen::Vector3d qv(quat[0], quat[1], quat[2]);
      const double w = quat[3];
      const Eigen::Vector3d uv = 2.0 * qv.cross(cp);
      for (int c = 0; c < 3; ++c) {
        const Eigen::Vector3d e = Eigen::Vector3d::Unit(c);
        const Eigen::Vector3d duv = 2.0 * e.cross(cp);
        const Eigen::Vector3d dv = w * duv + e.cross(uv) + qv.cross(duv);
        for (int r = 0; r < 3; ++r) jac[1][4 * r + c] = -dv[r];
      }
      for (int r = 0; r < 3; ++r) jac[1][4 * r + 3] = -uv[r];
    }
    if (jac[2] != nullptr) {  // 3 x 3: -I
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) jac[2][3 * r + c] = r == c ? -1.0 : 0.0;
    }
    return true;
  }

 private:
  double u_, v_;
  Eigen::Vector3d h_;
};

}  // namespace

ceres::CostFunction* NewModernQuaternionCost(double u, double v,
                                             const Eigen::Vector3d& reference_in_hand) {
  return new ModernCost(u, v, reference_in_hand);
}

namespace {

// All points' ModernCost in one residual block (3 m residuals over the same three blocks): the
// same residuals and Jacobian rows, without Ceres' per-block bookkeeping. Only without a robust
// loss, which Ceres applies per residual block.
//
// The intrinsics and translation blocks may hold only the free parameters of their group (the
// held ones are constants of the cost): the Jacobian columns of those are the full cost's, so the
// solve is the one with a SubsetManifold, without Ceres multiplying every Jacobian by the
// manifold's selection matrix.
//
// The last evaluation is kept: Ceres' bounded LM evaluates the Jacobian at the trial point in its
// projected line search and again once the step is accepted (and the residuals in between), at
// the same parameter values; those repeats are copies. Not thread-safe: one cost per problem,
// solved on one thread.
class ModernBatchCost final : public ceres::CostFunction {
 public:
  ModernBatchCost(const FitnessData& data, const Vector14d& held,
                  const std::array<bool, kNumParams>& held_mask)
      : held_(held) {
    for (Eigen::Index i = 0; i < data.size(); ++i) {
      points_.push_back(
          std::make_unique<ModernCost>(data.u(i), data.v(i), data.ReferenceInHand(i)));
    }
    intrinsics_ = PackedEntries(held_mask, kF, kTheta + 1);
    translation_ = PackedEntries(held_mask, kTx, 3);
    set_num_residuals(3 * static_cast<int>(points_.size()));
    *mutable_parameter_block_sizes() = {static_cast<int>(intrinsics_.size()), 4,
                                        static_cast<int>(translation_.size())};
  }

  /// Which parameters of a group (0-based within it) its block holds, in order.
  const std::vector<int>& intrinsics() const { return intrinsics_; }
  const std::vector<int>& translation() const { return translation_; }

  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const int n0 = static_cast<int>(intrinsics_.size());
    const int n2 = static_cast<int>(translation_.size());
    const int sizes[3] = {n0, 4, n2};
    const int rows = num_residuals();
    // The parameter values, as the key of the kept evaluation.
    key_.resize(n0 + 4 + n2);
    std::copy(p[0], p[0] + n0, key_.begin());
    std::copy(p[1], p[1] + 4, key_.begin() + n0);
    std::copy(p[2], p[2] + n2, key_.begin() + n0 + 4);
    bool wanted[3] = {false, false, false};
    if (jac != nullptr)
      for (int b = 0; b < 3; ++b) wanted[b] = jac[b] != nullptr;
    const bool same_point =
        has_kept_ && kept_key_.size() == key_.size() &&
        std::memcmp(kept_key_.data(), key_.data(), key_.size() * sizeof(double)) == 0;
    bool hit = same_point;
    for (int b = 0; b < 3; ++b) hit = hit && (!wanted[b] || kept_jac_[b]);
    if (hit) {
      std::copy(kept_residuals_.begin(), kept_residuals_.end(), residuals);
      for (int b = 0; b < 3; ++b) {
        if (wanted[b]) std::copy(kept_[b].begin(), kept_[b].end(), jac[b]);
      }
      return true;
    }

    double intrinsics[kTheta + 1], translation[3];
    for (int i = 0; i <= kTheta; ++i) intrinsics[i] = held_[kF + i];
    for (int i = 0; i < 3; ++i) translation[i] = held_[kTx + i];
    for (int k = 0; k < n0; ++k) intrinsics[intrinsics_[k]] = p[0][k];
    for (int k = 0; k < n2; ++k) translation[translation_[k]] = p[2][k];
    const ModernCost::Shared shared = ModernCost::Prepare(intrinsics, p[1], translation);
    double j0[3 * (kTheta + 1)], j2[9];
    for (std::size_t i = 0; i < points_.size(); ++i) {
      double* rows_of[3] = {wanted[0] ? j0 : nullptr, wanted[1] ? jac[1] + 3 * i * 4 : nullptr,
                            wanted[2] ? j2 : nullptr};
      if (!points_[i]->EvaluateWith(shared, residuals + 3 * i,
                                    jac != nullptr ? rows_of : nullptr)) {
        has_kept_ = false;
        return false;
      }
      for (int r = 0; r < 3; ++r) {
        if (wanted[0]) {
          double* out = jac[0] + (3 * i + r) * n0;
          for (int k = 0; k < n0; ++k) out[k] = j0[(kTheta + 1) * r + intrinsics_[k]];
        }
        if (wanted[2]) {
          double* out = jac[2] + (3 * i + r) * n2;
          for (int k = 0; k < n2; ++k) out[k] = j2[3 * r + translation_[k]];
        }
      }
    }
    has_kept_ = true;
    kept_key_.swap(key_);
    kept_residuals_.assign(residuals, residuals + rows);
    for (int b = 0; b < 3; ++b) {
      kept_jac_[b] = wanted[b];
      if (wanted[b]) kept_[b].assign(jac[b], jac[b] + static_cast<std::size_t>(rows) * sizes[b]);
    }
    return true;
  }

 private:
  std::vector<std::unique_ptr<ModernCost>> points_;
  Vector14d held_;
  std::vector<int> intrinsics_, translation_;
  // The kept evaluation.
  mutable std::vector<double> key_, kept_key_, kept_residuals_;
  mutable std::array<std::vector<double>, 3> kept_;
  mutable std::array<bool, 3> kept_jac_{};
  mutable bool has_kept_ = false;
};

}  // namespace

std::vector<int> PackedEntries(const std::array<bool, kNumParams>& held_mask, int first, int size) {
  std::vector<int> entries;
  for (int i = 0; i < size; ++i)
    if (!held_mask[first + i]) entries.push_back(i);
  // A group with no free parameter keeps all of them (its block is then held constant).
  if (entries.empty())
    for (int i = 0; i < size; ++i) entries.push_back(i);
  return entries;
}

ceres::CostFunction* NewModernBatchCost(const FitnessData& data) {
  return new ModernBatchCost(data, Vector14d::Zero(), {});
}

ceres::CostFunction* NewModernBatchCost(const FitnessData& data, const Vector14d& held,
                                        const std::array<bool, kNumParams>& held_mask) {
  return new ModernBatchCost(data, held, held_mask);
}

}  // namespace hmlvs::solvers
