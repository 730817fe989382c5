#include "hmlvs/geometry/hand_eye.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>
#include <stdexcept>
#include <string>

#include "hmlvs/geometry/geometry.h"

namespace hmlvs::geometry {

Eigen::Matrix4d MeanTransform(const std::vector<Eigen::Matrix4d>& transforms) {
  if (transforms.empty()) throw std::invalid_argument("no transforms to average");
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  for (const auto& m : transforms) {
    sum += m.topLeftCorner<3, 3>();
    t += m.topRightCorner<3, 1>();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  Eigen::Matrix4d out = Eigen::Matrix4d::Identity();
  out.topLeftCorner<3, 3>() = svd.matrixU() * d * svd.matrixV().transpose();
  out.topRightCorner<3, 1>() = t / static_cast<double>(transforms.size());
  return out;
}

Eigen::Matrix4d HandEyeParkMartin(const std::vector<Eigen::Matrix4d>& base_from_hand,
                                  const std::vector<Eigen::Matrix4d>& camera_from_board,
                                  double min_angle) {
  if (base_from_hand.size() != camera_from_board.size()) {
    throw std::invalid_argument("hand-eye: " + std::to_string(base_from_hand.size()) +
                                " robot poses but " + std::to_string(camera_from_board.size()) +
                                " camera poses");
  }
  const std::size_t n = base_from_hand.size();
  for (std::size_t i = 0; i < n; ++i) {
    CheckTransform(base_from_hand[i], "robot pose " + std::to_string(i));
    CheckTransform(camera_from_board[i], "camera pose " + std::to_string(i));
  }
  struct Motion {
    Eigen::Matrix4d a, b;
  };
  std::vector<Motion> motions;
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      // A = hand_i_from_hand_j, B = camera_i_from_camera_j: A X = X B.
      const Eigen::Matrix4d a = base_from_hand[i].inverse() * base_from_hand[j];
      const Eigen::Matrix4d b = camera_from_board[i] * camera_from_board[j].inverse();
      const Eigen::AngleAxisd aa(Eigen::Matrix3d(a.topLeftCorner<3, 3>()));
      const Eigen::AngleAxisd ab(Eigen::Matrix3d(b.topLeftCorner<3, 3>()));
      if (aa.angle() < min_angle || ab.angle() < min_angle) continue;
      m += (ab.axis() * ab.angle()) * (aa.axis() * aa.angle()).transpose();
      motions.push_back({a, b});
    }
  }
  if (motions.size() < 2) {
    throw std::invalid_argument(
        "hand-eye calibration needs at least two pairs of views whose orientations differ by "
        "more than " +
        std::to_string(min_angle * 180.0 / M_PI) + " degrees; got " +
        std::to_string(motions.size()));
  }
  // R_X = (M^T M)^(-1/2) M^T, through the SVD M = U S V^T: R_X = V U^T (det-corrected).
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d s = svd.singularValues();
  if (!(s[1] > 1e-3 * s[0])) {
    throw std::invalid_argument(
        "hand-eye calibration needs robot rotations about at least two non-parallel axes; the "
        "poses rotate about one axis only");
  }
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  const Eigen::Matrix3d rx = svd.matrixV() * d * svd.matrixU().transpose();
  // Translation: (R_A - I) t_X = R_X t_B - t_A, stacked, least squares.
  Eigen::MatrixXd c(3 * motions.size(), 3);
  Eigen::VectorXd rhs(3 * motions.size());
  for (std::size_t k = 0; k < motions.size(); ++k) {
    c.middleRows<3>(3 * k) = motions[k].a.topLeftCorner<3, 3>() - Eigen::Matrix3d::Identity();
    rhs.segment<3>(3 * k) =
        rx * motions[k].b.topRightCorner<3, 1>() - motions[k].a.topRightCorner<3, 1>();
  }
  Eigen::Matrix4d x = Eigen::Matrix4d::Identity();
  x.topLeftCorner<3, 3>() = rx;
  x.topRightCorner<3, 1>() = c.colPivHouseholderQr().solve(rhs);
  return x;
}

}  // namespace hmlvs::geometry
