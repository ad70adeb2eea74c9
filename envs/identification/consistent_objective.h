// The objective of the physically consistent fit (see spml/envs/consistent_identification.h)
// in the variables theta = (psi of every fitted body, then every fitted non-body parameter).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "spml/envs/log_cholesky.h"

namespace spml::identification {

struct Layout {
  std::vector<int> bodies;    // regressor body index b (standard parameters 10b .. 10b+9), fitted
  std::vector<int> terms;     // standard-parameter index of every fitted non-body parameter
  std::vector<bool> bounded;  // per term: bounded below by 0
  int size() const { return static_cast<int>(10 * bodies.size() + terms.size()); }
};

class ConsistentObjective {
 public:
  // R, z: ||W pi - tau||^2 = ||R pi - z||^2 + const (R square). pi0: the MJCF's standard
  // parameters (also the value of everything not fitted); term_weight: prior precision per term.
  ConsistentObjective(Layout layout, Eigen::MatrixXd R, Eigen::VectorXd z, double sigma, Eigen::VectorXd pi0,
                      Eigen::VectorXd term_weight, double lambda);

  const Layout& layout() const { return layout_; }
  Eigen::VectorXd start() const;   // the MJCF's point, joint terms raised to their bounds
  // pi(theta) and, optionally, d pi / d theta.
  Eigen::VectorXd standard(const Eigen::VectorXd& theta, Eigen::MatrixXd* jacobian = nullptr) const;
  double value(const Eigen::VectorXd& theta, Eigen::VectorXd* gradient = nullptr) const;
  // Gauss-Newton Hessian: data term with noise sigma, plus the prior's metric.
  Eigen::MatrixXd hessian(const Eigen::VectorXd& theta, double sigma) const;

 private:
  Layout layout_;
  Eigen::MatrixXd R_;
  Eigen::VectorXd z_, pi0_, term_weight_;
  double sigma_, lambda_;
  std::vector<Matrix4d> J0inv_;     // per fitted body
  std::vector<double> logdetJ0_;
  std::vector<Vector10d> psi0_;
};

}  // namespace spml::identification
