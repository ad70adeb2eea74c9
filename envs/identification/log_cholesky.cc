#include "spml/envs/log_cholesky.h"

#include <Eigen/Cholesky>
#include <cmath>
#include <stdexcept>

namespace spml {

Matrix4d pseudo_inertia(const Vector10d& p) {
  Eigen::Matrix3d I;
  I << p[4], p[7], p[8], p[7], p[5], p[9], p[8], p[9], p[6];
  Matrix4d J;
  J.topLeftCorner<3, 3>() = 0.5 * I.trace() * Eigen::Matrix3d::Identity() - I;
  J.topRightCorner<3, 1>() = p.segment<3>(1);
  J.bottomLeftCorner<1, 3>() = p.segment<3>(1).transpose();
  J(3, 3) = p[0];
  return J;
}

Vector10d body_params(const Matrix4d& J) {
  const Eigen::Matrix3d S = J.topLeftCorner<3, 3>();
  const Eigen::Matrix3d I = S.trace() * Eigen::Matrix3d::Identity() - S;   // tr(Sigma) = tr(I) / 2
  Vector10d p;
  p << J(3, 3), J(0, 3), J(1, 3), J(2, 3), I(0, 0), I(1, 1), I(2, 2), I(0, 1), I(0, 2), I(1, 2);
  return p;
}

bool realizable(const Vector10d& pi) {
  if (!pi.allFinite()) return false;
  const Eigen::LLT<Matrix4d> llt(pseudo_inertia(pi));
  return llt.info() == Eigen::Success && llt.matrixL().toDenseMatrix().diagonal().minCoeff() > 0;
}

Matrix4d log_cholesky_factor(const Vector10d& psi) {
  Matrix4d U;
  U << std::exp(psi[1]), psi[4], psi[6], psi[7],
       0, std::exp(psi[2]), psi[5], psi[8],
       0, 0, std::exp(psi[3]), psi[9],
       0, 0, 0, 1;
  return std::exp(psi[0]) * U;
}

void log_cholesky_factor_derivatives(const Vector10d& psi, Matrix4d dU[10]) {
  const double ea = std::exp(psi[0]);
  dU[0] = log_cholesky_factor(psi);   // U is e^alpha times a factor free of alpha
  // Entry (row, col) each remaining parameter sits in.
  static const int at[10][2] = {{0, 0}, {0, 0}, {1, 1}, {2, 2}, {0, 1}, {1, 2}, {0, 2}, {0, 3}, {1, 3}, {2, 3}};
  for (int k = 1; k < 10; ++k) {
    dU[k].setZero();
    dU[k](at[k][0], at[k][1]) = k <= 3 ? ea * std::exp(psi[k]) : ea;
  }
}

Vector10d params_from_log_cholesky(const Vector10d& psi, Matrix10d* jacobian) {
  const Matrix4d U = log_cholesky_factor(psi);
  if (jacobian) {
    Matrix4d dU[10];
    log_cholesky_factor_derivatives(psi, dU);
    for (int k = 0; k < 10; ++k) {
      const Matrix4d dUUt = dU[k] * U.transpose();
      jacobian->col(k) = body_params(dUUt + dUUt.transpose());   // pi is linear in J
    }
  }
  return body_params(U * U.transpose());
}

Vector10d log_cholesky_from_params(const Vector10d& pi) {
  if (!realizable(pi)) throw std::domain_error("the body parameters are not physically realizable (pseudo-inertia not positive definite)");
  // J = U U^T with U upper triangular: the ordinary Cholesky factor of J with rows and columns
  // reversed (P J P = L L^T, U = P L P).
  const Matrix4d P = Matrix4d::Identity().rowwise().reverse();
  const Matrix4d L = Eigen::LLT<Matrix4d>(P * pseudo_inertia(pi) * P).matrixL();
  const Matrix4d U = P * L * P;
  const double ea = U(3, 3);
  Vector10d psi;
  psi << std::log(ea), std::log(U(0, 0) / ea), std::log(U(1, 1) / ea), std::log(U(2, 2) / ea), U(0, 1) / ea, U(1, 2) / ea,
      U(0, 2) / ea, U(0, 3) / ea, U(1, 3) / ea, U(2, 3) / ea;
  return psi;
}

}  // namespace spml
