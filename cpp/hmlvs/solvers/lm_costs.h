// The residual blocks of the paper model's LM solves (RunLm), one per calibration point. Each
// evaluates the model's HandResidual (model/paper.h); they differ in parametrisation and
// differentiation. Exposed so that their Jacobians can be tested; the caller owns the returned
// object.
#pragma once

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <array>
#include <vector>

#include "hmlvs/model/paper_fitness.h"

namespace hmlvs::solvers {

/// The trigonometry of the paper-mode residual: R_C (ZYZ Euler angles) and tan(theta), which
/// depend on 4 of the 14 parameters, at a parameter vector x and, for its forward differences,
/// at x with one of those four moved by its difference step. All points of a problem are
/// evaluated at the same vectors, so they share one entry per x instead of computing 7 sines,
/// cosines and tangents per evaluation. The key is the four values' exact bits and the values
/// are computed by the same functions as without the cache, so nothing changes by a bit.
/// Not thread-safe: one cache per problem, solved on one thread.
class PaperTrigCache {
 public:
  struct Entry {
    std::array<double, 4> key;  ///< omega, phi, varphi, theta
    Eigen::Matrix3d rotation;   ///< RotationZYZ(omega, phi, varphi)
    double tan_theta;
    bool has_steps;
    std::array<Eigen::Matrix3d, 3> rotation_step;  ///< omega, phi or varphi + its step
    double tan_theta_step;                         ///< tan(theta + its step)
  };
  /// The entry for parameter vector x (paper order), computed on a miss; with `steps` the
  /// values at the difference steps too.
  const Entry& Get(const double* x, bool steps);

 private:
  static constexpr int kSize = 4;  // x and the trial steps of the LM
  std::array<Entry, kSize> entries_{};
  int size_ = 0;
  int newest_ = -1;
};

/// The forward-difference step of parameter value x, as Ceres' NumericDiffCostFunction takes
/// it (FORWARD, default options): max(sqrt(eps), 1e-6 |x|).
double PaperDifferenceStep(double x);

/// Paper mode: the scalar residual ||E_i|| over one 14-parameter block (paper order), Jacobian
/// by forward differences with Ceres' default relative step.
/// With a cache (owned by the caller, shared by all points of one problem), a cost function that
/// computes each difference from the parts that change (the trigonometry once per vector, the
/// camera point only when an intrinsic, H or theta moves); without, Ceres'
/// NumericDiffCostFunction over the plain residual, the reference that the first must match bit
/// for bit (residual and Jacobian).
ceres::CostFunction* NewPaperCost(double u, double v, const Eigen::Vector3d& reference_in_hand,
                                  PaperTrigCache* cache = nullptr);

/// Modern mode: the three components of E_h, analytic Jacobian (the chain rule through the
/// camera point and the quaternion rotation as Eigen computes it). Three blocks: f, Su, Sv, Cu,
/// Cv, k, H, theta (8, paper order), the hand_from_camera rotation as an Eigen quaternion
/// [x, y, z, w] (4, solved on ceres::EigenQuaternionManifold), tx, ty, tz (3).
ceres::CostFunction* NewModernQuaternionCost(double u, double v,
                                             const Eigen::Vector3d& reference_in_hand);

/// The same for all points of `data` in one residual block (3 m residuals, rows in point
/// order), used when no robust loss is set.
ceres::CostFunction* NewModernBatchCost(const paper::FitnessData& data);

/// The same with the intrinsics and translation blocks holding only the parameters of their group
/// that `held_mask` leaves free (all of the group when none is), in paper order; the held ones
/// take their values from `held`. The Jacobian columns are the full cost's free columns.
ceres::CostFunction* NewModernBatchCost(const paper::FitnessData& data,
                                        const paper::Vector14d& held,
                                        const std::array<bool, paper::kNumParams>& held_mask);

/// Which parameters of the group [first, first + size) (paper order) the packed block of the cost
/// above holds, 0-based within the group: those `held_mask` leaves free, all of the group when
/// none is.
std::vector<int> PackedEntries(const std::array<bool, paper::kNumParams>& held_mask, int first,
                               int size);

}  // namespace hmlvs::solvers
