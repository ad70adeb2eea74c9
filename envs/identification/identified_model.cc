#include "spml/envs/identified_model.h"

#include <mujoco/mujoco.h>

#include <map>

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
  // Declared plugins: "plugin:<instance>.<parameter>" -> (instance, parameter index, value).
  const auto& insts = reg.effects().instances();
  std::map<size_t, std::vector<std::pair<Eigen::Index, double>>> fitted;
  auto plugin_parameter = [&](const std::string& name, double value) {
    for (size_t n = 0; n < insts.size(); ++n) {
      const auto pnames = insts[n].object.param_names();
      for (size_t k = 0; k < pnames.size(); ++k)
        if (name == insts[n].decl.instance + "." + pnames[k]) {
          fitted[n].emplace_back(static_cast<Eigen::Index>(k), value);
          return true;
        }
    }
    return false;
  };
  for (const auto& t : id.terms) {
    if (!t.fitted) continue;
    const auto colon = t.name.find(':');
    const std::string kind = t.name.substr(0, colon), what = t.name.substr(colon + 1);
    const auto attr = joint_attribute_term(t.name);
    if (attr && mj_name2id(reg.model(), mjOBJ_JOINT, attr->joint.c_str()) >= 0)
      edits.joint_attributes[attr->joint][attr->attribute] = t.value;
    else if (t.value != t.prior && !(kind == "plugin" && plugin_parameter(what, t.value)))
      notes.push_back(t.name + " = " + std::to_string(t.value) + " (model: " + std::to_string(t.prior) +
                      ") has no MJCF attribute written here: edit it by hand");
  }
  for (const auto& [n, values] : fitted) {
    const auto& d = insts[n].decl;
    std::string data;
    try {
      data = reg.effects().redeclared(n, [&](Eigen::VectorXd& theta) {
        for (const auto& [k, v] : values) theta[k] = v;
      });
    } catch (const PluginError& e) {
      notes.push_back(d.element + ": its identified parameters are refused by the plugin (" + e.what() + "): edit it by hand");
      continue;
    }
    if (data.empty()) {
      notes.push_back(d.element + ": the plugin cannot write its configuration: its identified parameters are not written, edit it by hand");
      continue;
    }
    edits.replaced_texts["spml.plugin." + d.instance] = data;
  }
  return edits;
}

}  // namespace spml
