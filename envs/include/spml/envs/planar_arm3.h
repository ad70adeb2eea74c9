// The SimDyn arm's parametric model in the paper's naming: tau = Phi(q, qd, qdd) * theta
// with the 17 regrouped coefficients of Riedel & Stulp (Table simdyn_model_coeffs), in the
// paper's (alphabetical) order.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

namespace spml::planar_arm3 {

constexpr int kParams = 17;
const std::vector<std::string>& param_names();   // FS1 FS2 FS3 FV1 ... ZZR2

struct Geometry {
  double L1 = 1.0, L2 = 1.0;   // joint-to-joint distances
  double g = 9.81;             // gravity along -y of the arm's plane
};

// Phi: 3 x 17. Closed form, evaluated by a planar Newton-Euler recursion carried out on
// coefficient rows (every quantity kept as a linear form in theta), so no MuJoCo call.
Eigen::Matrix<double, 3, kParams> regressor(const Eigen::Vector3d& q, const Eigen::Vector3d& qd,
                                            const Eigen::Vector3d& qdd, const Geometry& geo = {});

// Regrouped coefficients and geometry of an MJCF arm with the structure of
// mjcf/planar_arm3.xml (three bodies, three hinges about -y, links along x).
Eigen::Matrix<double, kParams, 1> coefficients(const mjModel* m);
Geometry geometry(const mjModel* m);

}  // namespace spml::planar_arm3
