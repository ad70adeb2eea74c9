// The parametric model h_theta(x) = Phi(x) theta of a dataset, as the learners see it:
// for each input row, a D_out x M regressor. Chosen from the dataset's `model` group.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "spml/dataset.h"

namespace spml {

class ParametricModel {
 public:
  virtual ~ParametricModel() = default;
  virtual std::string name() const = 0;
  virtual int num_params() const = 0;
  virtual int num_outputs() const = 0;
  // Regressor for one input row x (the split's X row): D_out x M.
  virtual Eigen::MatrixXd features(const Eigen::Ref<const Eigen::RowVectorXd>& x) const = 0;

  // Stacked regressor for a whole split, output-major: rows [o * N + i] = Phi_o(x_i).
  Eigen::MatrixXd stacked(const RowMatrix& X) const;
  // Targets in the same output-major order: entry [o * N + i] = Y(i, o).
  static Eigen::VectorXd stacked_targets(const RowMatrix& Y);
  // Predictions h_theta(X): N x D_out.
  RowMatrix predict(const RowMatrix& X, const Eigen::VectorXd& theta) const;
};

// The model named in ds.model.name ("toy", "via", "planar_arm3"), wired to the split's
// column layout. Throws DatasetError naming the missing column or unknown model.
std::unique_ptr<ParametricModel> make_parametric_model(const Dataset& ds, const Split& layout);

}  // namespace spml
