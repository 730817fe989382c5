#include "hmlvs/sim/render.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace hmlvs {

namespace {

constexpr int kBlockRows = 40;  // pixel rows per block (the NumPy shading's chunk)

/// -1 -> 1 across an edge at signed distance 0: a cubic (C1) ramp over t in [-1, 1] (the
/// distance in units of the ramp's half-width).
double SoftSign(double t) {
  t = std::clamp(t, -1.0, 1.0);
  return t * (1.5 - 0.5 * t * t);
}

/// exp(-a^2 / 2), exactly 0 where it underflows (|a| > 38.6), without calling exp there.
double Gauss(double a) {
  const double e = 0.5 * (a * a);
  return e < 746.0 ? std::exp(-e) : 0.0;
}

/// numpy.nan_to_num: NaN -> `nan` (0 by default), +-inf -> the largest finite double of that
/// sign.
double NanToNum(double v, double nan = 0.0) {
  if (std::isnan(v)) return nan;
  if (std::isinf(v)) {
    return v > 0 ? std::numeric_limits<double>::max() : std::numeric_limits<double>::lowest();
  }
  return v;
}

/// numpy.gradient of a rows x cols block with sample spacing h: central differences inside,
/// one-sided at the block's edges; d/drow into gr, d/dcol into gc.
void Gradient(const std::vector<double>& f, int rows, int cols, double h, std::vector<double>& gr,
              std::vector<double>& gc) {
  gr.resize(f.size());
  gc.resize(f.size());
  for (int r = 0; r < rows; ++r) {
    const double* row = f.data() + static_cast<std::size_t>(r) * cols;
    double* out = gc.data() + static_cast<std::size_t>(r) * cols;
    for (int c = 1; c + 1 < cols; ++c) out[c] = (row[c + 1] - row[c - 1]) / (2.0 * h);
    out[0] = (row[1] - row[0]) / h;
    out[cols - 1] = (row[cols - 1] - row[cols - 2]) / h;
  }
  for (int r = 0; r < rows; ++r) {
    const int a = r == 0 ? 0 : r - 1;
    const int b = r + 1 == rows ? r : r + 1;
    double* out = gr.data() + static_cast<std::size_t>(r) * cols;
    if (a == b) {  // a block of one sample row: no change along the rows
      std::fill(out, out + cols, 0.0);
      continue;
    }
    const double step = (b - a) * h;
    const double* fa = f.data() + static_cast<std::size_t>(a) * cols;
    const double* fb = f.data() + static_cast<std::size_t>(b) * cols;
    for (int c = 0; c < cols; ++c) out[c] = (fb[c] - fa[c]) / step;
  }
}

/// The print's albedo at board point (x, y), its edges smoothed over +-1.5 samples;
/// kx, ky are 1 / (|grad x| width) and 1 / (|grad y| width), |grad| in mm per px and width
/// the ramp's half-width in px, so that a distance in mm times k is the ramp's argument.
double Albedo(double x, double y, double kx, double ky, const BoardShading& o) {
  const double sq = o.square;
  const auto soft_square = [&](double c, double k_mm) {  // (-1)^floor(c / sq), smoothed
    const double k = std::floor(c / sq);
    const double f = c / sq - k;
    const double ramp = SoftSign(sq * std::min(f, 1.0 - f) * k_mm);
    return 0.5 * k == std::floor(0.5 * k) ? ramp : -ramp;  // k even (exact for any k)
  };
  const auto inside = [&](double c, double k_mm, double lo, double hi) {
    return 0.25 * (1.0 + SoftSign((c - lo) * k_mm)) * (1.0 + SoftSign((hi - c) * k_mm));
  };
  const double dark = 0.5 + 0.5 * soft_square(x, kx) * soft_square(y, ky);
  const double pattern = inside(x, kx, -sq, o.rows * sq) * inside(y, ky, -sq, o.cols * sq);
  const double m = o.margin * sq;
  const double on_board =
      inside(x, kx, -sq - m, o.rows * sq + m) * inside(y, ky, -sq - m, o.cols * sq + m);
  const double white_part = o.table + (o.white - o.table) * on_board;
  return white_part + (o.black - o.white) * dark * pattern;
}

void Check(const double* rays, int sample_rows, int sample_cols, const BoardShading& o) {
  const auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  if (o.supersample < 1 || o.supersample % 2 == 0) {
    fail("supersample must be an odd integer >= 1, got " + std::to_string(o.supersample));
  }
  if (rays == nullptr || sample_rows <= 0 || sample_cols <= 0 || sample_rows % o.supersample != 0 ||
      sample_cols % o.supersample != 0) {
    fail("the rays must be (height * supersample) x (width * supersample) x 3, got " +
         std::to_string(sample_rows) + " x " + std::to_string(sample_cols) + " with supersample " +
         std::to_string(o.supersample));
  }
  if (sample_rows < 2 || sample_cols < 2) fail("the rays must be at least 2 x 2 samples");
  if (!(o.square > 0) || o.rows < 1 || o.cols < 1 || !(o.margin >= 0)) {
    fail("the board needs square > 0, rows and cols >= 1 and margin >= 0");
  }
  if (!(o.stripe_sigma > 0)) fail("stripe_sigma must be > 0");
}

// A block of pixel rows from r0 (pixel_rows of them, w wide) from its samples (s x s a
// pixel): the mean ambient and laser light, and the laser-plane distance at the centre sample.
void AverageSamples(const std::vector<double>& ambient, const std::vector<double>& laser,
                    const std::vector<double>& d, int r0, int pixel_rows, int w, int s,
                    int sample_cols, BoardExposure* out) {
  const double samples = static_cast<double>(s) * s;
  for (int pr = 0; pr < pixel_rows; ++pr) {
    for (int pc = 0; pc < w; ++pc) {
      double sa = 0.0;
      double sl = 0.0;
      for (int i = 0; i < s; ++i) {
        const std::size_t row = static_cast<std::size_t>(pr * s + i) * sample_cols;
        for (int j = 0; j < s; ++j) {
          sa += ambient[row + pc * s + j];
          sl += laser[row + pc * s + j];
        }
      }
      out->ambient(r0 + pr, pc) = sa / samples;
      out->laser(r0 + pr, pc) = sl / samples;
      out->distance(r0 + pr, pc) =
          d[static_cast<std::size_t>(pr * s + s / 2) * sample_cols + pc * s + s / 2];
    }
  }
}

}  // namespace

BoardExposure ShadeBoard(const double* rays, int sample_rows, int sample_cols,
                         const Eigen::Matrix4d& board_from_camera, const Eigen::Vector4d& plane,
                         const BoardShading& o) {
  Check(rays, sample_rows, sample_cols, o);
  const int s = o.supersample;
  const int h = sample_rows / s;
  const int w = sample_cols / s;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Eigen::Matrix3d rot = board_from_camera.topLeftCorner<3, 3>();
  const Eigen::Vector3d shift = board_from_camera.topRightCorner<3, 1>();
  BoardExposure out;
  out.ambient.resize(h, w);
  out.laser.resize(h, w);
  out.distance.resize(h, w);

  std::vector<double> x, y, d, gxr, gxc, gyr, gyc, gdr, gdc;
  std::vector<double> ambient, laser;
  std::vector<unsigned char> hit;
  const double spacing = 1.0 / s;
  const double width = 1.5 / s;  // the print's edges ramp over +-1.5 samples (px)
  const double inv_sigma = 1.0 / o.stripe_sigma;
  for (int r0 = 0; r0 < h; r0 += kBlockRows) {
    const int r1 = std::min(h, r0 + kBlockRows);
    const int rows = (r1 - r0) * s;
    const std::size_t n = static_cast<std::size_t>(rows) * sample_cols;
    const double* ray = rays + static_cast<std::size_t>(r0) * s * sample_cols * 3;
    x.resize(n);
    y.resize(n);
    d.resize(n);
    hit.assign(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d cam(ray[3 * i], ray[3 * i + 1], ray[3 * i + 2]);
      const Eigen::Vector3d rb = rot * cam;
      double t = -shift.z() / rb.z();
      hit[i] = std::isfinite(t) && t > 0;
      if (!hit[i]) t = nan;
      x[i] = shift.x() + t * rb.x();
      y[i] = shift.y() + t * rb.y();
      d[i] = plane.head<3>().dot(cam * t) + plane[3];
    }
    Gradient(x, rows, sample_cols, spacing, gxr, gxc);
    Gradient(y, rows, sample_cols, spacing, gyr, gyc);
    Gradient(d, rows, sample_cols, spacing, gdr, gdc);
    ambient.assign(n, 0.0);
    laser.assign(n, 0.0);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < sample_cols; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * sample_cols + c;
        double albedo = 0.0;
        if (hit[i]) {
          const double gx = NanToNum(std::sqrt(gxc[i] * gxc[i] + gxr[i] * gxr[i]), 1.0);
          const double gy = NanToNum(std::sqrt(gyc[i] * gyc[i] + gyr[i] * gyr[i]), 1.0);
          albedo =
              Albedo(NanToNum(x[i]), NanToNum(y[i]), 1.0 / (gx * width), 1.0 / (gy * width), o);
        }
        const double dpx = d[i] / std::sqrt(gdc[i] * gdc[i] + gdr[i] * gdr[i]);
        double profile = Gauss(dpx * inv_sigma);
        if (o.spurious > 0) {
          const double u = (c + 0.5) / s - 0.5;
          if (u >= o.spurious_lo * w && u <= o.spurious_hi * w) {
            profile += o.spurious * Gauss((dpx - o.spurious_offset) * inv_sigma);
          }
        }
        laser[i] = NanToNum(o.laser * albedo * profile);
        ambient[i] = o.ambient * albedo;
      }
    }
    AverageSamples(ambient, laser, d, r0, r1 - r0, w, s, sample_cols, &out);
  }
  return out;
}

}  // namespace hmlvs
