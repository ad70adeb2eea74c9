// LearnerRegistry: learner plugin libraries through the shared loader, each entry wrapped as
// a C++ Learner, and compositions of any two.
#include <algorithm>
#include <sstream>

#include "spml/learners/composition.h"
#include "spml/learners/learner.h"

namespace spml {
namespace {

std::string check_learner(const void* entry) { return learner_problem(*static_cast<const spml_learner*>(entry)); }

std::set<std::string> key_set(const spml_config_key* table) {
  std::set<std::string> out;
  for (const spml_config_key* k = table; k && k->name; ++k) out.insert(k->name);
  return out;
}

// A learner from a plugin library: marshals Eigen data into the C ABI.
class PluginLearner : public Learner {
 public:
  explicit PluginLearner(const spml_learner* api) : api_(api) {}
  ~PluginLearner() override { release(); }
  std::string name() const override { return api_->name; }
  std::uint32_t flags() const override { return api_->flags; }

  void fit(const LearnerData& train, const LearnerModel& model, const LearnerConfig& config) override {
    release();
    // The user's values for this learner's keys, then the table's defaults for the rest.
    std::vector<std::pair<std::string, std::string>> mine;
    for (const auto& kv : config.values)
      if (find_config_key(api_->config_keys, kv.first)) mine.push_back(kv);
    const auto filled = with_defaults(api_->config_keys, std::move(mine));
    std::vector<const char*> keys, values;
    for (const auto& [k, v] : filled) {
      keys.push_back(k.c_str());
      values.push_back(v.c_str());
    }
    spml_learner_config c{static_cast<int32_t>(keys.size()), keys.data(), values.data(), config.seed};
    std::vector<const char*> names;
    for (const auto& n : model.names) names.push_back(n.c_str());
    const int32_t M = train.phi ? static_cast<int32_t>(train.phi->cols()) : 0;
    spml_learner_model m{M, names.empty() ? nullptr : names.data(),
                         model.prior.size() == M && M > 0 ? model.prior.data() : nullptr,
                         model.truth.size() == M && M > 0 ? model.truth.data() : nullptr};
    spml_learner_data d = to_c(train);
    char error[1024] = "";
    // Revision 1: fit_progress only for an entry flagged PROGRESS (an older entry ends at destroy).
    if (config.progress && (api_->flags & SPML_LEARNER_PROGRESS))
      state_ = api_->fit_progress(&d, &m, &c, &PluginLearner::forward_progress, const_cast<ProgressFn*>(&config.progress),
                                  error, sizeof error);
    else
      state_ = api_->fit(&d, &m, &c, error, sizeof error);
    if (!state_) throw LearnerError(std::string(api_->name) + ": fit failed: " + (error[0] ? error : "no message"));
  }

  LearnerPrediction predict(const LearnerData& query) const override {
    if (!state_) throw LearnerError(std::string(api_->name) + ": predict before fit");
    spml_learner_data d = to_c(query);
    LearnerPrediction p;
    p.mean.resize(query.X->rows(), query.outputs);
    if (has_variance()) p.var.resize(query.X->rows(), query.outputs);
    char error[1024] = "";
    if (api_->predict(state_, &d, p.mean.data(), has_variance() ? p.var.data() : nullptr, error, sizeof error) != 0)
      throw LearnerError(std::string(api_->name) + ": predict failed: " + (error[0] ? error : "no message"));
    return p;
  }

  std::string notes() const override {
    const char* n = state_ && api_->notes ? api_->notes(state_) : nullptr;
    return n ? n : "";
  }
  Eigen::VectorXd coefficients() const override {
    if (!state_ || !api_->coefficients) return {};
    const int32_t n = api_->coefficients(state_, nullptr, 0);
    Eigen::VectorXd c(std::max<int32_t>(n, 0));
    if (n > 0) api_->coefficients(state_, c.data(), n);
    return c;
  }

 private:
  void release() {
    if (state_) api_->destroy(state_);
    state_ = nullptr;
  }
  // The C callback handed to fit_progress: nothing may unwind into the plugin.
  static void forward_progress(void* context, double fraction, const char* stage) {
    try {
      (*static_cast<ProgressFn*>(context))(fraction, stage ? stage : "");
    } catch (...) {
    }
  }
  static spml_learner_data to_c(const LearnerData& in) {
    spml_learner_data d{};
    d.rows = in.X->rows();
    d.inputs = static_cast<int32_t>(in.X->cols());
    d.outputs = in.outputs;
    d.x = in.X->data();
    d.y = in.Y ? in.Y->data() : nullptr;
    d.params = in.phi ? static_cast<int32_t>(in.phi->cols()) : 0;
    d.phi = in.phi ? in.phi->data() : nullptr;
    return d;
  }
  const spml_learner* api_;   // the catalog keeps its library loaded for the registry's life
  void* state_ = nullptr;
};

}  // namespace

const PluginKind& learner_plugin_kind() {
  static const PluginKind kind{"learner", "spml_learner", SPML_LEARNER_ABI_VERSION, "SPML_LEARNER_PATH", "learners"};
  return kind;
}

std::string learner_problem(const spml_learner& l) {
  if (!l.fit || !l.predict || !l.destroy) return "entry lacks fit, predict or destroy";
  // Read past destroy only when the flag says the entry is of revision 1 or later.
  if ((l.flags & SPML_LEARNER_PROGRESS) && !l.fit_progress) return "entry is flagged PROGRESS but lacks fit_progress";
  return "";
}

LearnerRegistry::LearnerRegistry() : catalog_(learner_plugin_kind(), &check_learner) {}

void LearnerRegistry::add_default_path() { catalog_.add_default_path(); }
void LearnerRegistry::add(const std::string& where) { catalog_.add(where, true); }

const spml_learner* LearnerRegistry::plugin(const std::string& name) const {
  return static_cast<const spml_learner*>(catalog_.find(name));
}

std::string LearnerRegistry::plugin_file(const std::string& name) const { return catalog_.file_of(name); }

bool LearnerRegistry::split_composition(const std::string& name, std::string* a, std::string* b, bool* iterative) const {
  return parse_composition(name, [this](const std::string& n) { return plugin(n) != nullptr; }, a, b, iterative);
}

std::vector<std::string> LearnerRegistry::expand(const std::string& list) const {
  const auto& names = plugin_names();
  std::vector<std::string> out;
  if (list == "all") {
    out = names;
    for (const char* prefix : {"", "it-"})
      for (const auto& a : names)
        for (const auto& b : names)
          if ((plugin(a)->flags & SPML_LEARNER_PARAMETRIC) && (plugin(b)->flags & SPML_LEARNER_NONPARAMETRIC))
            out.push_back(prefix + a + "-" + b);
    return out;
  }
  std::stringstream ss(list);
  std::string name;
  while (std::getline(ss, name, ',')) {
    if (name.empty()) continue;
    std::string a, b;
    bool it = false;
    if (!plugin(name) && !split_composition(name, &a, &b, &it))
      throw LearnerError(catalog_.unknown(name) + "; compositions A-B / it-A-B of them are accepted too");
    if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
  }
  if (out.empty()) throw LearnerError("no learner named in '" + list + "'");
  return out;
}

std::unique_ptr<Learner> LearnerRegistry::create(const std::string& name) const {
  if (const spml_learner* l = plugin(name)) return std::make_unique<PluginLearner>(l);
  std::string a, b;
  bool iterative = false;
  if (!split_composition(name, &a, &b, &iterative)) throw LearnerError(catalog_.unknown(name));
  return make_composition(name, create(a), create(b), iterative);
}

std::vector<std::string> LearnerRegistry::library_files(const std::string& name) const {
  if (plugin(name)) return {plugin_file(name)};
  std::string a, b;
  bool iterative = false;
  if (!split_composition(name, &a, &b, &iterative)) return {};
  std::vector<std::string> files = library_files(a);
  for (const auto& f : library_files(b)) files.push_back(f);
  return files;
}

std::set<std::string> LearnerRegistry::config_keys(const std::string& name) const {
  if (const spml_learner* l = plugin(name)) return key_set(l->config_keys);
  std::string a, b;
  bool iterative = false;
  if (!split_composition(name, &a, &b, &iterative)) return {};
  std::set<std::string> keys = config_keys(a);
  for (const auto& k : config_keys(b)) keys.insert(k);
  if (iterative) keys.insert("iterations");
  return keys;
}

std::string LearnerRegistry::check_config(const std::string& name, const std::string& key, const std::string& value) const {
  if (const spml_learner* l = plugin(name)) {
    const spml_config_key* k = find_config_key(l->config_keys, key);
    return k ? check_config_value(*k, value) : "";
  }
  std::string a, b;
  bool iterative = false;
  if (!split_composition(name, &a, &b, &iterative)) return "";
  if (iterative && key == "iterations") {
    static const spml_config_key kIterations{"iterations", SPML_VALUE_INTEGER, 1, 1000, "3", "rounds of it-A-B"};
    return check_config_value(kIterations, value);
  }
  std::string problem = check_config(a, key, value);
  return problem.empty() ? check_config(b, key, value) : problem;
}

}  // namespace spml
