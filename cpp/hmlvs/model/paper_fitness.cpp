#include "hmlvs/model/paper_fitness.h"

#include <cmath>
#include <limits>

namespace hmlvs::paper {

FitnessData::FitnessData(PixelsRef pixels, PosesRef poses, Points3Ref references)
    : points_(pixels, poses, references) {}

namespace {

// One point's share of the fitness: the model's HandResidual (one division, see PixelToCamera),
// returned by value. The `omp simd` loop below must not take the address of its own locals:
// that pragma is lowered before inlining and turns such locals into per-lane arrays, which
// blocks vectorisation. Inside this function they are ordinary and vanish once it is inlined.
struct PointTerm {
  double squared_error;
  double plane;  // the laser-plane test D s: > 0 iff the ray meets the plane
};

inline PointTerm Term(const double* q, const Eigen::Matrix3d& hand_from_camera_rot,
                      double tan_theta, double u, double v, double hx, double hy, double hz) {
  const double h[3] = {hx, hy, hz};
  double e[3];
  PointTerm t;
  t.plane = HandResidual(q, hand_from_camera_rot, tan_theta, u, v, h, e);
  t.squared_error = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
  return t;
}

// The hot loop over the reference points stored in their hand frames, vectorised across points
// with `#pragma omp simd` (-fopenmp-simd, no OpenMP runtime), which also allows the reordered
// sum and minimum. On x86-64 an AVX2 clone is chosen at load time when the CPU has it; each
// machine always runs the same clone, so results do not depend on the thread count.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__AVX2__)
__attribute__((target_clones("avx2", "default")))
#endif
double Kernel(const double* q, const Eigen::Matrix3d& hand_from_camera_rot, double tan_theta,
              const double* u, const double* v, const double* hx, const double* hy,
              const double* hz, Eigen::Index m, double* min_plane) {
  double sum = 0.0;
  double min_test = std::numeric_limits<double>::infinity();
#pragma omp simd reduction(+ : sum) reduction(min : min_test)
  for (Eigen::Index i = 0; i < m; ++i) {
    const PointTerm t = Term(q, hand_from_camera_rot, tan_theta, u[i], v[i], hx[i], hy[i], hz[i]);
    min_test = t.plane < min_test ? t.plane : min_test;
    sum += t.squared_error;
  }
  *min_plane = min_test;
  return sum;
}

}  // namespace

double FitnessData::Evaluate(const double* q) const {
  const Eigen::Matrix3d rc = geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  double min_plane = 0.0;
  const double sum =
      Kernel(q, rc, std::tan(q[kTheta]), points_.u.data(), points_.v.data(), points_.hx.data(),
             points_.hy.data(), points_.hz.data(), size(), &min_plane);
  if (!(min_plane > 0.0)) return std::numeric_limits<double>::infinity();
  return 0.5 * sum;
}

Eigen::VectorXd FitnessData::PointErrors(const double* q) const {
  const Eigen::Matrix3d rc = geometry::RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  const double tan_theta = std::tan(q[kTheta]);
  Eigen::VectorXd out(size());
  for (Eigen::Index i = 0; i < size(); ++i) {
    double e[3];
    if (HandResidual(q, rc, tan_theta, u(i), v(i), ReferenceInHand(i).data(), e) > 0.0) {
      out[i] = Eigen::Vector3d(e[0], e[1], e[2]).norm();
    } else {
      out[i] = std::numeric_limits<double>::quiet_NaN();
    }
  }
  return out;
}

}  // namespace hmlvs::paper
