#include "spml/envs/identified_model.h"

#include <mujoco/mujoco.h>

namespace spml {

MjcfEdits identified_model_edits(const MjcfRegressor& reg, const ConsistentIdentification& id, std::vector<std::string>& notes) {
  MjcfEdits edits;
  for (const auto& b : id.bodies) {
    if (!b.fitted) continue;
    // The MJCF editor finds bodies by name; an unnamed one cannot be written.
    if (!mj_id2name(reg.model(), mjOBJ_BODY, b.body_id)) {
      notes.push_back("body " + std::to_string(b.body_id) + " has no name in the MJCF: its identified inertial (mass " +
                      std::to_string(b.identified.mass) + ") is not written; name the body to have it written");
      continue;
    }
    MjcfEdits::Inertial in;
    in.body = b.name;
    in.mass = b.identified.mass;
    in.pos = b.identified.com;
    in.fullinertia = b.identified.fullinertia();
    edits.inertials.push_back(in);
  }
  for (const auto& t : id.terms) {
    if (!t.fitted) continue;
    const auto colon = t.name.find(':');
    const std::string kind = t.name.substr(0, colon), what = t.name.substr(colon + 1);
    const bool joint_attr = kind == "armature" || kind == "damping" || kind == "coulomb" || kind == "stiffness";
    if (joint_attr && mj_name2id(reg.model(), mjOBJ_JOINT, what.c_str()) >= 0)
      edits.joint_attributes[what][kind == "coulomb" ? "frictionloss" : kind] = t.value;
    else if (t.value != t.prior)
      notes.push_back(t.name + " = " + std::to_string(t.value) + " (model: " + std::to_string(t.prior) +
                      ") has no MJCF attribute written here: edit it by hand");
  }
  return edits;
}

}  // namespace spml
