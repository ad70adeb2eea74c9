// Learner plugins from Python: the registry the command line uses (shipped learners, then
// $SPML_LEARNER_PATH, then add_learner_path), each learner's key table, and one fitted
// learner as a native object that the Python Learner class wraps.
#include <pybind11/stl.h>

#include <algorithm>
#include <memory>

#include "convert.h"
#include "spml/learners/composition.h"
#include "spml/learners/evaluate.h"
#include "spml/learners/learner.h"

namespace spml::py {
namespace {

// One registry for the module's life. Never destroyed: fitted learners' code lives in its
// libraries, and Python may release a learner during interpreter shutdown.
LearnerRegistry& registry() {
  static LearnerRegistry* r = [] {
    auto* reg = new LearnerRegistry;
    reg->add_default_path();
    return reg;
  }();
  return *r;
}

pb::dict flag_dict(std::uint32_t f) {
  pb::dict d;
  d["uses_model"] = bool(f & SPML_LEARNER_USES_MODEL);
  d["variance"] = bool(f & SPML_LEARNER_VARIANCE);
  d["parametric"] = bool(f & SPML_LEARNER_PARAMETRIC);
  d["nonparametric"] = bool(f & SPML_LEARNER_NONPARAMETRIC);
  d["deterministic"] = bool(f & SPML_LEARNER_DETERMINISTIC);
  d["needs_prior"] = bool(f & SPML_LEARNER_NEEDS_PRIOR);
  d["needs_truth"] = bool(f & SPML_LEARNER_NEEDS_TRUTH);
  d["progress"] = bool(f & SPML_LEARNER_PROGRESS);   // ABI revision 1: reports progress during fit
  return d;
}

pb::dict key_dict(const spml_config_key& k) {
  static const char* types[] = {"", "number", "integer", "numbers", "text"};
  pb::dict d;
  d["type"] = k.type >= 1 && k.type <= 4 ? types[k.type] : "unknown";
  d["min"] = k.min;
  d["max"] = k.max;
  d["default"] = k.default_value ? pb::object(pb::str(k.default_value)) : pb::none();
  d["help"] = k.help ? k.help : "";
  return d;
}

// Every key of `name` with its description; a composition's come from its parts' tables.
void add_keys(const std::string& name, pb::dict& keys) {
  if (const spml_learner* l = registry().plugin(name)) {
    for (const spml_config_key* k = l->config_keys; k && k->name; ++k)
      if (!keys.contains(k->name)) keys[k->name] = key_dict(*k);
    return;
  }
  std::string a, b;
  bool iterative = false;
  parse_composition(name, [](const std::string& n) { return registry().plugin(n) != nullptr; }, &a, &b, &iterative);
  if (iterative) {
    static const std::string fallback = std::to_string(kDefaultIterations);
    keys["iterations"] = key_dict({"iterations", SPML_VALUE_INTEGER, 1, 1000, fallback.c_str(), "rounds of it-A-B"});
  }
  add_keys(a, keys);
  add_keys(b, keys);
}

// Checks a learner name (a plugin or a composition of two), as a ValueError when unknown.
std::unique_ptr<Learner> create(const std::string& name) {
  try {
    return registry().create(name);
  } catch (const LearnerError& e) {
    throw BadArgument(std::string(e.what()) + "; compositions A-B / it-A-B of them are accepted too");
  }
}

pb::dict learner_info(const std::string& name) {
  const auto l = create(name);
  pb::dict d;
  d["name"] = name;
  const spml_learner* p = registry().plugin(name);
  d["summary"] = p && p->summary ? p->summary : "composition of two learners (README: A-B, it-A-B)";
  d["flags"] = flag_dict(l->flags());
  pb::dict keys;
  add_keys(name, keys);
  d["keys"] = keys;
  std::vector<std::string> files;
  for (const auto& f : registry().library_files(name))
    if (std::find(files.begin(), files.end(), f) == files.end()) files.push_back(f);
  d["files"] = files;
  return d;
}

// "" when fine, else what is wrong with key=value for learner `name`.
std::string config_problem(const std::string& name, const std::string& key, const std::string& value) {
  const auto keys = registry().config_keys(name);
  if (!keys.count(key)) {
    std::string list;
    for (const auto& k : keys) list += (list.empty() ? "" : ", ") + k;
    return "learner '" + name + "' has no config key '" + key + "' (its keys: " + (list.empty() ? "none" : list) + ")";
  }
  const std::string why = registry().check_config(name, key, value);
  return why.empty() ? "" : name + ": " + key + "=" + value + ": " + why;
}

void require_finite(const RowMatrix& m, const std::string& what) {
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    if (!m.row(i).allFinite()) throw BadArgument(what + ": row " + std::to_string(i) + " holds NaN or Inf");
}

}  // namespace

// One learner: fit once (again and again), predict many times. Checks every shape before the
// C ABI sees the data (the plugins trust the sizes they are given).
class NativeLearner {
 public:
  explicit NativeLearner(const std::string& name) : name_(name), learner_(create(name)) {}

  void fit(const pb::handle& X_in, const pb::handle& Y_in, const pb::handle& phi_in, const std::vector<std::string>& names,
           const pb::handle& prior, const pb::handle& truth, const std::vector<std::pair<std::string, std::string>>& config,
           std::uint64_t seed) {
    const RowMatrix X = to_matrix(X_in, "X"), Y = to_matrix(Y_in, "Y");
    if (X.rows() != Y.rows())
      throw BadArgument("X has " + std::to_string(X.rows()) + " rows but Y has " + std::to_string(Y.rows()));
    if (X.rows() == 0) throw BadArgument("X: no rows to fit on");
    require_finite(X, "X");
    require_finite(Y, "Y");
    LearnerModel model;
    RowMatrix phi;
    const bool has_phi = !phi_in.is_none();
    if (has_phi) {
      phi = check_phi(phi_in, X.rows(), Y.cols(), -1);
      model.names = names;
      if (model.names.empty())
        for (Eigen::Index j = 0; j < phi.cols(); ++j) model.names.push_back("theta" + std::to_string(j));
      if (static_cast<Eigen::Index>(model.names.size()) != phi.cols())
        throw BadArgument(std::to_string(model.names.size()) + " parameter names for phi's " + std::to_string(phi.cols()) + " columns");
      if (!prior.is_none()) model.prior = coefficients_arg(prior, "prior", phi.cols());
      if (!truth.is_none()) model.truth = coefficients_arg(truth, "truth", phi.cols());
    } else if (learner_->uses_model()) {
      throw BadArgument("learner '" + name_ + "' uses the parametric model: pass model= (spml.parametric_model) or phi=");
    }
    LearnerConfig c;
    for (const auto& [k, v] : config)
      if (std::string why = config_problem(name_, k, v); !why.empty()) throw BadArgument(why);
    c.values = config;
    c.seed = seed;
    LearnerData d{&X, &Y, has_phi ? &phi : nullptr, static_cast<int>(Y.cols())};
    fitted_ = false;
    {
      pb::gil_scoped_release release;   // long fits leave other Python threads running
      learner_->fit(d, model, c);
    }
    inputs_ = X.cols();
    outputs_ = static_cast<int>(Y.cols());
    params_ = has_phi ? phi.cols() : -1;
    fitted_ = true;
  }

  pb::tuple predict(const pb::handle& X_in, const pb::handle& phi_in) const {
    if (!fitted_) throw BadArgument("learner '" + name_ + "': predict before fit");
    const RowMatrix X = to_matrix(X_in, "X");
    if (X.cols() != inputs_)
      throw BadArgument("X has " + std::to_string(X.cols()) + " columns, the fit had " + std::to_string(inputs_));
    require_finite(X, "X");
    RowMatrix phi;
    if (params_ >= 0) {
      if (phi_in.is_none()) throw BadArgument("learner '" + name_ + "' was fitted with a parametric model: predict needs its phi too");
      phi = check_phi(phi_in, X.rows(), outputs_, params_);
    }
    LearnerData d{&X, nullptr, params_ >= 0 ? &phi : nullptr, outputs_};
    LearnerPrediction p;
    {
      pb::gil_scoped_release release;
      p = learner_->predict(d);
    }
    return pb::make_tuple(to_numpy(p.mean), p.var.size() ? pb::object(to_numpy(p.var)) : pb::none());
  }

  std::string name() const { return name_; }
  std::uint32_t flags() const { return learner_->flags(); }
  std::string notes() const { return learner_->notes(); }
  pb::object coefficients() const {
    const Eigen::VectorXd c = learner_->coefficients();
    return c.size() ? pb::object(to_numpy(c)) : pb::none();
  }

 private:
  static RowMatrix check_phi(const pb::handle& obj, Eigen::Index rows, Eigen::Index outputs, Eigen::Index params) {
    RowMatrix phi = to_matrix(obj, "phi");
    if (phi.rows() != rows * outputs)
      throw BadArgument("phi has " + std::to_string(phi.rows()) + " rows, expected outputs x rows = " + std::to_string(outputs) +
                        " x " + std::to_string(rows) + " (stacked output-major)");
    if (params >= 0 && phi.cols() != params)
      throw BadArgument("phi has " + std::to_string(phi.cols()) + " columns, the fit's had " + std::to_string(params));
    require_finite(phi, "phi");
    return phi;
  }
  static Eigen::VectorXd coefficients_arg(const pb::handle& obj, const std::string& what, Eigen::Index params) {
    Eigen::VectorXd v = to_vector(obj, what);
    if (v.size() != params)
      throw BadArgument(what + " has " + std::to_string(v.size()) + " values for phi's " + std::to_string(params) + " columns");
    return v;
  }

  std::string name_;
  std::unique_ptr<Learner> learner_;
  Eigen::Index inputs_ = 0, params_ = -1;
  int outputs_ = 0;
  bool fitted_ = false;
};

void bind_learners(pb::module_& m) {
  m.def("learners", [](bool compositions) { return compositions ? registry().expand("all") : registry().plugin_names(); },
        pb::arg("compositions") = false);
  m.def(
      "add_learner_path", [](const std::string& p) { naming_missing_files({p}, [&] { registry().add(p); }); }, pb::arg("path"));
  m.def("learner_warnings", [] { return registry().warnings(); });
  m.def("learner_info", &learner_info, pb::arg("name"));
  m.def("config_problem", &config_problem, pb::arg("name"), pb::arg("key"), pb::arg("value"));
  m.def(
      "score",
      [](const pb::handle& Y, const pb::handle& mean, const pb::handle& var) {
        LearnerPrediction p{to_matrix(mean, "mean"), var.is_none() ? RowMatrix() : to_matrix(var, "var")};
        const RowMatrix y = to_matrix(Y, "Y");
        if (p.mean.rows() != y.rows() || p.mean.cols() != y.cols() || (p.var.size() && (p.var.rows() != y.rows() || p.var.cols() != y.cols())))
          throw BadArgument("Y, mean and var must have the same shape");
        const Scores s = score(y, p);
        pb::dict d;
        d["rmse"] = s.rmse;
        d["nllh"] = s.nllh;
        return d;
      },
      pb::arg("Y"), pb::arg("mean"), pb::arg("var") = pb::none());
  pb::class_<NativeLearner>(m, "NativeLearner")
      .def(pb::init<const std::string&>(), pb::arg("name"))
      .def("fit", &NativeLearner::fit, pb::arg("X"), pb::arg("Y"), pb::arg("phi"), pb::arg("names"), pb::arg("prior"),
           pb::arg("truth"), pb::arg("config"), pb::arg("seed"))
      .def("predict", &NativeLearner::predict, pb::arg("X"), pb::arg("phi"))
      .def_property_readonly("name", &NativeLearner::name)
      .def_property_readonly("flags", [](const NativeLearner& l) { return flag_dict(l.flags()); })
      .def("notes", &NativeLearner::notes)
      .def("coefficients", &NativeLearner::coefficients);
}

}  // namespace spml::py
