// Input checks and pose access shared by the model's batch functions (model.cpp, general.cpp).
#pragma once

#include <Eigen/Core>

#include "hmlvs/model/model.h"

namespace hmlvs {

/// Throws std::invalid_argument "<name_a> has a rows but <name_b> has b" unless a == b.
void RequireSameRows(Eigen::Index a, const char* name_a, Eigen::Index b, const char* name_b);

/// Throws std::invalid_argument naming the first row of a (rows x cols) row-major array that
/// holds a NaN or an infinity.
void RequireFinite(const double* data, Eigen::Index rows, int cols, const char* name);

/// The rotation and the position of pose i of a (m, 16) row-major array of 4x4 transforms.
inline Eigen::Matrix3d PoseRotation(PosesRef poses, Eigen::Index i) {
  Eigen::Matrix3d r;
  const double* p = poses.row(i).data();
  r << p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10];
  return r;
}

inline Eigen::Vector3d PosePosition(PosesRef poses, Eigen::Index i) {
  const double* p = poses.row(i).data();
  return Eigen::Vector3d(p[3], p[7], p[11]);
}

}  // namespace hmlvs
