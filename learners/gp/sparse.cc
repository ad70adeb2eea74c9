// The variational sparse GP (Titsias 2009) with a linear mean. Notation: K_mm = L L^T,
// V = L^-1 K_mn (m x n), S = sn2 I + V V^T. Then (Q + sn2 I)^-1 = (I - V^T S^-1 V) / sn2 and
// |Q + sn2 I| = sn2^(n-m) |S|, so every quantity needs V only through V V^T, V y and
// V phi, which are summed over blocks of rows.
#include <Eigen/Dense>
#include <cmath>

#include "spml/gp/gp.h"

namespace spml::gp {
namespace {

constexpr double kLog2Pi = 1.8378770664093453;
constexpr Eigen::Index kBlock = 4096;

Eigen::MatrixXd lower_solve(const Eigen::MatrixXd& L, const Eigen::MatrixXd& B) {
  return L.triangularView<Eigen::Lower>().solve(B);
}

}  // namespace

SparsePosterior::SparsePosterior(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, const Eigen::MatrixXd& phi,
                                 Eigen::MatrixXd Z, const Hyper& hyper)
    : Z_(std::move(Z)), h_(hyper) {
  const Eigen::Index n = X.rows(), O = Y.cols(), m = Z_.rows(), M = phi.cols();
  if (phi.size() && phi.rows() != n * O) throw std::invalid_argument("sparse GP: regressor rows != outputs * rows");
  const double sn2 = h_.noise_var;
  cholesky_with_jitter(cross_kernel(Z_, Z_, h_), 0.0, h_.signal_var, L_);
  L_.triangularView<Eigen::StrictlyUpper>().setZero();

  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(m, m);   // V V^T (lower triangle), then + sn2 I
  std::vector<Eigen::VectorXd> Vy(static_cast<size_t>(O), Eigen::VectorXd::Zero(m));
  std::vector<Eigen::MatrixXd> Vphi(static_cast<size_t>(O), Eigen::MatrixXd::Zero(m, M));
  Eigen::MatrixXd PtP = Eigen::MatrixXd::Zero(M, M);
  Eigen::VectorXd Pty = Eigen::VectorXd::Zero(M);
  double yty = 0.0, trace_q = 0.0;
  for (Eigen::Index start = 0; start < n; start += kBlock) {
    const Eigen::Index b = std::min(kBlock, n - start);
    const Eigen::MatrixXd V = lower_solve(L_, cross_kernel(Z_, X.middleRows(start, b), h_));   // m x b
    S.selfadjointView<Eigen::Lower>().rankUpdate(V);
    trace_q += V.squaredNorm();
    for (Eigen::Index o = 0; o < O; ++o) {
      const auto y = Y.col(o).segment(start, b);
      Vy[static_cast<size_t>(o)] += V * y;
      yty += y.squaredNorm();
      if (M == 0) continue;
      const auto P = phi.middleRows(o * n + start, b);
      Vphi[static_cast<size_t>(o)] += V * P;
      PtP += P.transpose() * P;
      Pty += P.transpose() * y;
    }
  }
  cholesky_with_jitter(S, sn2, sn2, LS_);   // reads the lower triangle only
  LS_.triangularView<Eigen::StrictlyUpper>().setZero();
  auto S_solve = [&](const Eigen::MatrixXd& B) -> Eigen::MatrixXd { return LS_.transpose().triangularView<Eigen::Upper>().solve(lower_solve(LS_, B)); };

  // theta: sum_o phi_o^T C^-1 phi_o theta = sum_o phi_o^T C^-1 y_o with C^-1 as above.
  h_.theta = Eigen::VectorXd::Zero(M);
  if (M > 0) {
    Eigen::MatrixXd A = PtP;
    Eigen::VectorXd rhs = Pty;
    for (Eigen::Index o = 0; o < O; ++o) {
      const Eigen::MatrixXd& Vp = Vphi[static_cast<size_t>(o)];
      A -= Vp.transpose() * S_solve(Vp);
      rhs -= Vp.transpose() * S_solve(Vy[static_cast<size_t>(o)]);
    }
    h_.theta = A.completeOrthogonalDecomposition().solve(rhs);
  }
  w_.resize(m, O);
  double quad = 0.0;
  const double rtr = yty - 2.0 * h_.theta.dot(Pty) + h_.theta.dot(PtP * h_.theta);
  for (Eigen::Index o = 0; o < O; ++o) {
    Eigen::VectorXd Vr = Vy[static_cast<size_t>(o)];
    if (M > 0) Vr -= Vphi[static_cast<size_t>(o)] * h_.theta;
    w_.col(o) = S_solve(Vr);
    quad -= Vr.dot(w_.col(o));
  }
  quad = (rtr + quad) / sn2;
  const double logdet = 2.0 * LS_.diagonal().array().log().sum() + static_cast<double>(n - m) * std::log(sn2);
  bound_ = -0.5 * quad - 0.5 * static_cast<double>(O) * (logdet + static_cast<double>(n) * kLog2Pi) -
           0.5 * static_cast<double>(O) * (static_cast<double>(n) * h_.signal_var - trace_q) / sn2;
}

void SparsePosterior::predict(const Eigen::MatrixXd& Xs, const Eigen::MatrixXd& phi_star, Eigen::MatrixXd* mean,
                              Eigen::MatrixXd* var) const {
  const Eigen::Index q = Xs.rows(), O = w_.cols();
  mean->resize(q, O);
  if (var) var->resize(q, O);
  for (Eigen::Index start = 0; start < q; start += kBlock) {
    const Eigen::Index b = std::min(kBlock, q - start);
    const Eigen::MatrixXd V = lower_solve(L_, cross_kernel(Z_, Xs.middleRows(start, b), h_));   // m x b
    mean->middleRows(start, b) = V.transpose() * w_;
    if (var) {
      const Eigen::MatrixXd W = lower_solve(LS_, V);
      const Eigen::ArrayXd v = (h_.signal_var - V.colwise().squaredNorm().array() +
                                h_.noise_var * W.colwise().squaredNorm().array()).max(0.0).transpose();
      for (Eigen::Index o = 0; o < O; ++o) var->col(o).segment(start, b) = (v + h_.noise_var).matrix();
    }
  }
  if (h_.theta.size() > 0) {
    const Eigen::VectorXd m = phi_star * h_.theta;
    for (Eigen::Index o = 0; o < O; ++o) mean->col(o) += m.segment(o * q, q);
  }
}

}  // namespace spml::gp
