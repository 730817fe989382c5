// Synthetic scenes with known parameters for the C++ tests.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <random>

#include "hmlvs/model/paper.h"

namespace hmlvs::test {

constexpr double kPi = 3.14159265358979323846;

/// Table 2 nominal parameters (docs/model.md).
inline paper::Vector14d Nominal() {
  paper::Vector14d q;
  q << 8.0, 0.0074, 0.0074, 320.0, 240.0, 0.0, 140.0, 5.0 * kPi / 36.0, 0.0, 0.0, 0.0, 60.0, 0.0,
      -45.0;
  return q;
}

/// A generic parameter vector: radial distortion, no gimbal lock (phi != 0), ty != 0.
inline paper::Vector14d Generic() {
  paper::Vector14d q = Nominal();
  q[paper::kK] = 0.01;
  q[paper::kOmega] = 0.05;
  q[paper::kPhi] = 0.1;
  q[paper::kVarphi] = -0.03;
  q[paper::kTy] = 2.0;
  return q;
}

/// Table 2 lower and upper bounds.
inline void Table2Bounds(paper::Vector14d* lower, paper::Vector14d* upper) {
  const double p16 = kPi / 16.0;
  *lower << 6, 0.005, 0.005, 300, 220, 0, 120, 0, -p16, -p16, -p16, 40, -10, -60;
  *upper << 10, 0.01, 0.01, 340, 260, 0.1, 150, kPi / 4, p16, p16, p16, 80, 10, -30;
}

/// Stripe pixels, base_from_hand poses with generic rotations, and the exact base-frame points
/// that parameters q give (docs/model.md simulation protocol, noise-free).
struct Scene {
  RowMatX2 pixels;
  RowMatX16 poses;
  RowMatX3 points;
};

/// m stripe pixels uniform in [0, u_max] x [v_min, v_max] and base_from_hand poses with generic
/// rotations, positions within 600 mm; no points.
inline Scene RandomPixelsAndPoses(int m, unsigned seed, double u_max, double v_min, double v_max) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uu(0.0, u_max), vv(v_min, v_max), pos(-600.0, 600.0);
  std::normal_distribution<double> g(0.0, 1.0);
  Scene s;
  s.pixels.resize(m, 2);
  s.poses.resize(m, 16);
  for (int i = 0; i < m; ++i) {
    s.pixels(i, 0) = uu(rng);
    s.pixels(i, 1) = vv(rng);
    const Eigen::Quaterniond r(g(rng), g(rng), g(rng), g(rng));
    Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
    t.topLeftCorner<3, 3>() = r.normalized().toRotationMatrix();
    t.topRightCorner<3, 1>() << pos(rng), pos(rng), pos(rng);
    for (int k = 0; k < 16; ++k) s.poses(i, k) = t(k / 4, k % 4);
  }
  return s;
}

/// A 640 x 480 camera's scene under paper parameters q.
inline Scene MakeScene(const paper::Vector14d& q, int m, unsigned seed) {
  Scene s = RandomPixelsAndPoses(m, seed, 639.0, 0.0, 479.0);
  s.points = paper::BasePointsFromPixels(q, s.pixels, s.poses, /*throw_on_invalid=*/true).points;
  return s;
}

/// Truth perturbed by up to 1e-3 relative (absolute 1e-3 for the parameters whose truth is
/// small), Su held (the scale gauge, docs/model.md: Su from the datasheet, held fixed).
inline paper::Vector14d PerturbedTruth(const paper::Vector14d& truth, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1e-3, 1e-3);
  paper::Vector14d q = truth;
  for (int j = 0; j < paper::kNumParams; ++j) {
    q[j] = std::abs(truth[j]) > 1.0 ? truth[j] * (1.0 + u(rng)) : truth[j] + u(rng);
  }
  q[paper::kSu] = truth[paper::kSu];
  return q;
}

/// Whether two vectors hold the same doubles to the bit.
template <typename Vector>
bool BitIdentical(const Vector& a, const Vector& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}

}  // namespace hmlvs::test
