// The simulator's shading of a checkerboard under ambient light and a laser plane: what one
// camera exposure of the board records, per pixel, before speckle, blur and noise.
//
// The camera model enters only through the rays of the supersample positions, and the laser
// only through its plane, so every sensor model renders with the same shading.
#pragma once

#include <Eigen/Core>

namespace hmlvs {

/// The board's print, the light and the stripe's profile. Lengths in mm, levels in grey
/// levels of an 8-bit frame.
struct BoardShading {
  int supersample = 3;  // samples per pixel along each axis, odd
  /// The board: rows x cols inner corners spaced `square` mm, corner (r, c) at board point
  /// (r square, c square, 0), so that the squares span x in [-square, rows square] and y in
  /// [-square, cols square], in a white border of `margin` squares.
  int rows = 6;
  int cols = 8;
  double square = 30.0;
  double margin = 1.0;
  double white = 0.85;  // albedos of the white squares and border, the dark squares and
  double black = 0.25;  // the table around the board
  double table = 0.45;
  double ambient = 130.0;     // exposure of albedo 1 under ambient light
  double laser = 140.0;       // exposure of albedo 1 at the stripe's centre
  double stripe_sigma = 1.2;  // the stripe's Gaussian profile across it (px)
  /// A second, weaker stripe (relative intensity; 0: none) `spurious_offset` px beside the
  /// first, on the sample columns whose position u lies in [spurious_lo, spurious_hi] x the
  /// image width.
  double spurious = 0.0;
  double spurious_offset = 20.0;
  double spurious_lo = 0.6;
  double spurious_hi = 0.8;
};

/// Ambient and laser exposure of each pixel, and the signed distance (mm) from the laser
/// plane of the board point at each pixel centre (NaN where the ray misses the board plane).
struct BoardExposure {
  using Image = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  Image ambient;
  Image laser;
  Image distance;
};

/// Renders the board seen along `rays`: (height * s) x (width * s) camera-frame rays, row
/// after row, x y z each (s = shading.supersample; the centre sample of each pixel at its
/// integer position). `board_from_camera` places the camera in the board's frame (the board
/// in its z = 0 plane, squares from (0, 0)); the laser plane is the camera-frame points p
/// with plane.head<3>() . p + plane[3] = 0, its value there the signed distance.
///
/// Each sample takes the print with its edges smoothed over +-1.5 samples (the distance to
/// an edge measured in pixels through the local gradient of the board coordinates), so that
/// the s x s samples integrate the pixel's area; the laser adds a Gaussian of the sample's
/// distance in pixels from the plane's trace on the board. Pixels are the means of their
/// samples. The work goes in blocks of 40 pixel rows, the gradients one-sided at a block's
/// first and last sample row, as hmlvs.sim.render's NumPy shading did (the same images).
/// Throws std::invalid_argument for a bad shape or option.
BoardExposure ShadeBoard(const double* rays, int sample_rows, int sample_cols,
                         const Eigen::Matrix4d& board_from_camera, const Eigen::Vector4d& plane,
                         const BoardShading& shading);

}  // namespace hmlvs
