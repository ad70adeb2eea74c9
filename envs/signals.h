// Small signal-processing steps shared by the scenario generators (internal header).
#pragma once

#include <Eigen/Core>
#include <cmath>

#include "spml/signal.h"

namespace spml::signals {

// Rows at each end of a twice-differentiated signal without a full central-difference stencil
// (spml/signal.h central_difference, applied twice): the scenario generators drop them.
constexpr int kEdge = 2;

// Mean of each block of `factor` rows: a boxcar anti-alias filter plus decimation.
inline Eigen::MatrixXd block_average(const Eigen::MatrixXd& x, int factor) {
  const Eigen::Index n = x.rows() / factor;
  Eigen::MatrixXd out(n, x.cols());
  for (Eigen::Index i = 0; i < n; ++i) out.row(i) = x.middleRows(i * factor, factor).colwise().mean();
  return out;
}

// Linear chirp from f0 to f1 [Hz] over `duration`: sin(2*pi*(f0 t + (f1-f0) t^2 / (2 T))).
struct Chirp {
  double f0, f1, duration;
  double phase(double t) const { return 2 * M_PI * (f0 * t + (f1 - f0) * t * t / (2 * duration)); }
  double freq(double t) const { return f0 + (f1 - f0) * t / duration; }
};

}  // namespace spml::signals
