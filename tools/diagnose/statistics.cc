// Part of stage 3 (estimate): effective sample size and HAC covariances (statistics.h).
#include "statistics.h"

#include <algorithm>
#include <cmath>

namespace spml::diagnose_detail {

Eigen::Index hac_block_length(const Eigen::Ref<const Eigen::VectorXd>& r) {
  const Eigen::Index N = r.size();
  if (N < 8) return 1;
  const double r0 = r.squaredNorm();
  if (!(r0 > 0)) return 1;
  double rho = r.tail(N - 1).dot(r.head(N - 1)) / r0;
  rho = std::clamp(rho, 0.0, 0.99);
  // Andrews (1991), Bartlett kernel: L = 1.1447 (alpha N)^(1/3), alpha = 4 rho^2 / (1 - rho^2)^2.
  const double alpha = 4 * rho * rho / ((1 - rho * rho) * (1 - rho * rho));
  const double L = 1.1447 * std::cbrt(alpha * static_cast<double>(N));
  return std::clamp<Eigen::Index>(static_cast<Eigen::Index>(std::ceil(L)), 1, std::max<Eigen::Index>(1, N / 4));
}

double effective_fraction(const Eigen::VectorXd& r, Eigen::Index N) {
  if (N <= 0 || r.size() == 0) return 1;
  double ss = 0, lrv = 0;
  for (Eigen::Index o = 0; o * N < r.size(); ++o) {
    const auto seg = r.segment(o * N, N);
    const Eigen::Index B = hac_block_length(seg);
    ss += seg.squaredNorm();
    for (Eigen::Index b = 0; b + B <= N; b += B) {
      const double s = seg.segment(b, B).sum();
      lrv += s * s * static_cast<double>(N) / static_cast<double>(N - N % B);
    }
  }
  if (!(lrv > 0)) return 1;
  return std::clamp(ss / lrv, 1.0 / static_cast<double>(r.size()), 1.0);
}

Eigen::MatrixXd long_run_covariance(const Eigen::MatrixXd& Z, const Eigen::VectorXd& r, Eigen::Index N) {
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(Z.cols(), Z.cols());
  for (Eigen::Index o = 0; o * N < Z.rows(); ++o) {
    const Eigen::Index B = hac_block_length(r.segment(o * N, N));
    const double scale = static_cast<double>(N) / static_cast<double>(N - N % B);
    for (Eigen::Index b = 0; b + B <= N; b += B) {
      const Eigen::VectorXd s = Z.middleRows(o * N + b, B).colwise().sum().transpose();
      S.noalias() += scale * s * s.transpose();
    }
  }
  return S;
}

double quantile(std::vector<double> v, double share) {
  if (v.empty()) return 0;
  const auto at = std::min(v.size() - 1, static_cast<size_t>(share * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(at), v.end());
  return v[at];
}

double familywise_z(double alpha, int k) {
  const double each = -std::expm1(std::log1p(-alpha) / std::max(k, 1));   // 1 - (1 - alpha)^(1/k), without cancellation
  // P(|Z| > z) = erfc(z / sqrt 2) falls monotonically: bisect it.
  double lo = 0, hi = 40;
  for (int it = 0; it < 100; ++it) {
    const double mid = 0.5 * (lo + hi);
    (std::erfc(mid / std::sqrt(2.0)) > each ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace spml::diagnose_detail
