// Closed-form starting values of the general model's joint calibration: hand-eye calibration
// AX = XB (Park and Martin) and the mean of rigid transforms.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace hmlvs::geometry {

/// Hand-eye calibration AX = XB by Park and Martin (1994): X = hand_from_camera from the robot's
/// base_from_hand poses and the camera's camera_from_board poses of the same views (all pairs
/// of views whose relative rotation exceeds `min_angle` radians). Throws std::invalid_argument
/// when the motions do not determine X (fewer than two pairs, or rotations about one axis only).
Eigen::Matrix4d HandEyeParkMartin(const std::vector<Eigen::Matrix4d>& base_from_hand,
                                  const std::vector<Eigen::Matrix4d>& camera_from_board,
                                  double min_angle = 0.05);

/// The mean of rigid transforms: the rotation closest (Frobenius) to the sum of rotations,
/// and the mean translation.
Eigen::Matrix4d MeanTransform(const std::vector<Eigen::Matrix4d>& transforms);

}  // namespace hmlvs::geometry
