#include "hmlvs/solvers/fitness.h"

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

struct KernelParams {
  double f, su, sv, cu, cv, k, h, ftan;
  double r[9];
  double tx, ty, tz;
};

// The hot loop, with one division per point: with s = 1 + k r^2 and D = Yd + f tan(theta) s,
// the camera point rho [Xu, Yu, f] equals (H / D) [Xd, Yd, f s], and the ray meets the plane
// iff D s > 0 (the model's Yu + f tan(theta) = D / s). On x86-64 an AVX2 clone is chosen at
// load time when the CPU has it; each machine always runs the same clone, so results do not
// depend on the thread count.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__AVX2__)
__attribute__((target_clones("avx2", "default")))
#endif
double Kernel(const KernelParams& p, const double* u, const double* v, const double* hx,
              const double* hy, const double* hz, Eigen::Index m, double* min_sign) {
  double sum = 0.0;
  double min_ds = std::numeric_limits<double>::infinity();
#pragma omp simd reduction(+ : sum) reduction(min : min_ds)
  for (Eigen::Index i = 0; i < m; ++i) {
    const double xd = p.su * (u[i] - p.cu);
    const double yd = p.sv * (v[i] - p.cv);
    const double s = 1.0 + p.k * (xd * xd + yd * yd);
    const double d = yd + p.ftan * s;
    const double ds = d * s;
    min_ds = ds < min_ds ? ds : min_ds;
    const double g = p.h / d;
    const double cx = g * xd, cy = g * yd, cz = g * p.f * s;
    const double ex = hx[i] - (p.r[0] * cx + p.r[1] * cy + p.r[2] * cz + p.tx);
    const double ey = hy[i] - (p.r[3] * cx + p.r[4] * cy + p.r[5] * cz + p.ty);
    const double ez = hz[i] - (p.r[6] * cx + p.r[7] * cy + p.r[8] * cz + p.tz);
    sum += ex * ex + ey * ey + ez * ez;
  }
  *min_sign = min_ds;
  return sum;
}

}  // namespace

double FitnessData::Evaluate(const double* q) const {
  const Eigen::Matrix3d rc = RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  KernelParams p;
  p.f = q[kF];
  p.su = q[kSu];
  p.sv = q[kSv];
  p.cu = q[kCu];
  p.cv = q[kCv];
  p.k = q[kK];
  p.h = q[kH];
  p.ftan = q[kF] * std::tan(q[kTheta]);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) p.r[3 * r + c] = rc(r, c);
  p.tx = q[kTx];
  p.ty = q[kTy];
  p.tz = q[kTz];
  double min_ds = 0.0;
  const double sum =
      Kernel(p, u_.data(), v_.data(), hx_.data(), hy_.data(), hz_.data(), size(), &min_ds);
  if (!(min_ds > 0.0)) return std::numeric_limits<double>::infinity();
  return 0.5 * sum;
}

Eigen::VectorXd FitnessData::PointErrors(const double* q) const {
  const Eigen::Matrix3d rc = RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  const double tan_theta = std::tan(q[kTheta]);
  const Eigen::Vector3d t(q[kTx], q[kTy], q[kTz]);
  Eigen::VectorXd out(size());
  for (Eigen::Index i = 0; i < size(); ++i) {
    double cp[3];
    if (PixelToCamera(q, tan_theta, u_[i], v_[i], cp) > 0.0) {
      out[i] = (ReferenceInHand(i) - (rc * Eigen::Vector3d(cp[0], cp[1], cp[2]) + t)).norm();
    } else {
      out[i] = std::numeric_limits<double>::quiet_NaN();
    }
  }
  return out;
}

}  // namespace hmlvs
