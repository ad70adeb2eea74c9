// The parametric model h_theta(x) = Phi(x) theta of a dataset, as the learners see it.
//
// Where it comes from, in this order:
//   1. an MJCF given explicitly (spml bench --model M.xml): the MJCF regressor's base
//      parameters (envs/mjcf_regressor.h), prior = the MJCF's own values;
//   2. the dataset's model/name, when a scenario registered an analytic model under that
//      name (the paper's own regressors: toy, via, planar_arm3, with the paper's
//      coefficient names, prior and truth);
//   3. the dataset's model/mjcf_xml or model/mjcf_path: the MJCF regressor again.
// So any measured dataset with an MJCF gets a parametric model, and nothing here (or in
// the learner host) knows scenario names.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "spml/dataset.h"

namespace spml {

class ParametricModel {
 public:
  virtual ~ParametricModel() = default;
  virtual std::string name() const = 0;
  int num_params() const { return static_cast<int>(param_names.size()); }
  int num_outputs() const { return outputs; }
  // Stacked regressor of a split laid out like the one the model was made for, output-major:
  // rows [o * N + i] = Phi_o(x_i), outputs in that split's Y column order.
  virtual Eigen::MatrixXd stacked(const RowMatrix& X) const = 0;
  // Predictions h_theta(X): N x outputs.
  RowMatrix predict(const RowMatrix& X, const Eigen::VectorXd& theta) const;

  std::vector<std::string> param_names;
  Eigen::VectorXd prior, truth;   // empty when unknown
  int outputs = 0;
  // The model's slide joints (their columns are in N, m, ...; every other joint is a hinge).
  std::vector<std::string> slide_joints;
};

// An analytic model written per input row: features(x) is outputs x params.
class RowwiseModel : public ParametricModel {
 public:
  Eigen::MatrixXd stacked(const RowMatrix& X) const override;
  virtual Eigen::MatrixXd features(const Eigen::Ref<const Eigen::RowVectorXd>& x) const = 0;
};
// Index of a required X column; throws DatasetError naming the split, column and model.
int require_column(const Split& s, const std::string& column, const std::string& model);
// Throws unless the split's Y columns are exactly `names`, in this order.
void require_outputs(const Split& s, const std::vector<std::string>& names, const std::string& model);

// Takes the coefficient names, prior and truth of an analytic model from the dataset's
// model group; throws unless it lists `params` names.
void take_coefficients(ParametricModel& m, const Dataset& ds, int params, int outputs);

// An analytic model's factory: wires it to the split's columns (throws DatasetError naming a
// missing column) and fills names/prior/truth from the dataset.
using ParametricModelFactory = std::function<std::unique_ptr<ParametricModel>(const Dataset&, const Split&)>;
// Called by the scenarios at load time; returns true so it can initialise a static.
bool register_parametric_model(const std::string& name, ParametricModelFactory factory);

// The model of `ds` (rules above) wired to the columns of `layout`. `mjcf_override` is an
// MJCF file or "". Throws DatasetError naming the file, column or missing model.
std::unique_ptr<ParametricModel> make_parametric_model(const Dataset& ds, const Split& layout,
                                                       const std::string& mjcf_override = "");

// A path as stored in model/mjcf_path, resolved: absolute; else next to the dataset file;
// else relative to the working folder; else in spml's share folder (mjcf/...).
std::string resolve_mjcf_path(const std::string& stored, const std::string& dataset_file);

}  // namespace spml
