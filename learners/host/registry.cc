#include <dlfcn.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "spml/learners/learner.h"

namespace spml {

namespace fs = std::filesystem;

class LearnerLibrary {
 public:
  explicit LearnerLibrary(const std::string& file) : file_(file) {
    handle_ = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle_) throw LearnerError("learner library '" + file + "': cannot load: " + dlerror());
    auto version = reinterpret_cast<int32_t (*)()>(dlsym(handle_, "spml_learner_abi_version"));
    auto get = reinterpret_cast<const spml_learner* (*)(int32_t)>(dlsym(handle_, "spml_learner_get"));
    if (!version || !get) {
      dlclose(handle_);
      throw LearnerError("learner library '" + file + "': missing symbol " +
                         (version ? "spml_learner_get" : "spml_learner_abi_version") + " (not an spml learner?)");
    }
    if (version() != SPML_LEARNER_ABI_VERSION) {
      const int v = version();
      dlclose(handle_);
      throw LearnerError("learner library '" + file + "': ABI version " + std::to_string(v) + ", this spml speaks " +
                         std::to_string(SPML_LEARNER_ABI_VERSION) + "; rebuild it against this spml");
    }
    for (int32_t i = 0; const spml_learner* l = get(i); ++i) {
      if (l->abi_version != SPML_LEARNER_ABI_VERSION || !l->name || !l->fit || !l->predict || !l->destroy) {
        dlclose(handle_);
        throw LearnerError("learner library '" + file + "': entry " + std::to_string(i) +
                           " is incomplete or has another ABI version");
      }
      learners_.push_back(l);
    }
  }
  ~LearnerLibrary() {
    if (handle_) dlclose(handle_);
  }
  const std::string& file() const { return file_; }
  const std::vector<const spml_learner*>& learners() const { return learners_; }

 private:
  std::string file_;
  void* handle_ = nullptr;
  std::vector<const spml_learner*> learners_;
};

namespace {

std::set<std::string> key_set(const char* keys) {
  std::set<std::string> out;
  std::stringstream ss(keys ? keys : "");
  std::string k;
  while (std::getline(ss, k, ','))
    if (!k.empty()) out.insert(k);
  return out;
}

// A learner from a plugin library: marshals Eigen data into the C ABI.
class PluginLearner : public Learner {
 public:
  PluginLearner(const spml_learner* api, std::shared_ptr<LearnerLibrary> lib) : api_(api), lib_(std::move(lib)) {}
  ~PluginLearner() override {
    if (state_) api_->destroy(state_);
  }
  std::string name() const override { return api_->name; }
  std::uint32_t flags() const override { return api_->flags; }

  void fit(const LearnerData& train, const LearnerModel& model, const LearnerConfig& config) override {
    if (state_) {
      api_->destroy(state_);
      state_ = nullptr;
    }
    const std::set<std::string> accepted = key_set(api_->config_keys);
    std::vector<const char*> keys, values;
    for (const auto& [k, v] : config.values)
      if (accepted.count(k)) {
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
  const spml_learner* api_;
  std::shared_ptr<LearnerLibrary> lib_;   // keeps the code mapped while the learner lives
  void* state_ = nullptr;
};

// A then B on A's residual (sequential semi-parametric learning, paper eq. 3-5); with
// `iterations` > 1, A is refitted to the data minus B's prediction, and B again (it-A-B).
class SequentialLearner : public Learner {
 public:
  SequentialLearner(std::string name, std::unique_ptr<Learner> a, std::unique_ptr<Learner> b, bool iterative)
      : name_(std::move(name)), a_(std::move(a)), b_(std::move(b)), iterative_(iterative) {}
  std::string name() const override { return name_; }
  std::uint32_t flags() const override {
    const std::uint32_t fa = a_->flags(), fb = b_->flags();
    constexpr std::uint32_t kEither =
        SPML_LEARNER_USES_MODEL | SPML_LEARNER_VARIANCE | SPML_LEARNER_NEEDS_PRIOR | SPML_LEARNER_NEEDS_TRUTH;
    return ((fa | fb) & kEither) | (fa & fb & SPML_LEARNER_DETERMINISTIC);
  }
  void fit(const LearnerData& train, const LearnerModel& model, const LearnerConfig& config) override {
    int iterations = iterative_ ? kDefaultIterations : 1;
    for (const auto& [k, v] : config.values)
      if (k == "iterations" && iterative_) {
        char* end = nullptr;
        iterations = static_cast<int>(std::strtol(v.c_str(), &end, 10));
        if (v.empty() || *end != '\0' || iterations < 1)
          throw LearnerError(name_ + ": config 'iterations' must be an integer >= 1, got '" + v + "'");
      }
    const LearnerMatrix& Y = *train.Y;
    LearnerData part = train;
    LearnerMatrix target = Y;
    for (int it = 0; it < iterations; ++it) {
      if (it > 0) target = Y - b_->predict(without_y(train)).mean;   // eq. 6: residual of B
      part.Y = &target;
      a_->fit(part, model, config);
      LearnerMatrix residual = Y - a_->predict(without_y(train)).mean;
      part.Y = &residual;
      b_->fit(part, model, config);
    }
  }
  LearnerPrediction predict(const LearnerData& query) const override {
    LearnerPrediction pa = a_->predict(query), pb = b_->predict(query);
    LearnerPrediction p;
    p.mean = pa.mean + pb.mean;
    if (pa.var.size() && pb.var.size()) p.var = pa.var + pb.var;
    else if (pb.var.size()) p.var = pb.var;
    else if (pa.var.size()) p.var = pa.var;
    return p;
  }
  std::string notes() const override {
    std::string n;
    for (const Learner* l : {a_.get(), b_.get()}) {
      const std::string s = l->notes();
      if (!s.empty()) n += (n.empty() ? "" : "; ") + l->name() + ": " + s;
    }
    return n;
  }
  Eigen::VectorXd coefficients() const override { return a_->coefficients(); }

 private:
  static LearnerData without_y(const LearnerData& d) {
    LearnerData q = d;
    q.Y = nullptr;
    return q;
  }
  std::string name_;
  std::unique_ptr<Learner> a_, b_;
  bool iterative_;
};

}  // namespace

LearnerRegistry::LearnerRegistry() = default;
LearnerRegistry::~LearnerRegistry() = default;

std::vector<std::string> LearnerRegistry::default_search_path() {
  std::vector<std::string> path{SPML_BUILD_LEARNER_DIR};
  if (const char* env = std::getenv("SPML_LEARNER_PATH")) {
    std::stringstream ss(env);
    std::string dir;
    while (std::getline(ss, dir, ':'))
      if (!dir.empty()) path.push_back(dir);
  }
  return path;
}

void LearnerRegistry::add_default_path() {
  for (const auto& p : default_search_path())
    if (fs::exists(p) || p != SPML_BUILD_LEARNER_DIR) add(p);
}

void LearnerRegistry::add(const std::string& where) {
  std::vector<std::string> files;
  if (fs::is_directory(where)) {
    for (const auto& e : fs::directory_iterator(where))
      if (e.is_regular_file() && e.path().extension() == ".so") files.push_back(e.path().string());
    std::sort(files.begin(), files.end());
  } else if (fs::is_regular_file(where)) {
    files.push_back(where);
  } else {
    throw LearnerError("learner path '" + where + "': no such file or folder");
  }
  for (const auto& f : files) {
    const std::string canonical = fs::weakly_canonical(f).string();
    bool loaded = false;
    for (const auto& lib : libraries_) loaded |= lib->file() == canonical;
    if (loaded) continue;
    auto lib = std::make_shared<LearnerLibrary>(canonical);
    for (const spml_learner* l : lib->learners()) {
      auto it = plugins_.find(l->name);
      if (it != plugins_.end())
        throw LearnerError("learner '" + std::string(l->name) + "' is provided twice: by '" + it->second.second->file() +
                           "' and by '" + canonical + "'");
      plugins_[l->name] = {l, lib};
      order_.push_back(l->name);
    }
    libraries_.push_back(lib);
  }
}

std::vector<std::string> LearnerRegistry::plugin_names() const { return order_; }

const spml_learner* LearnerRegistry::plugin(const std::string& name) const {
  auto it = plugins_.find(name);
  return it == plugins_.end() ? nullptr : it->second.first;
}

std::string LearnerRegistry::plugin_file(const std::string& name) const {
  auto it = plugins_.find(name);
  return it == plugins_.end() ? "" : it->second.second->file();
}

bool LearnerRegistry::parse_composition(const std::string& name, std::string* a, std::string* b,
                                        bool* iterative) const {
  std::string rest = name;
  *iterative = rest.rfind("it-", 0) == 0;
  if (*iterative) rest = rest.substr(3);
  for (size_t pos = rest.find('-'); pos != std::string::npos; pos = rest.find('-', pos + 1)) {
    const std::string first = rest.substr(0, pos), second = rest.substr(pos + 1);
    if (plugin(first) && plugin(second)) {
      *a = first;
      *b = second;
      return true;
    }
  }
  return false;
}

std::vector<std::string> LearnerRegistry::expand(const std::string& list) const {
  std::vector<std::string> out;
  if (list == "all") {
    out = order_;
    for (const auto& a : order_)
      for (const auto& b : order_)
        if ((plugin(a)->flags & SPML_LEARNER_PARAMETRIC) && (plugin(b)->flags & SPML_LEARNER_NONPARAMETRIC))
          out.push_back(a + "-" + b);
    for (const auto& a : order_)
      for (const auto& b : order_)
        if ((plugin(a)->flags & SPML_LEARNER_PARAMETRIC) && (plugin(b)->flags & SPML_LEARNER_NONPARAMETRIC))
          out.push_back("it-" + a + "-" + b);
    return out;
  }
  std::stringstream ss(list);
  std::string name;
  while (std::getline(ss, name, ',')) {
    if (name.empty()) continue;
    std::string a, b;
    bool it = false;
    if (!plugin(name) && !parse_composition(name, &a, &b, &it)) {
      std::string known;
      for (const auto& n : order_) known += (known.empty() ? "" : ", ") + n;
      throw LearnerError("unknown learner '" + name + "' (known: " + known +
                         ", and compositions A-B / it-A-B of them)");
    }
    if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
  }
  if (out.empty()) throw LearnerError("no learner named in '" + list + "'");
  return out;
}

std::unique_ptr<Learner> LearnerRegistry::create(const std::string& name) const {
  auto it = plugins_.find(name);
  if (it != plugins_.end()) return std::make_unique<PluginLearner>(it->second.first, it->second.second);
  std::string a, b;
  bool iterative = false;
  if (!parse_composition(name, &a, &b, &iterative)) throw LearnerError("unknown learner '" + name + "'");
  return std::make_unique<SequentialLearner>(name, create(a), create(b), iterative);
}

std::set<std::string> LearnerRegistry::config_keys(const std::string& name) const {
  if (const spml_learner* l = plugin(name)) return key_set(l->config_keys);
  std::string a, b;
  bool iterative = false;
  if (!parse_composition(name, &a, &b, &iterative)) return {};
  std::set<std::string> keys = config_keys(a);
  for (const auto& k : config_keys(b)) keys.insert(k);
  if (iterative) keys.insert("iterations");
  return keys;
}

}  // namespace spml
