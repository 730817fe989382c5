// What both sensor models (paper.h, opencv.h) share: the row-major array types their batch
// functions take and return, and the input checks on them.
//
// Arrays come in as row-major Eigen::Ref views so that numpy buffers can be passed without a
// copy. Poses are base_from_hand 4x4 transforms flattened to 16 row-major numbers per row.
#pragma once

#include <Eigen/Core>
#include <cstdint>

namespace hmlvs {

/// Measurement (hmlvs.measure) refuses pixels whose ray meets the laser plane at less than 0.5
/// degrees (the sine below): such points lie hundreds of baselines away, where a tenth of a
/// pixel moves them by metres. The batch functions apply it when asked (`min_ray_sine`); the
/// objective and the solvers do not.
constexpr double kMinRaySine = 0.0087265354983739347;  // sin(0.5 deg)

using RowMatX2 = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
using RowMatX3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowMatX16 = Eigen::Matrix<double, Eigen::Dynamic, 16, Eigen::RowMajor>;
using PixelsRef = Eigen::Ref<const RowMatX2>;
using Points3Ref = Eigen::Ref<const RowMatX3>;
using PosesRef = Eigen::Ref<const RowMatX16>;
using Mask = Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 1>;

/// Points computed from pixels, with a per-point validity mask. Invalid rows hold NaN.
struct PointsResult {
  RowMatX3 points;
  Mask valid;
  Eigen::Index num_invalid = 0;
};

/// Pixels computed from points, with a per-point validity mask. Invalid rows hold NaN.
struct PixelsResult {
  RowMatX2 pixels;
  Mask valid;
  Eigen::Index num_invalid = 0;
};

/// Throws std::invalid_argument "<name_a> has a rows but <name_b> has b" unless a == b.
void RequireSameRows(Eigen::Index a, const char* name_a, Eigen::Index b, const char* name_b);

/// Throws std::invalid_argument naming the first row of a (rows x cols) row-major array that
/// holds a NaN or an infinity.
void RequireFinite(const double* data, Eigen::Index rows, int cols, const char* name);

}  // namespace hmlvs
