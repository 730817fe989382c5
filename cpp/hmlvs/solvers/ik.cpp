#include "hmlvs/solvers/ik.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

namespace hmlvs::solvers {

namespace {

using geometry::BaseFromHand;
using geometry::DHRobot;

using Vec = std::vector<double>;

// Sum of squares, accumulated in order from 0.
double SumSq(const Vec& r) {
  double acc = 0.0;
  for (double v : r) acc += v * v;
  return acc;
}

// min(max(v, lo), hi), NaN passing through.
double Clip(double v, double lo, double hi) {
  if (std::isnan(v)) return v;
  return std::min(std::max(v, lo), hi);
}

class LookAtResidual {
 public:
  LookAtResidual(const DHRobot& robot, const LookAtTarget& target)
      : robot_(robot), target_(target) {}

  std::size_t size() const { return target_.has_x ? 9 : 6; }

  // Residuals at joint readings `q`. The camera pose is base_from_hand * hand_from_camera,
  // each entry summed over the inner index in order 0..3.
  Vec operator()(const Vec& q) const {
    for (double v : q)
      if (!std::isfinite(v)) throw std::invalid_argument("a joint reading is not finite");
    Eigen::Map<const Eigen::VectorXd> joints(q.data(), static_cast<Eigen::Index>(q.size()));
    const Eigen::Matrix4d t = BaseFromHand(robot_, joints);
    const Eigen::Matrix4d& h = target_.hand_from_camera;
    auto cam = [&](int r, int c) {
      double acc = t(r, 0) * h(0, c);
      for (int i = 1; i < 4; ++i) acc = acc + t(r, i) * h(i, c);
      return acc;
    };
    Vec out(size());
    for (int r = 0; r < 3; ++r) {
      out[r] = cam(r, 3) - target_.position[r];
      out[3 + r] = 300.0 * (cam(r, 2) - target_.axis[r]);
      if (target_.has_x) out[6 + r] = 100.0 * (cam(r, 0) - target_.x[r]);
    }
    return out;
  }

 private:
  const DHRobot& robot_;
  const LookAtTarget& target_;
};

// Gaussian elimination with partial pivoting (the first largest |pivot|, or the first NaN),
// then back substitution; the matrix is small and symmetric positive definite.
Vec Solve(std::vector<Vec> m, const Vec& g) {
  const std::size_t n = g.size();
  for (std::size_t i = 0; i < n; ++i) m[i].push_back(g[i]);
  for (std::size_t k = 0; k < n; ++k) {
    std::size_t p = k;
    double best = std::fabs(m[k][k]);
    if (!std::isnan(best)) {
      for (std::size_t i = k + 1; i < n; ++i) {
        const double v = std::fabs(m[i][k]);
        if (std::isnan(v)) {
          p = i;
          break;
        }
        if (v > best) p = i, best = v;
      }
    }
    if (p != k) std::swap(m[k], m[p]);
    for (std::size_t i = k + 1; i < n; ++i) {
      const double f = m[i][k] / m[k][k];
      for (std::size_t j = 0; j <= n; ++j) m[i][j] = m[i][j] - f * m[k][j];
    }
  }
  Vec x(n, 0.0);
  for (std::size_t k = n; k-- > 0;) {
    double acc = m[k][n];
    for (std::size_t j = k + 1; j < n; ++j) acc = acc - m[k][j] * x[j];
    x[k] = acc / m[k][k];
  }
  return x;
}

}  // namespace

LookAtResult SolveLookAt(const geometry::DHRobot& robot, const LookAtTarget& target,
                         const Eigen::VectorXd& start, const Eigen::VectorXd& lower,
                         const Eigen::VectorXd& upper, const LookAtOptions& options) {
  const std::size_t n = robot.joints.size();
  if (static_cast<std::size_t>(start.size()) != n || static_cast<std::size_t>(lower.size()) != n ||
      static_cast<std::size_t>(upper.size()) != n) {
    std::ostringstream msg;
    msg << "the start and the joint bounds must have one value per joint (" << n << "), got "
        << start.size() << ", " << lower.size() << " and " << upper.size();
    throw std::invalid_argument(msg.str());
  }
  const LookAtResidual res(robot, target);
  const std::size_t k_res = res.size();
  Vec x(n);
  for (std::size_t i = 0; i < n; ++i) x[i] = Clip(start[i], lower[i], upper[i]);
  Vec r = res(x);
  double cost = SumSq(r);
  double lam = 1e-3;
  bool done = false;
  auto finish = [&]() {
    LookAtResult out;
    out.joints = Eigen::Map<const Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(n));
    out.error = std::sqrt(cost);
    return out;
  };
  for (int it = 0; it < options.iterations; ++it) {
    // Central differences: joint i moved by +-1e-6 (the others by +-0.0, as x + h does).
    std::vector<Vec> jac(n);
    for (std::size_t i = 0; i < n; ++i) {
      Vec xp(n), xm(n);
      for (std::size_t j = 0; j < n; ++j) {
        const double h = i == j ? 1e-6 : 0.0;
        xp[j] = x[j] + h;
        xm[j] = x[j] - h;
      }
      const Vec rp = res(xp), rm = res(xm);
      jac[i].resize(k_res);
      for (std::size_t c = 0; c < k_res; ++c) jac[i][c] = (rp[c] - rm[c]) / 2e-6;
    }
    // Normal equations J^T J and J^T r, summed over the residuals in order.
    std::vector<Vec> a(n, Vec(n, 0.0));
    Vec g(n, 0.0);
    for (std::size_t c = 0; c < k_res; ++c) {
      for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t j = 0; j < n; ++j) a[i][j] = a[i][j] + jac[i][c] * jac[j][c];
        g[i] = g[i] + jac[i][c] * r[c];
      }
    }
    Vec d(n);
    for (std::size_t i = 0; i < n; ++i) d[i] = a[i][i] + 1e-9;
    while (true) {
      std::vector<Vec> damped = a;
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < n; ++j) damped[i][j] = a[i][j] + (i == j ? lam * d[i] : 0.0);
      Vec step = Solve(std::move(damped), g);
      for (double& s : step) s = -s;
      const double norm = std::sqrt(SumSq(step));
      if (norm > options.max_step) {
        const double scale = options.max_step / norm;
        for (double& s : step) s = s * scale;
      }
      Vec xn(n);
      for (std::size_t i = 0; i < n; ++i) xn[i] = Clip(x[i] + step[i], lower[i], upper[i]);
      Vec rn = res(xn);
      const double cn = SumSq(rn);
      if (cn < cost) {
        done = cost - cn < 1e-14 * cost || norm < 1e-13;
        x = std::move(xn);
        r = std::move(rn);
        cost = cn;
        lam = std::max(lam / 4.0, 1e-12);
        break;
      }
      lam *= 8.0;
      if (lam > 1e10) return finish();  // no step lowers the cost: converged to rounding
    }
    if (done) break;
  }
  return finish();
}

}  // namespace hmlvs::solvers
