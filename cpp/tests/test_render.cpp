// The simulator's board shading on a board seen square-on: levels, edges and the stripe by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "hmlvs/sim/render.h"

namespace hmlvs {
namespace {

// A pinhole camera (f = 1000 px, centre (80, 60)) of 160 x 120 px, its rays at the s x s
// sample positions, looking along +z at a board 500 mm away: 1 px is 0.5 mm on the board.
constexpr int kW = 160;
constexpr int kH = 120;

std::vector<double> SampleRays(int s) {
  std::vector<double> rays;
  for (int i = 0; i < kH * s; ++i) {
    for (int j = 0; j < kW * s; ++j) {
      const double u = (j + 0.5) / s - 0.5;
      const double v = (i + 0.5) / s - 0.5;
      rays.insert(rays.end(), {(u - 80.0) / 1000.0, (v - 60.0) / 1000.0, 1.0});
    }
  }
  return rays;
}

// Board point (x, y) = (25 + (u - 80) / 2, 25 + (v - 60) / 2) mm: pixel (u, v) of board point
// (x, y) is (80 + 2 (x - 25), 60 + 2 (y - 25)).
Eigen::Matrix4d BoardFromCamera(double z = -500.0, double x = 25.0) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.block<3, 1>(0, 3) << x, 25.0, z;
  return t;
}

BoardShading Shading(int s) {
  BoardShading o;
  o.supersample = s;
  o.rows = 4;  // squares span x in [-10, 40] mm, y in [-10, 50] mm, a 10 mm border around
  o.cols = 5;
  o.square = 10.0;
  return o;
}

TEST(Render, LevelsOfTheSquaresTheBorderAndTheTable) {
  const BoardShading o = Shading(3);
  const std::vector<double> rays = SampleRays(3);
  const Eigen::Vector4d plane(0, 1, 0, 0);  // the plane y = 0: the stripe on row v = 60
  const BoardExposure e = ShadeBoard(rays.data(), kH * 3, kW * 3, BoardFromCamera(), plane, o);
  ASSERT_EQ(e.ambient.rows(), kH);
  ASSERT_EQ(e.ambient.cols(), kW);
  EXPECT_NEAR(e.ambient(20, 40), o.ambient * o.black, 1e-12);  // square (0, 0) is dark
  EXPECT_NEAR(e.ambient(20, 60), o.ambient * o.white, 1e-12);  // its neighbour light
  EXPECT_NEAR(e.ambient(40, 60), o.ambient * o.black, 1e-12);
  EXPECT_NEAR(e.ambient(60, 120), o.ambient * o.white, 1e-12);  // the border, x = 45 mm
  EXPECT_NEAR(e.ambient(60, 150), o.ambient * o.table, 1e-12);  // beyond it, x = 60 mm
  // An edge through the pixel's centre (x = 10 mm at u = 50): half dark, half light.
  EXPECT_NEAR(e.ambient(20, 50), o.ambient * 0.5 * (o.black + o.white), 1e-12);
  // Area integration: with the board moved 1/4 px, pixel u = 50 lies 3/4 on the light
  // square (the print's smoothed edge, symmetric about the edge, integrates to the sharp
  // edge's area, up to the 3 x 3 samples' quadrature: measured 0.6940 against 0.7000, the
  // edge 0.01 px off).
  const BoardExposure q =
      ShadeBoard(rays.data(), kH * 3, kW * 3, BoardFromCamera(-500.0, 25.125), plane, o);
  EXPECT_NEAR(q.ambient(20, 50), o.ambient * (0.75 * o.white + 0.25 * o.black), 0.01 * o.ambient);
}

TEST(Render, TheStripeIsAGaussianOfTheDistanceInPixels) {
  const int s = 3;
  const BoardShading o = Shading(s);
  const std::vector<double> rays = SampleRays(s);
  const BoardExposure e =
      ShadeBoard(rays.data(), kH * s, kW * s, BoardFromCamera(), Eigen::Vector4d(0, 1, 0, 0), o);
  // Pixel (u = 60, v = 60) lies on a light square (x = 15, y = 25 mm); its samples sit 0 and
  // +-1/3 px from the trace.
  const double g = std::exp(-0.5 * std::pow(1.0 / 3.0 / o.stripe_sigma, 2));
  EXPECT_NEAR(e.laser(60, 60), o.laser * o.white * (1.0 + 2.0 * g) / 3.0, 1e-9);
  EXPECT_NEAR(e.laser(59, 60), e.laser(61, 60), 1e-9);
  EXPECT_GT(e.laser(60, 60), e.laser(59, 60));
  EXPECT_LT(e.laser(20, 60), 1e-200);  // 40 px = 33 sigma away: exp(-555)
  for (int v : {0, 30, 60, 119}) EXPECT_NEAR(e.distance(v, 10), 0.5 * (v - 60), 1e-12);
}

TEST(Render, RaysThatMissTheBoardSeeNothing) {
  const std::vector<double> rays = SampleRays(1);
  // The board plane behind the camera: no ray meets it in front.
  const BoardExposure e = ShadeBoard(rays.data(), kH, kW, BoardFromCamera(500.0),
                                     Eigen::Vector4d(0, 1, 0, 0), Shading(1));
  EXPECT_EQ(e.ambient.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(e.laser.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_TRUE(e.distance.array().isNaN().all());
}

TEST(Render, RefusesBadInput) {
  const std::vector<double> rays = SampleRays(3);
  const Eigen::Vector4d plane(0, 1, 0, 0);
  BoardShading even = Shading(3);
  even.supersample = 2;
  EXPECT_THROW(ShadeBoard(rays.data(), kH * 3, kW * 3, BoardFromCamera(), plane, even),
               std::invalid_argument);
  EXPECT_THROW(ShadeBoard(rays.data(), kH * 3 - 1, kW * 3, BoardFromCamera(), plane, Shading(3)),
               std::invalid_argument);
  BoardShading flat = Shading(3);
  flat.stripe_sigma = 0.0;
  EXPECT_THROW(ShadeBoard(rays.data(), kH * 3, kW * 3, BoardFromCamera(), plane, flat),
               std::invalid_argument);
}

}  // namespace
}  // namespace hmlvs
