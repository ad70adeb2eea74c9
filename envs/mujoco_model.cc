#include "spml/envs/mujoco_model.h"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

#include "spml/plugin_loader.h"


namespace spml {

ModelPtr load_mjcf(const std::string& path) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path + ": no such MJCF file");
  char error[1000] = {0};
  mjModel* m = mj_loadXML(path.c_str(), nullptr, error, sizeof error);
  if (!m) throw std::runtime_error(path + ": MuJoCo cannot load the model: " + error);
  return ModelPtr(m);
}

Simulation open_simulation(const std::string& mjcf_path) {
  Simulation sim;
  sim.model = load_mjcf(mjcf_path);
  sim.model->opt.disableflags |= mjDSBL_CONTACT;
  sim.effects = std::make_unique<ForceEffects>(sim.model.get(), mjcf_path);
  if (!sim.effects->empty()) sim.effects->attach();
  sim.data = make_data(sim.model.get());
  return sim;
}

std::string joint_description(const mjModel* m, int j) {
  static const char* kType[4] = {"free", "ball", "slide", "hinge"};
  const int type = m->jnt_type[j];
  const char* name = mj_id2name(m, mjOBJ_JOINT, j);
  const char* body = mj_id2name(m, mjOBJ_BODY, m->jnt_bodyid[j]);
  return "joint " + std::to_string(j) + " (" + (type >= 0 && type < 4 ? kType[type] : "unknown") +
         (name && *name ? ", '" + std::string(name) + "'" : std::string(", unnamed")) + ", in body " +
         (body ? "'" + std::string(body) + "'" : "#" + std::to_string(m->jnt_bodyid[j])) + ")";
}

std::string mjcf_dir() {
  if (const char* env = std::getenv("SPML_MJCF_DIR"); env && *env) return env;
  return (std::filesystem::path(spml_share_dir()) / "mjcf").string();
}

std::string mjcf_path(const std::string& file) { return (std::filesystem::path(mjcf_dir()) / file).string(); }

}  // namespace spml
