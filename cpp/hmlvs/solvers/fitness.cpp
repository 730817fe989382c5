#include "hmlvs/solvers/fitness.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace hmlvs {

FitnessData::FitnessData(PixelsRef pixels, PosesRef poses, Points3Ref references) {
  const Eigen::Index m = pixels.rows();
  if (poses.rows() != m || references.rows() != m) {
    std::ostringstream msg;
    msg << "pixels has " << m << " rows, poses " << poses.rows() << " and reference points "
        << references.rows() << "; they must match";
    throw std::invalid_argument(msg.str());
  }
  ValidatePoses(poses);
  for (Eigen::Index i = 0; i < m; ++i) {
    if (!pixels.row(i).allFinite() || !references.row(i).allFinite()) {
      std::ostringstream msg;
      msg << "calibration point " << i << " has a non-finite pixel or reference point";
      throw std::invalid_argument(msg.str());
    }
  }
  u_.resize(m);
  v_.resize(m);
  hx_.resize(m);
  hy_.resize(m);
  hz_.resize(m);
  for (Eigen::Index i = 0; i < m; ++i) {
    const double* p = poses.row(i).data();
    Eigen::Matrix3d r;
    r << p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10];
    const Eigen::Vector3d h =
        r.transpose() * (references.row(i).transpose() - Eigen::Vector3d(p[3], p[7], p[11]));
    u_[i] = pixels(i, 0);
    v_[i] = pixels(i, 1);
    hx_[i] = h[0];
    hy_[i] = h[1];
    hz_[i] = h[2];
  }
}

namespace {

// Points per block of the hot loop: the blocks' per-point values live on the stack (8 KiB).
constexpr Eigen::Index kBlock = 512;

// The hot loop: the model's HandResidual (one division per point, see PixelToCamera) on the
// reference points stored in their hand frames, in blocks of two passes:
//  1. per point, the squared error and the laser-plane test. The compiler vectorises this loop
//     across points once HandResidual is inlined. (Not `omp simd`: that pragma is lowered before
//     inlining and turns the model's small local arrays into per-lane arrays, which blocks
//     vectorisation.)
//  2. their sum and minimum, with `#pragma omp simd` reductions (-fopenmp-simd, no OpenMP
//     runtime), which allows the reordered, vectorised sum.
// On x86-64 an AVX2 clone is chosen at load time when the CPU has it; each machine always runs
// the same clone, so results do not depend on the thread count.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__AVX2__)
__attribute__((target_clones("avx2", "default")))
#endif
double Kernel(const double* q, const Eigen::Matrix3d& hand_from_camera_rot, double tan_theta,
              const double* u, const double* v, const double* hx, const double* hy,
              const double* hz, Eigen::Index m, double* min_plane) {
  double sum = 0.0;
  double min_test = std::numeric_limits<double>::infinity();
  double err2[kBlock];
  double plane[kBlock];
  for (Eigen::Index start = 0; start < m; start += kBlock) {
    const Eigen::Index n = std::min(kBlock, m - start);
    for (Eigen::Index j = 0; j < n; ++j) {
      const Eigen::Index i = start + j;
      const double h[3] = {hx[i], hy[i], hz[i]};
      double e[3];
      plane[j] = HandResidual(q, hand_from_camera_rot, tan_theta, u[i], v[i], h, e);
      err2[j] = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
    }
#pragma omp simd reduction(+ : sum) reduction(min : min_test)
    for (Eigen::Index j = 0; j < n; ++j) {
      sum += err2[j];
      min_test = plane[j] < min_test ? plane[j] : min_test;
    }
  }
  *min_plane = min_test;
  return sum;
}

}  // namespace

double FitnessData::Evaluate(const double* q) const {
  const Eigen::Matrix3d rc = RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  double min_plane = 0.0;
  const double sum = Kernel(q, rc, std::tan(q[kTheta]), u_.data(), v_.data(), hx_.data(),
                            hy_.data(), hz_.data(), size(), &min_plane);
  if (!(min_plane > 0.0)) return std::numeric_limits<double>::infinity();
  return 0.5 * sum;
}

Eigen::VectorXd FitnessData::PointErrors(const double* q) const {
  const Eigen::Matrix3d rc = RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  const double tan_theta = std::tan(q[kTheta]);
  Eigen::VectorXd out(size());
  for (Eigen::Index i = 0; i < size(); ++i) {
    double e[3];
    if (HandResidual(q, rc, tan_theta, u_[i], v_[i], ReferenceInHand(i).data(), e) > 0.0) {
      out[i] = Eigen::Vector3d(e[0], e[1], e[2]).norm();
    } else {
      out[i] = std::numeric_limits<double>::quiet_NaN();
    }
  }
  return out;
}

}  // namespace hmlvs
