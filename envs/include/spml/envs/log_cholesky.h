// The log-Cholesky parametrization of one rigid body's inertia (Rucker & Wensing, "Smooth
// parameterization of rigid-body inertia", IEEE RA-L 2022): ten unconstrained numbers psi
// map smoothly and one-to-one onto the physically realizable bodies, i.e. the bodies whose
// 4x4 pseudo-inertia
//   J = [ Sigma  h ]      Sigma = tr(I)/2 * 1 - I  (second moment of the mass distribution),
//       [ h^T    m ]      h = m c,  I = inertia about the body frame origin
// is positive definite (Wensing, Kim, Slotine, RA-L 2017). J = U U^T with U upper triangular,
//   U = e^alpha [ e^d1  s12   s13   t1 ]
//               [ 0     e^d2  s23   t2 ]
//               [ 0     0     e^d3  t3 ]
//               [ 0     0     0     1  ],   psi = (alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3).
// Body parameters pi follow MjcfRegressor's order: (m, m cx, m cy, m cz, Ixx, Iyy, Izz, Ixy, Ixz,
// Iyz), inertia about the body origin in body coordinates.
#pragma once

#include <Eigen/Core>

namespace spml {

using Vector10d = Eigen::Matrix<double, 10, 1>;
using Matrix10d = Eigen::Matrix<double, 10, 10>;
using Matrix4d = Eigen::Matrix4d;

// Pseudo-inertia of body parameters pi, and back (both linear).
Matrix4d pseudo_inertia(const Vector10d& pi);
Vector10d body_params(const Matrix4d& J);

// True when the pseudo-inertia is positive definite (strictly realizable: positive mass and
// principal moments that satisfy the strict triangle inequalities).
bool realizable(const Vector10d& pi);

// The factor U of psi; J = U U^T.
Matrix4d log_cholesky_factor(const Vector10d& psi);
// pi(psi) and its Jacobian d pi / d psi (columns in psi's order).
Vector10d params_from_log_cholesky(const Vector10d& psi, Matrix10d* jacobian = nullptr);
// The inverse map; throws std::domain_error when pi is not realizable.
Vector10d log_cholesky_from_params(const Vector10d& pi);
// d U / d psi_k for each k (the factor is linear in every entry but alpha and the d's).
void log_cholesky_factor_derivatives(const Vector10d& psi, Matrix4d dU[10]);

}  // namespace spml
