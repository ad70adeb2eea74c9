// The one matrix type of spml's data (row-major, like HDF5 and the C ABIs) and the one
// output-major stacking of targets that goes with the stacked regressor phi.
#pragma once

#include <Eigen/Core>

namespace spml {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Targets Y (N x outputs) stacked output-major: entry [o * N + i] = Y(i, o), matching the
// rows of a stacked regressor phi (row o * N + i holds phi_o(x_i)).
template <class Derived>
Eigen::VectorXd stacked_targets(const Eigen::MatrixBase<Derived>& Y) {
  Eigen::VectorXd b(Y.size());
  for (Eigen::Index o = 0; o < Y.cols(); ++o) b.segment(o * Y.rows(), Y.rows()) = Y.col(o);
  return b;
}

}  // namespace spml
