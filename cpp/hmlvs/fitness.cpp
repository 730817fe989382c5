#include "hmlvs/fitness.h"

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

double FitnessData::Evaluate(const double* q) const {
  const Eigen::Matrix3d rc = RotationZYZ(q[kOmega], q[kPhi], q[kVarphi]);
  const double tan_theta = std::tan(q[kTheta]);
  const double f = q[kF], su = q[kSu], sv = q[kSv], cu = q[kCu], cv = q[kCv], k = q[kK],
               h = q[kH], ftan = f * tan_theta;
  const double r00 = rc(0, 0), r01 = rc(0, 1), r02 = rc(0, 2);
  const double r10 = rc(1, 0), r11 = rc(1, 1), r12 = rc(1, 2);
  const double r20 = rc(2, 0), r21 = rc(2, 1), r22 = rc(2, 2);
  const double tx = q[kTx], ty = q[kTy], tz = q[kTz];
  const Eigen::Index m = size();
  const double* u = u_.data();
  const double* v = v_.data();
  const double* hx = hx_.data();
  const double* hy = hy_.data();
  const double* hz = hz_.data();
  double sum = 0.0;
  double min_denom = std::numeric_limits<double>::infinity();
  for (Eigen::Index i = 0; i < m; ++i) {
    const double xd = su * (u[i] - cu);
    const double yd = sv * (v[i] - cv);
    const double inv = 1.0 / (1.0 + k * (xd * xd + yd * yd));
    const double xu = xd * inv;
    const double yu = yd * inv;
    const double denom = yu + ftan;
    min_denom = denom < min_denom ? denom : min_denom;
    const double rho = h / denom;
    const double cx = rho * xu, cy = rho * yu, cz = rho * f;
    const double ex = hx[i] - (r00 * cx + r01 * cy + r02 * cz + tx);
    const double ey = hy[i] - (r10 * cx + r11 * cy + r12 * cz + ty);
    const double ez = hz[i] - (r20 * cx + r21 * cy + r22 * cz + tz);
    sum += ex * ex + ey * ey + ez * ez;
  }
  if (!(min_denom > 0.0)) return std::numeric_limits<double>::infinity();
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
