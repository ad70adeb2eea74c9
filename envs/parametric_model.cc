#include "spml/envs/parametric_model.h"

#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>

#include <unistd.h>

#include "spml/envs/mjcf_regressor.h"
#include "spml/matrix_file.h"
#include "spml/plugin_loader.h"

namespace spml {
namespace {

namespace fs = std::filesystem;

std::map<std::string, ParametricModelFactory>& factories() {
  static std::map<std::string, ParametricModelFactory> f;
  return f;
}

// Any MJCF through its identification regressor, on base parameters.
class MjcfModel : public ParametricModel {
 public:
  // `label` names the model in messages and bench.json (the file, or where inline XML came from).
  MjcfModel(const std::string& file, const std::string& label, const Dataset& ds, const Split& layout)
      : label_(label), reg_(file), base_(reg_.base_parameters()), cols_(reg_, layout) {
    warn_inverse_mismatches(reg_, label_);
    param_names = base_.names;
    prior = base_.model_values;
    outputs = static_cast<int>(layout.Y.cols());
    for (int j = 0; j < reg_.model()->njnt; ++j)
      if (reg_.model()->jnt_type[j] == mjJNT_SLIDE) slide_joints.push_back(reg_.joint_names()[static_cast<size_t>(j)]);
    // The dataset's truth applies when it is stated in these same parameters.
    if (ds.model.param_names == param_names && ds.model.truth.size() == num_params()) truth = ds.model.truth;
  }
  std::string name() const override { return "mjcf:" + label_; }
  Eigen::MatrixXd stacked(const RowMatrix& X) const override {
    // X may come from any split laid out like `layout`; it is not named here.
    return stacked_base_regressor(reg_, base_, X, cols_, "(query)");
  }

 private:
  std::string label_;
  MjcfRegressor reg_;
  MjcfRegressor::Base base_;
  JointColumns cols_;
};

// A private folder (mkdtemp, mode 0700) removed with everything in it when it goes.
class PrivateDir {
 public:
  PrivateDir() {
    std::string pattern = (fs::temp_directory_path() / "spml-model-XXXXXX").string();
    if (!::mkdtemp(pattern.data())) throw DatasetError("cannot create a private temporary folder in " + fs::temp_directory_path().string());
    path_ = pattern;
  }
  ~PrivateDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

// The dataset's own MJCF text (model/mjcf_xml). MuJoCo 2.2.2 loads models from files, so the
// text goes into a private folder nobody else can write to (a predictable name in $TMPDIR
// let a planted file change the model). Files it would include are refused: next to a
// temporary copy they cannot be found, and nothing else says where they are.
std::unique_ptr<ParametricModel> embedded_mjcf_model(const Dataset& ds, const Split& layout, const std::string& where) {
  const std::string& xml = ds.model.mjcf_xml;
  if (const auto at = xml.find("<include"); at != std::string::npos)
    throw DatasetError("group 'model': attribute 'mjcf_xml' includes other files ('" + xml.substr(at, 60) +
                       "...'), which an embedded model cannot resolve; store the model's path in mjcf_path or give "
                       "the MJCF with --model");
  PrivateDir dir;
  const fs::path file = dir.path() / "model.xml";
  write_text_atomic(file.string(), xml);
  return std::make_unique<MjcfModel>(file.string(), where + ":model/mjcf_xml", ds, layout);
}

}  // namespace

RowMatrix ParametricModel::predict(const RowMatrix& X, const Eigen::VectorXd& theta) const {
  const Eigen::VectorXd y = stacked(X) * theta;
  RowMatrix Y(X.rows(), outputs);
  for (int o = 0; o < outputs; ++o) Y.col(o) = y.segment(o * X.rows(), X.rows());
  return Y;
}

Eigen::MatrixXd RowwiseModel::stacked(const RowMatrix& X) const {
  const Eigen::Index N = X.rows();
  Eigen::MatrixXd A(N * outputs, num_params());
  for (Eigen::Index i = 0; i < N; ++i) {
    const Eigen::MatrixXd phi = features(X.row(i));
    for (int o = 0; o < outputs; ++o) A.row(o * N + i) = phi.row(o);
  }
  return A;
}

int require_column(const Split& s, const std::string& column, const std::string& model) {
  const int i = s.x_index(column);
  if (i < 0) throw DatasetError("split '" + s.name + "': model '" + model + "' needs input column '" + column + "'");
  return i;
}

void require_outputs(const Split& s, const std::vector<std::string>& names, const std::string& model) {
  if (s.y_columns != names)
    throw DatasetError("split '" + s.name + "': model '" + model + "' predicts the outputs " + join_list(names) +
                       " but Y has the columns " + join_list(s.y_columns));
}

void take_coefficients(ParametricModel& m, const Dataset& ds, int params, int outputs) {
  if (ds.model.param_names.size() != static_cast<size_t>(params))
    throw DatasetError("group 'model': '" + ds.model.name + "' has " + std::to_string(params) +
                       " parameters, param_names lists " + std::to_string(ds.model.param_names.size()));
  m.param_names = ds.model.param_names;
  m.prior = ds.model.prior;
  m.truth = ds.model.truth;
  m.outputs = outputs;
}

bool register_parametric_model(const std::string& name, ParametricModelFactory factory) {
  factories()[name] = std::move(factory);
  return true;
}

std::string resolve_mjcf_path(const std::string& stored, const std::string& dataset_file) {
  const fs::path p(stored);
  std::vector<fs::path> tries;
  if (p.is_absolute()) tries.push_back(p);
  else {
    if (!dataset_file.empty()) tries.push_back(fs::path(dataset_file).parent_path() / p);
    tries.push_back(p);
    tries.push_back(fs::path(spml_share_dir()) / p);
  }
  for (const auto& t : tries)
    if (fs::is_regular_file(t)) return t.string();
  std::string looked;
  for (const auto& t : tries) looked += (looked.empty() ? "" : ", ") + t.string();
  throw DatasetError(dataset_file + ": group 'model': attribute 'mjcf_path' = '" + stored +
                     "' is not a file (looked at " + looked + "); give the model with --model");
}

std::unique_ptr<ParametricModel> make_parametric_model(const Dataset& ds, const Split& layout,
                                                       const std::string& mjcf_override) {
  std::unique_ptr<ParametricModel> model;
  const std::string where = ds.source.empty() ? std::string("dataset") : ds.source;
  try {
    if (!mjcf_override.empty()) {
      model = std::make_unique<MjcfModel>(mjcf_override, mjcf_override, ds, layout);
    } else if (auto it = factories().find(ds.model.name); !ds.model.name.empty() && it != factories().end()) {
      model = it->second(ds, layout);
    } else if (!ds.model.mjcf_xml.empty()) {
      model = embedded_mjcf_model(ds, layout, where);
    } else if (!ds.model.mjcf_path.empty()) {
      const std::string file = resolve_mjcf_path(ds.model.mjcf_path, where);
      model = std::make_unique<MjcfModel>(file, file, ds, layout);
    } else if (!ds.model.name.empty()) {
      std::string known;
      for (const auto& [n, f] : factories()) known += (known.empty() ? "" : ", ") + n;
      throw DatasetError("group 'model': no parametric model called '" + ds.model.name + "' (known: " + known +
                         ") and no mjcf_path/mjcf_xml; give the MJCF with --model");
    } else {
      throw DatasetError("no parametric model: the file has no 'model' group; give the robot's MJCF with --model");
    }
  } catch (const DatasetError& e) {
    throw DatasetError(where + ": " + e.what());
  } catch (const std::runtime_error& e) {
    throw DatasetError(e.what());
  }
  if (model->num_outputs() != layout.Y.cols())
    throw DatasetError(where + ": split '" + layout.name + "': Y has " + std::to_string(layout.Y.cols()) + " columns (" +
                       join_list(layout.y_columns) + ") but the parametric model '" + model->name() + "' predicts " +
                       std::to_string(model->num_outputs()));
  return model;
}

}  // namespace spml
