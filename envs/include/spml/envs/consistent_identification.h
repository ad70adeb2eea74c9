// Physically consistent identification of an MJCF model's standard parameters.
//
// Every body's ten inertial parameters go through the log-Cholesky map (Rucker & Wensing, RA-L
// 2022; spml/envs/log_cholesky.h), so every estimate is a realizable body; armature, damping,
// Coulomb friction (frictionloss) and stiffness are bounded below by 0. The fit minimises
//   ||W pi(theta) - tau||^2 / (2 sigma^2)                         the data (W: MjcfRegressor's
//                                                                 standard regressor, stacked)
//   + lambda * sum_b D(J_b || J0_b)                               bodies: log-det (Bregman)
//                                                                 divergence of pseudo-inertias
//   + lambda/2 * sum_k |W_k|^2 / (n sigma^2) * (x_k - x0_k)^2      joint terms: a Gaussian prior
//                                                                 worth lambda equations
// with D(J || J0) = tr(J0^-1 J) - log det(J0^-1 J) - 4 (the entropic divergence of Lee, Wensing
// and Park, "Geometric robot dynamic identification: a convex programming approach", IEEE T-RO
// 2020), J0, x0 the MJCF's values and sigma the least-squares residual standard deviation (at
// least 1e-4 of the torques' RMS). Directions the data cannot see (W's null space) cost nothing
// in the first term, so the prior keeps them at the MJCF's values; elsewhere lambda = 1 weighs
// next to nothing against thousands of equations. NLopt's SLSQP minimises it with analytic
// gradients (chain rule through pi(theta)), in variables whitened by the Gauss-Newton Hessian
// (re-computed at each round's end, a few rounds), the joint terms' bounds as linear constraints. Standard errors: the inverse Gauss-Newton Hessian
// at the optimum (data + prior), sigma re-estimated from the fit's residual, mapped to mass,
// centre of mass and inertia by the delta method.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "spml/dataset.h"
#include "spml/envs/body_inertial.h"
#include "spml/envs/mjcf_regressor.h"

namespace spml {

struct ConsistentOptions {
  double prior_weight = 1.0;      // lambda above
  double sigma_floor = 1e-4;      // sigma >= this times the RMS of the torques
  int max_evaluations = 20000;
  double max_seconds = 120;
  double change_z = 2.0;          // a body "changed" when a quantity moved by more than this many SEs
};

struct ConsistentBody {
  std::string name;
  int body_id = 0;             // MuJoCo body id
  bool fitted = false;         // false: kept at the MJCF's values (see note)
  std::string note;
  BodyInertial identified, prior;
  Vector10d std_error = Vector10d::Zero();   // mass, com xyz, fullinertia (xx yy zz xy xz yz)
  double max_z = 0;            // largest |identified - prior| / SE over those ten
  bool changed = false;        // max_z > ConsistentOptions::change_z
};

struct ConsistentTerm {        // a non-body standard parameter (armature:j, damping:j, ...)
  std::string name;
  double value = 0, std_error = 0, prior = 0;
  bool fitted = false, at_bound = false;
};

struct ConsistentIdentification {
  std::vector<ConsistentBody> bodies;
  std::vector<ConsistentTerm> terms;
  Eigen::VectorXd pi, prior;        // standard parameters, MjcfRegressor::param_names() order
  Eigen::MatrixXd covariance;       // of pi
  double sigma = 0;                 // residual standard deviation of the fit
  double sigma_objective = 0;       // the sigma the objective used
  int rank = 0;                     // of the stacked regressor
  int evaluations = 0;
  double seconds = 0;
  std::string stop;                 // CONVERGED, or why not (MAXEVAL_REACHED, MAXTIME_REACHED)
  double prior_weight = 0;
  std::vector<Identification::SplitError> errors;   // as in identify(): fit split first
  Eigen::VectorXd extra, extra_std_error;           // coefficients of the extra columns, if any
};

// The stacked standard regressor (all of reg.param_names(), rows output-major as in
// stacked_base_regressor) of inputs X laid out like that split.
Eigen::MatrixXd stacked_standard_regressor(const MjcfRegressor& reg, const RowMatrix& X, const JointColumns& cols,
                                           const std::string& where);

// The fit on a stacked regressor W (columns: reg.param_names()) and torques tau. `extra`
// (same rows, optional): more columns fitted jointly with free coefficients (e.g. force
// effects a diagnosis found), each with a prior toward 0 worth lambda equations as for the
// joint terms; their coefficients come back in `extra`. Throws std::runtime_error when the
// problem is empty or not finite.
ConsistentIdentification fit_consistent(const MjcfRegressor& reg, const Eigen::MatrixXd& W, const Eigen::VectorXd& tau,
                                        const ConsistentOptions& options = {}, const Eigen::MatrixXd& extra = Eigen::MatrixXd());

// The fit on one split of a dataset (columns as for identify()), every split scored.
ConsistentIdentification identify_consistent(const MjcfRegressor& reg, const Dataset& ds, const std::string& split,
                                             const ConsistentOptions& options = {});

}  // namespace spml
