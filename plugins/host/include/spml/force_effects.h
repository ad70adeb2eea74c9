// Loading and running force plugins declared in an MJCF model.
//
// Declaration (MuJoCo 2.2.2 has no <extension>/<plugin> element, so spml uses custom text):
//   <custom>
//     <text name="spml.plugin.band" data="type=friction_band joints=shoulder lower=0.15 upper=0.25 level=60"/>
//   </custom>
// Every <text> whose name starts with "spml.plugin." declares one instance (the rest of the
// name is the instance name). `type` picks the plugin, `joints` lists the MJCF joints it acts
// on (comma-separated), every other key=value goes to the plugin. Unknown plugins, unknown
// keys, bad values and missing joints are errors naming the element.
#pragma once

#include <mujoco/mujoco.h>

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "spml/force_plugin.h"
#include "spml/plugin_loader.h"

namespace spml {

struct PluginDeclaration {
  std::string element;    // e.g. <custom><text name="spml.plugin.band">
  std::string instance;   // "band"
  std::string type;       // "friction_band"
  std::vector<std::string> joints;
  std::vector<std::pair<std::string, std::string>> config;   // everything but type/joints
};

// Splits "key=value key=value" (a declaration's data, a write_config text) into pairs;
// throws PluginError prefixed with `where` for a word without '=' or a key given twice.
std::vector<std::pair<std::string, std::string>> parse_config_words(const std::string& text, const std::string& where);

// Parses the declarations of a compiled model; `source` (the MJCF path) prefixes messages.
std::vector<PluginDeclaration> parse_plugin_declarations(const mjModel* m, const std::string& source);

// The force plugins of this process: the shipped ones, then $SPML_PLUGIN_PATH (see
// spml/plugin_loader.h for the search order). Created on first use; a command line may
// add folders (--plugin-path) before any model is loaded.
PluginCatalog& force_plugins();
// The plugin called `type`; throws PluginError naming `element` and what is available.
const spml_force_plugin& load_force_plugin(const std::string& type, const std::string& element = "");
// Names of all plugins found.
std::vector<std::string> available_force_plugins();
// A plugin's SPML_FORCE_* flags: its `flags` member where its library declares revision >= 1
// (the member exists only there), else 0. The first form looks the library up in
// force_plugins() (0 for a descriptor not found there).
uint32_t force_plugin_flags(const spml_force_plugin& plugin, int revision);
uint32_t force_plugin_flags(const spml_force_plugin& plugin);
// Whether two instances may run on two threads at once: SPML_FORCE_INDEPENDENT among the above.
inline bool force_plugin_independent(const spml_force_plugin& plugin) { return (force_plugin_flags(plugin) & SPML_FORCE_INDEPENDENT) != 0; }
// How force-plugin libraries are recognised (symbol prefix, ABI version, search folders).
const PluginKind& force_plugin_kind();
// "" for a descriptor the host can use, else what is wrong with it (required callbacks
// missing, a shape parameter that is not a config key or has an invalid search range).
std::string force_plugin_problem(const spml_force_plugin& plugin);

// How long PluginInstance::start_steady holds a state: 1 s. LuGre's bristles settle at the rate
// sigma0 |v| / g(v), within a few of their pre-sliding deflections of travel: in milliseconds at
// the speeds of a motion, while near rest (a few mrad/s) they only part settle - where the log
// cannot say the state either. In this many advances (a plugin may integrate explicitly).
inline constexpr double kSteadyStart = 1;
inline constexpr int kSteadyStartSteps = 200;

// One instance of a plugin made outside a model's declarations (diagnose's candidates): the
// configuration is checked against the plugin's key table and completed with its defaults
// exactly as for a declaration; `where` prefixes messages. Throws PluginError.
class PluginInstance {
 public:
  PluginInstance(const spml_force_plugin& plugin, const mjModel* m, const std::vector<int>& joints,
                 const std::vector<std::pair<std::string, std::string>>& config, const std::string& where);
  ~PluginInstance();
  PluginInstance(PluginInstance&& o) noexcept : plugin_(o.plugin_), state_(o.state_) { o.state_ = nullptr; }
  PluginInstance(const PluginInstance&) = delete;
  PluginInstance& operator=(const PluginInstance&) = delete;
  PluginInstance& operator=(PluginInstance&&) = delete;

  const spml_force_plugin& plugin() const { return *plugin_; }
  void* state() const { return state_; }
  int nparam() const { return plugin_->nparam(state_); }
  std::vector<std::string> param_names() const;
  Eigen::VectorXd params() const;
  void set_params(const Eigen::VectorXd& theta);
  // The key=value words that recreate it (write_config); empty when the plugin cannot.
  std::string config_text() const;
  // Reset, then advanced for kSteadyStart seconds with the state in d held: the internal state
  // at a measured row, where the log does not hold it (a state the motion drives and that
  // forgets, as LuGre's bristles; one that integrates displacement starts offset).
  void start_steady(const mjModel* m, const mjData* d) const;

 private:
  const spml_force_plugin* plugin_;
  void* state_;
};

// The plugin instances of one model. While attached, MuJoCo's passive-force callback adds
// their forces for this model (and only this model) in every mj_step/mj_forward/mj_inverse.
class ForceEffects {
 public:
  ForceEffects(const mjModel* m, const std::string& source);
  ~ForceEffects();
  ForceEffects(const ForceEffects&) = delete;
  ForceEffects& operator=(const ForceEffects&) = delete;

  // One declared instance; owns its plugin state (released when the effects are, or when a
  // later declaration fails to create).
  struct Instance {
    PluginDeclaration decl;
    PluginInstance object;
    int param_offset, nparam;
    const spml_force_plugin& plugin() const { return object.plugin(); }
    void* state() const { return object.state(); }
  };

  const std::vector<Instance>& instances() const { return instances_; }
  bool empty() const { return instances_.empty(); }

  void attach();   // start contributing through mjcb_passive
  void detach();   // stop; also done by the destructor
  bool attached() const { return attached_; }

  // Adds all instances' forces into qfrc (nv) for the state in d.
  void compute(const mjData* d, mjtNum* qfrc) const;
  // Steps internal states; call after every integrator step.
  void advance(const mjData* d, double dt);
  void reset();
  void start_steady(const mjData* d);   // PluginInstance::start_steady for every instance

  // Parameter vector of all instances, names "<instance>.<plugin parameter>".
  int nparam() const { return nparam_; }
  std::vector<std::string> param_names() const;
  Eigen::VectorXd params() const;
  void set_params(const Eigen::VectorXd& theta);

  // Regressor of the instances that are linear: force = R * theta_linear with R of size
  // nv x (sum of their nparam); `linear_names` lists the columns. Nonlinear instances are
  // skipped (listed by nonlinear_instances()).
  Eigen::MatrixXd linear_regressor(const mjtNum* qpos, const mjtNum* qvel) const;
  std::vector<std::string> linear_names() const;
  Eigen::VectorXd linear_params() const;   // values of the linear_names() parameters
  std::vector<std::string> nonlinear_instances() const;

  const mjModel* model() const { return m_; }

  // Instance n's declaration written again, its parameters changed by `set` (called with the
  // values the instance made from its configuration holds: its declared words, or those of
  // `data`, another <text> data of it, when given): the new <text> data, "type=T joints=a,b
  // key=value ...", or "" when the plugin cannot write its configuration. Throws PluginError
  // when the plugin refuses the parameters.
  std::string redeclared(size_t n, const std::function<void(Eigen::VectorXd&)>& set, const std::string& data = "") const;

 private:
  const mjModel* m_;
  std::vector<Instance> instances_;
  int nparam_ = 0;
  bool attached_ = false;
};

// mj_step followed by advancing the plugin states.
void step(const mjModel* m, mjData* d, ForceEffects& effects);

}  // namespace spml
