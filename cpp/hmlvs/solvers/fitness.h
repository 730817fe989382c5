// What the global searches (search.h) minimise: an objective over N parameters. The sensor
// models' calibration objectives implement it (paper::FitnessData, 14 parameters;
// opencv::PointFitness, 18), so that PSO and random search serve both.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace hmlvs::solvers {

template <int N>
class Fitness {
 public:
  static constexpr int kDim = N;
  using Vector = Eigen::Matrix<double, N, 1>;

  virtual ~Fitness() = default;

  /// The objective at x (N numbers); +inf where it has no value (e.g. a ray that misses the
  /// laser plane). Called by several threads at once: it must not change any state.
  virtual double Evaluate(const double* x) const = 0;

  /// How many data points it sums over (a search refuses none).
  virtual Eigen::Index size() const = 0;

  /// The name of parameter d (0 <= d < N), for messages.
  virtual const std::string& ParameterName(int d) const = 0;
};

/// Throws std::invalid_argument "<what> of <name> ..." for the first parameter whose bounds
/// [lower, upper] are not finite or reversed.
template <int N>
void CheckBounds(const Fitness<N>& fitness, const typename Fitness<N>::Vector& lower,
                 const typename Fitness<N>::Vector& upper, const char* what) {
  for (int d = 0; d < N; ++d) {
    if (!std::isfinite(lower[d]) || !std::isfinite(upper[d])) {
      throw std::invalid_argument(std::string(what) + " of " + fitness.ParameterName(d) +
                                  " are not finite");
    }
    if (lower[d] > upper[d]) {
      std::ostringstream msg;
      msg << what << " of " << fitness.ParameterName(d) << ": lower " << lower[d] << " > upper "
          << upper[d];
      throw std::invalid_argument(msg.str());
    }
  }
}

}  // namespace hmlvs::solvers
