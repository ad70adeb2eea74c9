// The parametric model from Python: a dataset's Phi(x) as the learners get it (the same
// rules as `spml bench`: --model MJCF, the scenario's analytic model, the dataset's MJCF),
// the MJCF regressor's base parameters, and least-squares identification.
#include <pybind11/stl.h>

#include <memory>

#include "convert.h"
#include "dataset_py.h"
#include "spml/envs/mjcf_regressor.h"
#include "spml/envs/parametric_model.h"
#include "spml/force_effects.h"

namespace spml::py {
namespace {

// A ParametricModel wired to one split's column layout; phi() takes X in that layout.
class PyParametricModel {
 public:
  PyParametricModel(const pb::handle& data, const std::string& mjcf, const std::string& split) {
    const Dataset ds = dataset_arg(data);
    const Split& layout = ds.get(split);
    model_ = naming_missing_files({mjcf}, [&] { return make_parametric_model(ds, layout, mjcf); });
    x_columns_ = layout.x_columns;
    y_columns_ = layout.y_columns;
  }
  pb::array_t<double> phi(const pb::handle& X_in) const { return to_numpy(model_->stacked(checked(X_in))); }
  pb::array_t<double> predict(const pb::handle& X_in, const pb::handle& theta_in) const {
    const Eigen::VectorXd theta = to_vector(theta_in, "theta");
    if (theta.size() != model_->num_params())
      throw BadArgument("theta has " + std::to_string(theta.size()) + " values, the model " + std::to_string(model_->num_params()));
    return to_numpy(model_->predict(checked(X_in), theta));
  }
  const ParametricModel& model() const { return *model_; }
  std::vector<std::string> x_columns_, y_columns_;

 private:
  RowMatrix checked(const pb::handle& X_in) const {
    RowMatrix X = to_matrix(X_in, "X");
    if (X.cols() != static_cast<Eigen::Index>(x_columns_.size()))
      throw BadArgument("X has " + std::to_string(X.cols()) + " columns; the model reads the split's " +
                        std::to_string(x_columns_.size()) + " (" + join_list(x_columns_) + ")");
    return X;
  }
  std::unique_ptr<ParametricModel> model_;
};

pb::object optional(const Eigen::VectorXd& v) { return v.size() ? pb::object(to_numpy(v)) : pb::none(); }

std::unique_ptr<MjcfRegressor> load_regressor(const std::string& model, bool offsets) {
  return naming_missing_files({model}, [&] { return std::make_unique<MjcfRegressor>(model, RegressorOptions{offsets}); });
}

pb::dict regressor_dict(const std::string& model, bool offsets, const std::vector<std::string>& plugin_path) {
  add_plugin_paths(plugin_path);
  const auto reg = load_regressor(model, offsets);
  const MjcfRegressor::Base base = reg->base_parameters();
  pb::dict d;
  d["model"] = model;
  d["joints"] = reg->joint_names();
  d["standard_names"] = reg->param_names();
  d["standard_values"] = to_numpy(reg->model_params());
  d["standard_parameters"] = reg->param_names().size();
  d["rank"] = base.rank;
  pb::dict decision;   // the same fields as the commands' --json "rank_decision"
  decision["method"] = "svd";
  decision["tolerance"] = base.tolerance;
  decision["smallest_kept"] = base.smallest_kept;
  decision["largest_dropped"] = base.largest_dropped;
  decision["ratio"] = base.largest_dropped > 0 ? pb::object(pb::float_(base.gap())) : pb::object(pb::none());
  decision["close_call"] = base.close_call();
  decision["singular_values"] = to_numpy(base.singular_values);
  d["rank_decision"] = decision;
  d["names"] = base.names;
  d["prior"] = to_numpy(base.model_values);
  d["independent"] = base.independent;
  d["dependent"] = base.dependent;
  d["Kd"] = to_numpy(base.Kd);
  return d;
}

pb::dict identify_dict(const std::string& model, const pb::handle& data, const std::string& split, bool offsets,
                       const std::vector<std::string>& plugin_path) {
  add_plugin_paths(plugin_path);
  const auto reg = load_regressor(model, offsets);
  const MjcfRegressor::Base base = reg->base_parameters();
  const Dataset ds = dataset_arg(data);
  const Identification id = identify(*reg, base, ds, split);
  pb::dict d;
  d["model"] = model;
  d["data"] = ds.source;
  d["split"] = split;
  d["names"] = id.names;
  d["estimate"] = to_numpy(id.estimate);
  d["std_error"] = to_numpy(id.std_error);
  d["prior"] = to_numpy(id.prior);
  d["sigma"] = id.sigma;
  d["condition_number"] = id.condition;
  pb::list errors;
  for (const auto& e : id.errors) {
    pb::dict r;
    r["split"] = e.split;
    r["rows"] = e.rows;
    r["relative_error"] = e.relative_error;
    r["rmse"] = e.rmse;
    errors.append(r);
  }
  d["errors"] = errors;
  return d;
}

}  // namespace

void add_plugin_path(const std::string& p) {
  naming_missing_files({p}, [&] { force_plugins().add(p, true); });
}
void add_plugin_paths(const std::vector<std::string>& paths) {
  for (const auto& p : paths) add_plugin_path(p);
}

void bind_models(pb::module_& m) {
  pb::class_<PyParametricModel>(m, "ParametricModel")
      .def(pb::init<const pb::handle&, const std::string&, const std::string&>(), pb::arg("data"), pb::arg("mjcf") = "",
           pb::arg("split") = "train")
      .def("phi", &PyParametricModel::phi, pb::arg("X"))
      .def("predict", &PyParametricModel::predict, pb::arg("X"), pb::arg("theta"))
      .def_property_readonly("name", [](const PyParametricModel& p) { return p.model().name(); })
      .def_property_readonly("param_names", [](const PyParametricModel& p) { return p.model().param_names; })
      .def_property_readonly("prior", [](const PyParametricModel& p) { return optional(p.model().prior); })
      .def_property_readonly("truth", [](const PyParametricModel& p) { return optional(p.model().truth); })
      .def_property_readonly("outputs", [](const PyParametricModel& p) { return p.model().num_outputs(); })
      .def_readonly("x_columns", &PyParametricModel::x_columns_)
      .def_readonly("y_columns", &PyParametricModel::y_columns_);
  m.def("add_plugin_path", &add_plugin_path, pb::arg("path"));
  m.def("regressor", &regressor_dict, pb::arg("model"), pb::arg("offsets") = false,
        pb::arg("plugin_path") = std::vector<std::string>{});
  m.def("identify", &identify_dict, pb::arg("model"), pb::arg("data"), pb::arg("split") = "train", pb::arg("offsets") = false,
        pb::arg("plugin_path") = std::vector<std::string>{});
}

}  // namespace spml::py
