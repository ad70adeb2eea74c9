// One body's ten inertial parameters in MJCF terms: what an <inertial pos mass fullinertia> or
// <inertial pos mass diaginertia quat> element says, and the first-order (delta-method) map of a
// covariance of the parameters onto those quantities.
#pragma once

#include <array>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "spml/envs/log_cholesky.h"

namespace spml {

struct BodyInertial {
  double mass = 0;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();          // centre of mass in the body frame
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();      // about the centre of mass, body axes
  Eigen::Vector3d principal = Eigen::Vector3d::Zero();    // principal moments, ascending
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();   // principal axes -> body frame
  // MJCF fullinertia order: Ixx Iyy Izz Ixy Ixz Iyz (about the centre of mass).
  std::array<double, 6> fullinertia() const;
};

// pi in MjcfRegressor's order (m, m c, inertia about the body origin); requires m > 0.
BodyInertial body_inertial(const Vector10d& pi);

// (mass, com xyz, fullinertia xx yy zz xy xz yz): the ten quantities an MJCF <inertial> states.
Vector10d mjcf_quantities(const BodyInertial& b);

// Standard errors of those ten quantities from the covariance of pi.
Vector10d body_inertial_std_errors(const Vector10d& pi, const Matrix10d& covariance);

// d (mass, com, fullinertia) / d pi at pi.
Matrix10d body_inertial_jacobian(const Vector10d& pi);

}  // namespace spml
