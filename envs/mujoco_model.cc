#include "spml/envs/mujoco_model.h"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

#ifndef SPML_SOURCE_MJCF_DIR
#define SPML_SOURCE_MJCF_DIR "mjcf"
#endif

namespace spml {

ModelPtr load_mjcf(const std::string& path) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path + ": no such MJCF file");
  char error[1000] = {0};
  mjModel* m = mj_loadXML(path.c_str(), nullptr, error, sizeof error);
  if (!m) throw std::runtime_error(path + ": MuJoCo cannot load the model: " + error);
  return ModelPtr(m);
}

std::string mjcf_dir() {
  if (const char* env = std::getenv("SPML_MJCF_DIR")) return env;
  return SPML_SOURCE_MJCF_DIR;
}

std::string mjcf_path(const std::string& file) { return (std::filesystem::path(mjcf_dir()) / file).string(); }

}  // namespace spml
