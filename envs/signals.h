// Small signal-processing steps shared by the scenario generators (internal header).
#pragma once

#include <Eigen/Core>
#include <cmath>

namespace spml::signals {

// Velocity and acceleration by a central difference applied twice (NumPy's `gradient`
// recipe): qd_k = (q_{k+1} - q_{k-1}) / 2h, qdd_k = (qd_{k+1} - qd_{k-1}) / 2h. Unbiased for
// smooth signals; white position noise of std s becomes s*sqrt(6)/(4h^2) on qdd. The first
// and last `kEdge` rows lack a full stencil and are left at zero (callers drop them).
constexpr int kEdge = 2;
inline void central_differences(const Eigen::MatrixXd& q, double h, Eigen::MatrixXd& qd, Eigen::MatrixXd& qdd) {
  const Eigen::Index n = q.rows();
  qd = Eigen::MatrixXd::Zero(n, q.cols());
  qdd = Eigen::MatrixXd::Zero(n, q.cols());
  for (Eigen::Index k = 1; k + 1 < n; ++k) qd.row(k) = (q.row(k + 1) - q.row(k - 1)) / (2 * h);
  for (Eigen::Index k = 2; k + 2 < n; ++k) qdd.row(k) = (qd.row(k + 1) - qd.row(k - 1)) / (2 * h);
}

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
