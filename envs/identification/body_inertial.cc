#include "spml/envs/body_inertial.h"

#include <Eigen/Eigenvalues>
#include <stdexcept>

namespace spml {
namespace {

// fullinertia's entry k as a (row, col) of the 3x3 inertia.
constexpr int kRow[6] = {0, 1, 2, 0, 0, 1}, kCol[6] = {0, 1, 2, 1, 2, 2};

}  // namespace

std::array<double, 6> BodyInertial::fullinertia() const {
  std::array<double, 6> f{};
  for (int k = 0; k < 6; ++k) f[static_cast<size_t>(k)] = inertia(kRow[k], kCol[k]);
  return f;
}

Vector10d mjcf_quantities(const BodyInertial& b) {
  const std::array<double, 6> full = b.fullinertia();
  Vector10d q;
  q << b.mass, b.com, full[0], full[1], full[2], full[3], full[4], full[5];
  return q;
}

BodyInertial body_inertial(const Vector10d& pi) {
  if (!(pi[0] > 0)) throw std::domain_error("a body with mass <= 0 has no centre of mass");
  BodyInertial b;
  b.mass = pi[0];
  b.com = pi.segment<3>(1) / pi[0];
  Eigen::Matrix3d I;
  I << pi[4], pi[7], pi[8], pi[7], pi[5], pi[9], pi[8], pi[9], pi[6];
  // Parallel-axis theorem, from the body origin to the centre of mass.
  b.inertia = I - b.mass * (b.com.squaredNorm() * Eigen::Matrix3d::Identity() - b.com * b.com.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(b.inertia);
  b.principal = eig.eigenvalues();
  Eigen::Matrix3d R = eig.eigenvectors();
  if (R.determinant() < 0) R.col(2) = -R.col(2);   // a rotation, so that it is a quaternion
  b.orientation = Eigen::Quaterniond(R).normalized();
  return b;
}

Matrix10d body_inertial_jacobian(const Vector10d& pi) {
  const double m = pi[0];
  const Eigen::Vector3d h = pi.segment<3>(1);
  Matrix10d D = Matrix10d::Zero();
  D(0, 0) = 1;
  // c = h / m
  D.block<3, 3>(1, 1) = Eigen::Matrix3d::Identity() / m;
  D.block<3, 1>(1, 0) = -h / (m * m);
  // Ic = I - (|h|^2 1 - h h^T) / m
  const Eigen::Matrix3d S = h.squaredNorm() * Eigen::Matrix3d::Identity() - h * h.transpose();
  for (int k = 0; k < 6; ++k) {
    const int r = kRow[k], c = kCol[k];
    D(4 + k, 4 + k) = 1;
    D(4 + k, 0) = S(r, c) / (m * m);
    for (int i = 0; i < 3; ++i) {
      // d S(r,c) / d h_i = 2 h_i delta_rc - delta_ri h_c - h_r delta_ci
      const double dS = 2 * h[i] * (r == c) - (r == i) * h[c] - h[r] * (c == i);
      D(4 + k, 1 + i) = -dS / m;
    }
  }
  return D;
}

Vector10d body_inertial_std_errors(const Vector10d& pi, const Matrix10d& covariance) {
  const Matrix10d D = body_inertial_jacobian(pi);
  return (D * covariance * D.transpose()).diagonal().cwiseMax(0.0).cwiseSqrt();
}

}  // namespace spml
