// Owning handles for MuJoCo models/data, loading with errors that name the file.
#pragma once

#include <mujoco/mujoco.h>

#include <memory>
#include <string>

#include "spml/force_effects.h"

namespace spml {

struct ModelDeleter { void operator()(mjModel* m) const { mj_deleteModel(m); } };
struct DataDeleter { void operator()(mjData* d) const { mj_deleteData(d); } };
using ModelPtr = std::unique_ptr<mjModel, ModelDeleter>;
using DataPtr = std::unique_ptr<mjData, DataDeleter>;

// Loads an MJCF file; throws std::runtime_error with MuJoCo's message and the path.
ModelPtr load_mjcf(const std::string& path);
inline DataPtr make_data(const mjModel* m) { return DataPtr(mj_makeData(m)); }

// A model loaded for open simulation along measured data (rollouts, IV instruments): contacts
// off (inverse dynamics has none either), its force plugins attached, one mjData.
struct Simulation {
  ModelPtr model;
  std::unique_ptr<ForceEffects> effects;   // destroyed before the model it points to
  DataPtr data;
  mjModel* m() const { return model.get(); }
  mjData* d() const { return data.get(); }
};
Simulation open_simulation(const std::string& mjcf_path);

// Joint j as messages name it: "joint 0 (free, unnamed, in body 'base')", "joint 2 (slide,
// 'j1', in body #3)": its type, its name if any and its body.
std::string joint_description(const mjModel* m, int j);

// Directory holding the project's MJCF models: $SPML_MJCF_DIR, else <share>/spml/mjcf.
std::string mjcf_dir();
std::string mjcf_path(const std::string& file);   // mjcf_dir()/file

}  // namespace spml
