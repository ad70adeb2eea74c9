#include "consistent_objective.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <cmath>

namespace spml::identification {
namespace {

// tr(J^-1 dJ_k J^-1 dJ_l) for one body: with A_k = U^-1 dU_k, J^-1 dJ_k is similar to
// A_k + A_k^T, so the metric is the Frobenius product of those symmetric matrices.
Matrix10d prior_metric(const Vector10d& psi) {
  const Matrix4d U = log_cholesky_factor(psi);
  const Matrix4d Uinv = U.inverse();
  Matrix4d dU[10], B[10];
  log_cholesky_factor_derivatives(psi, dU);
  for (int k = 0; k < 10; ++k) {
    const Matrix4d A = Uinv * dU[k];
    B[k] = A + A.transpose();
  }
  Matrix10d M;
  for (int k = 0; k < 10; ++k)
    for (int l = 0; l <= k; ++l) M(k, l) = M(l, k) = (B[k].cwiseProduct(B[l])).sum();
  return M;
}

}  // namespace

ConsistentObjective::ConsistentObjective(Layout layout, Eigen::MatrixXd R, Eigen::VectorXd z, double sigma, Eigen::VectorXd pi0,
                                         Eigen::VectorXd term_weight, double lambda)
    : layout_(std::move(layout)), R_(std::move(R)), z_(std::move(z)), pi0_(std::move(pi0)), term_weight_(std::move(term_weight)),
      sigma_(sigma), lambda_(lambda) {
  for (int b : layout_.bodies) {
    const Vector10d p = pi0_.segment<10>(10 * b);
    const Matrix4d J0 = pseudo_inertia(p);
    J0inv_.push_back(J0.inverse());
    logdetJ0_.push_back(std::log(J0.determinant()));
    psi0_.push_back(log_cholesky_from_params(p));
  }
}

Eigen::VectorXd ConsistentObjective::start() const {
  Eigen::VectorXd theta(layout_.size());
  for (size_t i = 0; i < layout_.bodies.size(); ++i) theta.segment<10>(10 * static_cast<Eigen::Index>(i)) = psi0_[i];
  const auto nb = static_cast<Eigen::Index>(10 * layout_.bodies.size());
  for (size_t t = 0; t < layout_.terms.size(); ++t) {
    const double v = pi0_[layout_.terms[t]];
    theta[nb + static_cast<Eigen::Index>(t)] = layout_.bounded[t] ? std::max(v, 0.0) : v;
  }
  return theta;
}

Eigen::VectorXd ConsistentObjective::standard(const Eigen::VectorXd& theta, Eigen::MatrixXd* jacobian) const {
  Eigen::VectorXd pi = pi0_;
  if (jacobian) jacobian->setZero(pi.size(), theta.size());
  for (size_t i = 0; i < layout_.bodies.size(); ++i) {
    const auto at = 10 * static_cast<Eigen::Index>(i), b = 10 * static_cast<Eigen::Index>(layout_.bodies[i]);
    Matrix10d Jb;
    pi.segment<10>(b) = params_from_log_cholesky(theta.segment<10>(at), jacobian ? &Jb : nullptr);
    if (jacobian) jacobian->block<10, 10>(b, at) = Jb;
  }
  const auto nb = static_cast<Eigen::Index>(10 * layout_.bodies.size());
  for (size_t t = 0; t < layout_.terms.size(); ++t) {
    pi[layout_.terms[t]] = theta[nb + static_cast<Eigen::Index>(t)];
    if (jacobian) (*jacobian)(layout_.terms[t], nb + static_cast<Eigen::Index>(t)) = 1;
  }
  return pi;
}

double ConsistentObjective::value(const Eigen::VectorXd& theta, Eigen::VectorXd* gradient) const {
  Eigen::VectorXd pi = standard(theta);
  const Eigen::VectorXd r = R_ * pi - z_;
  const double s2 = sigma_ * sigma_;
  double f = 0.5 * r.squaredNorm() / s2;
  Eigen::VectorXd gpi;
  if (gradient) {
    gpi = R_.transpose() * r / s2;
    gradient->resize(theta.size());
  }
  for (size_t i = 0; i < layout_.bodies.size(); ++i) {
    const auto at = 10 * static_cast<Eigen::Index>(i), b = 10 * static_cast<Eigen::Index>(layout_.bodies[i]);
    const Vector10d psi = theta.segment<10>(at);
    const Matrix4d U = log_cholesky_factor(psi);
    // D = tr(J0^-1 J) - log det J + log det J0 - 4, log det J = 8 alpha + 2 (d1 + d2 + d3)
    const double logdetJ = 8 * psi[0] + 2 * (psi[1] + psi[2] + psi[3]);
    f += lambda_ * ((J0inv_[i] * U * U.transpose()).trace() - logdetJ + logdetJ0_[i] - 4);
    if (!gradient) continue;
    Matrix10d Jb;
    params_from_log_cholesky(psi, &Jb);
    Vector10d g = Jb.transpose() * gpi.segment<10>(b);
    Matrix4d dU[10];
    log_cholesky_factor_derivatives(psi, dU);
    const Matrix4d A = J0inv_[i] * U;   // d tr(J0^-1 U U^T) = 2 <J0^-1 U, dU>
    for (int k = 0; k < 10; ++k) g[k] += lambda_ * 2 * A.cwiseProduct(dU[k]).sum();
    g[0] -= lambda_ * 8;
    g.segment<3>(1).array() -= lambda_ * 2;
    gradient->segment<10>(at) = g;
  }
  const auto nb = static_cast<Eigen::Index>(10 * layout_.bodies.size());
  for (size_t t = 0; t < layout_.terms.size(); ++t) {
    const int k = layout_.terms[t];
    const double d = pi[k] - pi0_[k], w = term_weight_[static_cast<Eigen::Index>(t)];
    f += 0.5 * w * d * d;
    if (gradient) (*gradient)[nb + static_cast<Eigen::Index>(t)] = gpi[k] + w * d;
  }
  return f;
}

Eigen::MatrixXd ConsistentObjective::hessian(const Eigen::VectorXd& theta, double sigma) const {
  Eigen::MatrixXd Jt;
  standard(theta, &Jt);
  const Eigen::MatrixXd RJ = R_ * Jt;
  Eigen::MatrixXd H = RJ.transpose() * RJ / (sigma * sigma);
  for (size_t i = 0; i < layout_.bodies.size(); ++i) {
    const auto at = 10 * static_cast<Eigen::Index>(i);
    H.block<10, 10>(at, at) += lambda_ * prior_metric(theta.segment<10>(at));
  }
  const auto nb = static_cast<Eigen::Index>(10 * layout_.bodies.size());
  for (size_t t = 0; t < layout_.terms.size(); ++t) H(nb + static_cast<Eigen::Index>(t), nb + static_cast<Eigen::Index>(t)) += term_weight_[static_cast<Eigen::Index>(t)];
  return H;
}

}  // namespace spml::identification
