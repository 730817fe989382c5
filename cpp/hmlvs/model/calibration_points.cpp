#include "hmlvs/model/calibration_points.h"

#include <sstream>
#include <stdexcept>

#include "hmlvs/geometry/geometry.h"

namespace hmlvs {

CalibrationPoints::CalibrationPoints(PixelsRef pixels, PosesRef poses, Points3Ref references) {
  const Eigen::Index m = pixels.rows();
  if (poses.rows() != m || references.rows() != m) {
    std::ostringstream msg;
    msg << "pixels has " << m << " rows, poses " << poses.rows() << " and reference points "
        << references.rows() << "; they must match";
    throw std::invalid_argument(msg.str());
  }
  geometry::ValidatePoses(poses);
  for (Eigen::Index i = 0; i < m; ++i) {
    if (!pixels.row(i).allFinite() || !references.row(i).allFinite()) {
      std::ostringstream msg;
      msg << "calibration point " << i << " has a non-finite pixel or reference point";
      throw std::invalid_argument(msg.str());
    }
  }
  u.resize(m);
  v.resize(m);
  hx.resize(m);
  hy.resize(m);
  hz.resize(m);
  for (Eigen::Index i = 0; i < m; ++i) {
    const Eigen::Vector3d h = geometry::PoseRotation(poses, i).transpose() *
                              (references.row(i).transpose() - geometry::PosePosition(poses, i));
    u[i] = pixels(i, 0);
    v[i] = pixels(i, 1);
    hx[i] = h[0];
    hy[i] = h[1];
    hz[i] = h[2];
  }
}

}  // namespace hmlvs
