#include "hmlvs/model/arrays.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace hmlvs {

void RequireSameRows(Eigen::Index a, const char* name_a, Eigen::Index b, const char* name_b) {
  if (a != b) {
    std::ostringstream msg;
    msg << name_a << " has " << a << " rows but " << name_b << " has " << b;
    throw std::invalid_argument(msg.str());
  }
}

void RequireFinite(const double* data, Eigen::Index rows, int cols, const char* name) {
  for (Eigen::Index i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j) {
      if (!std::isfinite(data[i * cols + j])) {
        std::ostringstream msg;
        msg << name << " row " << i << " is not finite (NaN or inf in column " << j << ")";
        throw std::invalid_argument(msg.str());
      }
    }
  }
}

}  // namespace hmlvs
