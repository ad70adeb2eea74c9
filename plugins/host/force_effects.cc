#include "spml/force_effects.h"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#ifndef SPML_FORCE_PLUGIN_BUILD_DIR
#define SPML_FORCE_PLUGIN_BUILD_DIR ""
#endif
#ifndef SPML_FORCE_PLUGIN_INSTALL_DIR
#define SPML_FORCE_PLUGIN_INSTALL_DIR ""
#endif

namespace spml {
namespace {

namespace fs = std::filesystem;
constexpr const char* kPrefix = "spml.plugin.";

std::string element_of(const std::string& name) { return "<custom><text name=\"" + name + "\">"; }

// ---- the process-wide passive callback, dispatching per model ----
std::mutex g_registry_mutex;
std::map<const mjModel*, const ForceEffects*> g_registry;

void passive_dispatch(const mjModel* m, mjData* d) {
  const ForceEffects* fx = nullptr;
  {
    std::lock_guard<std::mutex> lock(g_registry_mutex);
    auto it = g_registry.find(m);
    if (it != g_registry.end()) fx = it->second;
  }
  if (fx) fx->compute(d, d->qfrc_passive);
}

}  // namespace

std::vector<PluginDeclaration> parse_plugin_declarations(const mjModel* m, const std::string& source) {
  std::vector<PluginDeclaration> out;
  for (int i = 0; i < m->ntext; ++i) {
    std::string name = m->names + m->name_textadr[i];
    if (name.rfind(kPrefix, 0) != 0) continue;
    PluginDeclaration decl;
    decl.element = element_of(name);
    decl.instance = name.substr(std::string(kPrefix).size());
    const std::string where = source + ": " + decl.element;
    if (decl.instance.empty()) throw PluginError(where + ": the instance name after 'spml.plugin.' is empty");
    std::istringstream words(std::string(m->text_data + m->text_adr[i]));
    std::string word;
    std::set<std::string> seen;
    while (words >> word) {
      auto eq = word.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == word.size())
        throw PluginError(where + ": '" + word + "' is not of the form key=value");
      std::string key = word.substr(0, eq), value = word.substr(eq + 1);
      if (!seen.insert(key).second) throw PluginError(where + ": key '" + key + "' given twice");
      if (key == "type")
        decl.type = value;
      else if (key == "joints") {
        std::stringstream js(value);
        std::string j;
        while (std::getline(js, j, ',')) decl.joints.push_back(j);
      } else
        decl.config.emplace_back(key, value);
    }
    if (decl.type.empty()) throw PluginError(where + ": missing 'type=<plugin>'");
    if (decl.joints.empty()) throw PluginError(where + ": missing 'joints=<joint>[,<joint>...]'");
    for (const auto& j : decl.joints)
      if (mj_name2id(m, mjOBJ_JOINT, j.c_str()) < 0)
        throw PluginError(where + ": joint '" + j + "' does not exist in the model");
    out.push_back(std::move(decl));
  }
  return out;
}

std::vector<std::string> plugin_search_path() {
  std::vector<std::string> dirs;
  if (const char* env = std::getenv("SPML_PLUGIN_PATH")) {
    std::stringstream ss(env);
    std::string d;
    while (std::getline(ss, d, ':'))
      if (!d.empty()) dirs.push_back(d);
  }
  for (const char* d : {SPML_FORCE_PLUGIN_BUILD_DIR, SPML_FORCE_PLUGIN_INSTALL_DIR})
    if (*d) dirs.push_back(d);
  return dirs;
}

std::vector<std::string> available_force_plugins() {
  std::set<std::string> names;
  for (const auto& dir : plugin_search_path()) {
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      std::string f = entry.path().filename().string();
      if (f.rfind("spml_force_", 0) == 0 && entry.path().extension() == ".so")
        names.insert(f.substr(11, f.size() - 11 - 3));
    }
  }
  return {names.begin(), names.end()};
}

const spmlForcePlugin& load_force_plugin(const std::string& type, const std::string& element) {
  static std::mutex mutex;
  static std::map<std::string, const spmlForcePlugin*> cache;
  std::lock_guard<std::mutex> lock(mutex);
  if (auto it = cache.find(type); it != cache.end()) return *it->second;
  const std::string where = element.empty() ? "" : element + ": ";
  for (const auto& dir : plugin_search_path()) {
    fs::path file = fs::path(dir) / ("spml_force_" + type + ".so");
    if (!fs::exists(file)) continue;
    void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) throw PluginError(where + file.string() + ": cannot be loaded: " + dlerror());
    auto entry = reinterpret_cast<spmlForcePluginEntry>(dlsym(handle, SPML_FORCE_PLUGIN_ENTRY));
    if (!entry) throw PluginError(where + file.string() + ": missing symbol '" + SPML_FORCE_PLUGIN_ENTRY + "'");
    const spmlForcePlugin* p = entry();
    if (!p || p->abi_version != SPML_FORCE_PLUGIN_ABI)
      throw PluginError(where + file.string() + ": force-plugin ABI version " + std::to_string(p ? p->abi_version : -1) +
                        ", this spml speaks version " + std::to_string(SPML_FORCE_PLUGIN_ABI));
    if (!p->create || !p->destroy || !p->compute || !p->nparam || !p->param_name || !p->get_params || !p->set_params)
      throw PluginError(where + file.string() + ": descriptor lacks a required callback");
    cache[type] = p;
    return *p;
  }
  std::string known;
  for (const auto& n : available_force_plugins()) known += (known.empty() ? "" : ", ") + n;
  throw PluginError(where + "unknown plugin '" + type + "' (available: " + (known.empty() ? "none found" : known) +
                    "; search path: $SPML_PLUGIN_PATH, " + SPML_FORCE_PLUGIN_BUILD_DIR + ")");
}

ForceEffects::ForceEffects(const mjModel* m, const std::string& source) : m_(m) {
  for (auto& decl : parse_plugin_declarations(m, source)) {
    const std::string where = source + ": " + decl.element;
    const spmlForcePlugin& p = load_force_plugin(decl.type, where);
    std::set<std::string> accepted;
    for (const char* const* k = p.keys; k && *k; ++k) accepted.insert(*k);
    std::vector<const char*> keys, values;
    for (auto& [k, v] : decl.config) {
      if (!accepted.count(k)) {
        std::string list;
        for (auto& a : accepted) list += (list.empty() ? "" : ", ") + a;
        throw PluginError(where + ": unknown key '" + k + "' for plugin '" + decl.type + "' (accepted: type, joints, " + list + ")");
      }
      keys.push_back(k.c_str());
      values.push_back(v.c_str());
    }
    std::vector<int> joints;
    for (auto& j : decl.joints) joints.push_back(mj_name2id(m, mjOBJ_JOINT, j.c_str()));
    char err[512] = {0};
    void* state = p.create(m, joints.data(), static_cast<int>(joints.size()), keys.data(), values.data(),
                           static_cast<int>(keys.size()), err, sizeof err);
    if (!state) throw PluginError(where + ": plugin '" + decl.type + "': " + err);
    int np = p.nparam(state);
    instances_.push_back({std::move(decl), &p, state, nparam_, np});
    nparam_ += np;
  }
}

ForceEffects::~ForceEffects() {
  detach();
  for (auto& inst : instances_) inst.plugin->destroy(inst.state);
}

void ForceEffects::attach() {
  std::lock_guard<std::mutex> lock(g_registry_mutex);
  auto it = g_registry.find(m_);
  if (it != g_registry.end() && it->second != this)
    throw PluginError("another set of force plugins is already attached to this mjModel");
  g_registry[m_] = this;
  // Another library may own mjcb_passive; refuse rather than silently replace it.
  if (mjcb_passive && mjcb_passive != passive_dispatch)
    throw PluginError("mjcb_passive is already set by someone else; spml cannot dispatch force plugins");
  mjcb_passive = passive_dispatch;
  attached_ = true;
}

void ForceEffects::detach() {
  if (!attached_) return;
  std::lock_guard<std::mutex> lock(g_registry_mutex);
  g_registry.erase(m_);
  if (g_registry.empty() && mjcb_passive == passive_dispatch) mjcb_passive = nullptr;
  attached_ = false;
}

void ForceEffects::compute(const mjData* d, mjtNum* qfrc) const {
  for (const auto& inst : instances_) inst.plugin->compute(inst.state, m_, d, qfrc);
}

void ForceEffects::advance(const mjData* d, double dt) {
  for (auto& inst : instances_)
    if (inst.plugin->advance) inst.plugin->advance(inst.state, m_, d, dt);
}

void ForceEffects::reset() {
  for (auto& inst : instances_)
    if (inst.plugin->reset) inst.plugin->reset(inst.state);
}

std::vector<std::string> ForceEffects::param_names() const {
  std::vector<std::string> names;
  for (const auto& inst : instances_)
    for (int i = 0; i < inst.nparam; ++i) names.push_back(inst.decl.instance + "." + inst.plugin->param_name(inst.state, i));
  return names;
}

Eigen::VectorXd ForceEffects::params() const {
  Eigen::VectorXd theta(nparam_);
  for (const auto& inst : instances_) inst.plugin->get_params(inst.state, theta.data() + inst.param_offset);
  return theta;
}

void ForceEffects::set_params(const Eigen::VectorXd& theta) {
  if (theta.size() != nparam_) throw PluginError("set_params: expected " + std::to_string(nparam_) + " values");
  for (auto& inst : instances_) inst.plugin->set_params(inst.state, theta.data() + inst.param_offset);
}

std::vector<std::string> ForceEffects::linear_names() const {
  std::vector<std::string> names;
  for (const auto& inst : instances_)
    if (inst.plugin->regressor)
      for (int i = 0; i < inst.nparam; ++i) names.push_back(inst.decl.instance + "." + inst.plugin->param_name(inst.state, i));
  return names;
}

Eigen::VectorXd ForceEffects::linear_params() const {
  const Eigen::VectorXd all = params();
  std::vector<double> out;
  for (const auto& inst : instances_)
    if (inst.plugin->regressor)
      for (int i = 0; i < inst.nparam; ++i) out.push_back(all[inst.param_offset + i]);
  return Eigen::Map<Eigen::VectorXd>(out.data(), static_cast<Eigen::Index>(out.size()));
}

std::vector<std::string> ForceEffects::nonlinear_instances() const {
  std::vector<std::string> out;
  for (const auto& inst : instances_)
    if (!inst.plugin->regressor) out.push_back(inst.decl.instance + " (" + inst.decl.type + ")");
  return out;
}

Eigen::MatrixXd ForceEffects::linear_regressor(const mjtNum* qpos, const mjtNum* qvel) const {
  int cols = 0;
  for (const auto& inst : instances_)
    if (inst.plugin->regressor) cols += inst.nparam;
  Eigen::MatrixXd R = Eigen::MatrixXd::Zero(m_->nv, cols);
  int c = 0;
  std::vector<mjtNum> block;
  for (const auto& inst : instances_) {
    if (!inst.plugin->regressor) continue;
    block.assign(static_cast<size_t>(m_->nv) * inst.nparam, 0.0);
    inst.plugin->regressor(inst.state, m_, qpos, qvel, block.data());
    for (int r = 0; r < m_->nv; ++r)
      for (int k = 0; k < inst.nparam; ++k) R(r, c + k) = block[static_cast<size_t>(r) * inst.nparam + k];
    c += inst.nparam;
  }
  return R;
}

void step(const mjModel* m, mjData* d, ForceEffects& effects) {
  mj_step(m, d);
  effects.advance(d, m->opt.timestep);
}

}  // namespace spml
