#include "spml/force_effects.h"


#include <cstdlib>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <map>
#include <mutex>
#include <set>
#include <sstream>


namespace spml {
namespace {

constexpr const char* kPrefix = "spml.plugin.";

std::string element_of(const std::string& name) { return "<custom><text name=\"" + name + "\">"; }

// ---- the process-wide passive callback, dispatching per model ----
// mjcb_passive runs in every step, so its look-up takes no lock: a fixed table of
// (model, effects) slots written under a mutex (attach/detach are rare) and read with atomics.
constexpr int kSlots = 256;
std::atomic<const mjModel*> g_models[kSlots];
std::atomic<const ForceEffects*> g_effects[kSlots];
std::mutex g_write_mutex;

void passive_dispatch(const mjModel* m, mjData* d) {
  for (int i = 0; i < kSlots; ++i)
    if (g_models[i].load(std::memory_order_acquire) == m) {
      if (const ForceEffects* fx = g_effects[i].load(std::memory_order_acquire)) fx->compute(d, d->qfrc_passive);
      return;
    }
}

std::string check_force_plugin(const void* entry) {
  return force_plugin_problem(*static_cast<const spml_force_plugin*>(entry));
}

}  // namespace

const PluginKind& force_plugin_kind() {
  static const PluginKind kind{"force plugin", "spml_force_plugin", SPML_FORCE_PLUGIN_ABI_VERSION, "SPML_PLUGIN_PATH",
                               "plugins"};
  return kind;
}

std::string force_plugin_problem(const spml_force_plugin& plugin) {
  const spml_force_plugin* p = &plugin;
  if (!p->create || !p->destroy || !p->compute || !p->nparam || !p->param_name || !p->get_params || !p->set_params)
    return "descriptor lacks a required callback (create, destroy, compute, nparam, param_name, get_params, set_params)";
  for (const spml_shape_param* sp = p->shape_params; sp && sp->key; ++sp) {
    const std::string k = sp->key;
    if (!find_config_key(p->config_keys, k)) return "shape parameter '" + k + "' is not one of its config keys";
    if (!(sp->lo < sp->hi) || !std::isfinite(sp->lo) || !std::isfinite(sp->hi) || (sp->log_scale && sp->lo <= 0) ||
        sp->domain < SPML_SHAPE_ABSOLUTE || sp->domain > SPML_SHAPE_SPEED)
      return "shape parameter '" + k + "' has an invalid search description (need finite lo < hi, lo > 0 on a log scale, a known domain)";
  }
  return "";
}

std::vector<std::pair<std::string, std::string>> parse_config_words(const std::string& text, const std::string& where) {
  std::vector<std::pair<std::string, std::string>> out;
  std::istringstream words(text);
  std::set<std::string> seen;
  for (std::string word; words >> word;) {
    const auto eq = word.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == word.size())
      throw PluginError(where + ": '" + word + "' is not of the form key=value");
    std::string key = word.substr(0, eq);
    if (!seen.insert(key).second) throw PluginError(where + ": key '" + key + "' given twice");
    out.emplace_back(std::move(key), word.substr(eq + 1));
  }
  return out;
}

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
    for (auto& [key, value] : parse_config_words(m->text_data + m->text_adr[i], where)) {
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

PluginCatalog& force_plugins() {
  static PluginCatalog catalog = [] {
    PluginCatalog c(force_plugin_kind(), &check_force_plugin);
    c.add_default_path();
    return c;
  }();
  return catalog;
}

std::vector<std::string> available_force_plugins() {
  std::vector<std::string> names = force_plugins().names();
  std::sort(names.begin(), names.end());
  return names;
}

uint32_t force_plugin_flags(const spml_force_plugin& plugin, int revision) { return revision >= 1 ? plugin.flags : 0u; }

uint32_t force_plugin_flags(const spml_force_plugin& plugin) {
  const PluginCatalog& catalog = force_plugins();
  if (catalog.find(plugin.name) != &plugin) return 0;
  return force_plugin_flags(plugin, catalog.revision_of(plugin.name));
}

const spml_force_plugin& load_force_plugin(const std::string& type, const std::string& element) {
  const PluginCatalog& catalog = force_plugins();
  if (const void* p = catalog.find(type)) return *static_cast<const spml_force_plugin*>(p);
  throw PluginError((element.empty() ? "" : element + ": ") + catalog.unknown(type));
}

namespace {

// Checks a configuration against the plugin's key table, fills in defaults and creates the
// instance; the one path for declarations and for instances made by tools.
void* create_checked(const spml_force_plugin& p, const mjModel* m, const std::vector<int>& joints,
                     const std::vector<std::pair<std::string, std::string>>& given, const std::string& where) {
  const std::string plugin = "plugin '" + std::string(p.name) + "'";
  for (auto& [k, v] : given) {
    const spml_config_key* key = find_config_key(p.config_keys, k);
    if (!key)
      throw PluginError(where + ": unknown key '" + k + "' for " + plugin + " (accepted: type, joints, " +
                        config_key_list(p.config_keys) + ")");
    if (std::string why = check_config_value(*key, v); !why.empty())
      throw PluginError(where + ": " + plugin + ": key '" + k + "': " + why);
  }
  for (const spml_config_key* key = p.config_keys; key && key->name; ++key) {
    bool present = false;
    for (auto& kv : given) present |= kv.first == key->name;
    if (!present && !key->default_value)
      throw PluginError(where + ": " + plugin + ": missing required key '" + key->name + "'");
  }
  const auto config = with_defaults(p.config_keys, given);
  std::vector<const char*> keys, values;
  for (auto& [k, v] : config) {
    keys.push_back(k.c_str());
    values.push_back(v.c_str());
  }
  char err[512] = {0};
  void* state = p.create(m, joints.data(), static_cast<int32_t>(joints.size()), keys.data(), values.data(),
                         static_cast<int32_t>(keys.size()), err, sizeof err);
  if (!state) throw PluginError(where + ": " + plugin + ": " + (err[0] ? err : "create failed"));
  return state;
}

}  // namespace

PluginInstance::PluginInstance(const spml_force_plugin& plugin, const mjModel* m, const std::vector<int>& joints,
                               const std::vector<std::pair<std::string, std::string>>& config, const std::string& where)
    : plugin_(&plugin), state_(create_checked(plugin, m, joints, config, where)) {}

PluginInstance::~PluginInstance() {
  if (state_) plugin_->destroy(state_);
}

std::vector<std::string> PluginInstance::param_names() const {
  std::vector<std::string> out;
  for (int i = 0; i < nparam(); ++i) out.push_back(plugin_->param_name(state_, i));
  return out;
}

Eigen::VectorXd PluginInstance::params() const {
  Eigen::VectorXd theta(nparam());
  plugin_->get_params(state_, theta.data());
  return theta;
}

void PluginInstance::set_params(const Eigen::VectorXd& theta) {
  if (theta.size() != nparam()) throw PluginError("set_params: expected " + std::to_string(nparam()) + " values");
  plugin_->set_params(state_, theta.data());
}

void PluginInstance::start_steady(const mjModel* m, const mjData* d) const {
  if (plugin_->reset) plugin_->reset(state_);
  if (plugin_->advance)
    for (int k = 0; k < kSteadyStartSteps; ++k) plugin_->advance(state_, m, d, kSteadyStart / kSteadyStartSteps);
}

std::string PluginInstance::config_text() const {
  if (!plugin_->write_config) return "";
  std::vector<char> buf(256);
  int32_t n = plugin_->write_config(state_, buf.data(), buf.size());
  if (n >= 0 && static_cast<size_t>(n) >= buf.size()) {
    buf.resize(static_cast<size_t>(n) + 1);
    n = plugin_->write_config(state_, buf.data(), buf.size());
  }
  return n < 0 ? "" : std::string(buf.data());
}

namespace {

std::vector<int> joint_ids(const mjModel* m, const std::vector<std::string>& names) {
  std::vector<int> out;
  for (const auto& j : names) out.push_back(mj_name2id(m, mjOBJ_JOINT, j.c_str()));
  return out;
}

}  // namespace

ForceEffects::ForceEffects(const mjModel* m, const std::string& source) : m_(m) {
  for (auto& decl : parse_plugin_declarations(m, source)) {
    const std::string where = source + ": " + decl.element;
    const spml_force_plugin& p = load_force_plugin(decl.type, where);
    PluginInstance object(p, m, joint_ids(m, decl.joints), decl.config, where);
    const int np = object.nparam();
    instances_.push_back({std::move(decl), std::move(object), nparam_, np});
    nparam_ += np;
  }
}

ForceEffects::~ForceEffects() { detach(); }

std::string ForceEffects::redeclared(size_t n, const std::function<void(Eigen::VectorXd&)>& set, const std::string& data) const {
  const Instance& in = instances_.at(n);
  std::vector<std::pair<std::string, std::string>> config = in.decl.config;
  if (!data.empty()) {
    config.clear();
    for (auto& kv : parse_config_words(data, in.decl.element))
      if (kv.first != "type" && kv.first != "joints") config.push_back(std::move(kv));
  }
  PluginInstance inst(in.plugin(), m_, joint_ids(m_, in.decl.joints), config, in.decl.element);
  Eigen::VectorXd theta = inst.params();
  set(theta);
  inst.set_params(theta);
  const std::string words = inst.config_text();
  if (words.empty()) return "";
  std::string joints;
  for (const auto& j : in.decl.joints) joints += (joints.empty() ? "" : ",") + j;
  return "type=" + in.decl.type + " joints=" + joints + " " + words;
}

void ForceEffects::attach() {
  std::lock_guard<std::mutex> lock(g_write_mutex);
  // Another library may own mjcb_passive; refuse rather than silently replace it.
  if (mjcb_passive && mjcb_passive != passive_dispatch)
    throw PluginError("mjcb_passive is already set by someone else; spml cannot dispatch force plugins");
  int free_slot = -1;
  for (int i = 0; i < kSlots; ++i) {
    if (g_models[i].load() == m_) {
      if (g_effects[i].load() != this) throw PluginError("another set of force plugins is already attached to this mjModel");
      attached_ = true;
      return;
    }
    if (free_slot < 0 && g_models[i].load() == nullptr) free_slot = i;
  }
  if (free_slot < 0) throw PluginError("more than " + std::to_string(kSlots) + " models with force plugins attached at once");
  g_effects[free_slot].store(this, std::memory_order_release);
  g_models[free_slot].store(m_, std::memory_order_release);
  mjcb_passive = passive_dispatch;
  attached_ = true;
}

void ForceEffects::detach() {
  if (!attached_) return;
  std::lock_guard<std::mutex> lock(g_write_mutex);
  bool any = false;
  for (int i = 0; i < kSlots; ++i) {
    if (g_models[i].load() == m_ && g_effects[i].load() == this) {
      g_models[i].store(nullptr, std::memory_order_release);
      g_effects[i].store(nullptr, std::memory_order_release);
    }
    any |= g_models[i].load() != nullptr;
  }
  if (!any && mjcb_passive == passive_dispatch) mjcb_passive = nullptr;
  attached_ = false;
}

void ForceEffects::compute(const mjData* d, mjtNum* qfrc) const {
  for (const auto& inst : instances_) inst.plugin().compute(inst.state(), m_, d, qfrc);
}

void ForceEffects::advance(const mjData* d, double dt) {
  for (auto& inst : instances_)
    if (inst.plugin().advance) inst.plugin().advance(inst.state(), m_, d, dt);
}

void ForceEffects::reset() {
  for (auto& inst : instances_)
    if (inst.plugin().reset) inst.plugin().reset(inst.state());
}

void ForceEffects::start_steady(const mjData* d) {
  for (auto& inst : instances_) inst.object.start_steady(m_, d);
}

std::vector<std::string> ForceEffects::param_names() const {
  std::vector<std::string> names;
  for (const auto& inst : instances_)
    for (int i = 0; i < inst.nparam; ++i) names.push_back(inst.decl.instance + "." + inst.plugin().param_name(inst.state(), i));
  return names;
}

Eigen::VectorXd ForceEffects::params() const {
  Eigen::VectorXd theta(nparam_);
  for (const auto& inst : instances_) inst.plugin().get_params(inst.state(), theta.data() + inst.param_offset);
  return theta;
}

void ForceEffects::set_params(const Eigen::VectorXd& theta) {
  if (theta.size() != nparam_) throw PluginError("set_params: expected " + std::to_string(nparam_) + " values");
  for (auto& inst : instances_) inst.plugin().set_params(inst.state(), theta.data() + inst.param_offset);
}

std::vector<std::string> ForceEffects::linear_names() const {
  std::vector<std::string> names;
  for (const auto& inst : instances_)
    if (inst.plugin().regressor)
      for (int i = 0; i < inst.nparam; ++i) names.push_back(inst.decl.instance + "." + inst.plugin().param_name(inst.state(), i));
  return names;
}

Eigen::VectorXd ForceEffects::linear_params() const {
  const Eigen::VectorXd all = params();
  std::vector<double> out;
  for (const auto& inst : instances_)
    if (inst.plugin().regressor)
      for (int i = 0; i < inst.nparam; ++i) out.push_back(all[inst.param_offset + i]);
  return Eigen::Map<Eigen::VectorXd>(out.data(), static_cast<Eigen::Index>(out.size()));
}

std::vector<std::string> ForceEffects::nonlinear_instances() const {
  std::vector<std::string> out;
  for (const auto& inst : instances_)
    if (!inst.plugin().regressor) out.push_back(inst.decl.instance + " (" + inst.decl.type + ")");
  return out;
}

Eigen::MatrixXd ForceEffects::linear_regressor(const mjtNum* qpos, const mjtNum* qvel) const {
  int cols = 0;
  for (const auto& inst : instances_)
    if (inst.plugin().regressor) cols += inst.nparam;
  Eigen::MatrixXd R = Eigen::MatrixXd::Zero(m_->nv, cols);
  int c = 0;
  std::vector<mjtNum> block;
  for (const auto& inst : instances_) {
    if (!inst.plugin().regressor) continue;
    block.assign(static_cast<size_t>(m_->nv) * inst.nparam, 0.0);
    inst.plugin().regressor(inst.state(), m_, qpos, qvel, block.data());
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
