// Stage 6 (with verify.cc), the written form of the named effects: where MuJoCo has the physics
// itself, extended.xml states it in MuJoCo's own terms, so that plain MuJoCo simulates it. A
// `spring` is the joint's `stiffness` and `springref` (MuJoCo 2.2.2's passive force on a hinge or
// slide joint is -stiffness*(qpos - springref), springref in degrees for a hinge under the default
// <compiler angle="degree">), `viscous` friction the joint's `damping`. Everything upstream (the
// choice, the rejection in simulation, the refits, the held-out guard) works on the effects'
// plugin declarations; they are turned into joint attributes only here, as the file is written,
// on top of whatever the edits already write on that joint (the `parameters` cause's damping or
// stiffness) or else the MJCF's own values.
#include <algorithm>
#include <cmath>

#include "diagnosis.h"
#include "spml/matrix_file.h"   // write_text_atomic
#include "spml/parse.h"

namespace spml::diagnose_detail {

WrittenForm mujoco_form(const mjModel* m, bool degrees, const std::vector<std::string>& defined, const MjcfEdits& edits,
                        const std::set<std::string>& frictionloss_joints) {
  WrittenForm w;
  w.edits = edits;
  w.edits.texts.clear();
  for (const auto& text : edits.texts) {
    const auto& [name, data] = text;
    std::string type, joint;
    std::map<std::string, double> value;
    if (name.rfind(kDiagnosedPrefix, 0) == 0)   // a declaration diagnose wrote (one joint)
      for (const auto& [key, v] : parse_config_words(data, name)) {
        if (key == "type") type = v;
        else if (key == "joints") joint = v;
        else if (const auto number = parse_number(v)) value[key] = *number;
      }
    const int j = joint.empty() ? -1 : mj_name2id(m, mjOBJ_JOINT, joint.c_str());
    bool hinge_or_slide = j >= 0 && (m->jnt_type[j] == mjJNT_HINGE || m->jnt_type[j] == mjJNT_SLIDE);
    const bool coulomb = type == "coulomb" && frictionloss_joints.count(joint) && value.count("fc") && (!value.count("smooth") || value.at("smooth") == 0);
    if (hinge_or_slide && (type == "viscous" || type == "spring" || coulomb) && std::find(defined.begin(), defined.end(), joint) == defined.end()) {
      w.kept_why[data] = "joint '" + joint + "' is not defined in the model file itself (an included file?), so its attributes cannot be "
                         "written: written as the plugin declaration";
      hinge_or_slide = false;
    }
    auto attributes = w.edits.joint_attributes.find(joint);
    auto current = [&](const std::string& attr, double model_value) {
      if (attributes != w.edits.joint_attributes.end())
        if (const auto a = attributes->second.find(attr); a != attributes->second.end()) return a->second;
      return model_value;
    };
    if (hinge_or_slide && type == "viscous" && value.count("fv")) {
      const double d0 = current("damping", m->dof_damping[m->jnt_dofadr[j]]), total = d0 + value["fv"];
      if (total >= 0) {
        w.edits.joint_attributes[joint]["damping"] = total;
        w.as_mjcf[data] = {{"joint", joint}, {"damping", total}, {"damping_before", d0}};
        continue;
      }
      w.kept_why[data] = "the joint's damping " + fmt(d0) + " + fv " + fmt(value["fv"]) + " = " + fmt(total) +
                         " < 0, which MuJoCo's damping cannot be: written as the plugin declaration";
    }
    if (hinge_or_slide && coulomb) {
      const double f0 = current("frictionloss", m->dof_frictionloss[m->jnt_dofadr[j]]), total = f0 + value["fc"];
      if (total >= 0) {
        w.edits.joint_attributes[joint]["frictionloss"] = total;
        w.as_mjcf[data] = {{"joint", joint}, {"frictionloss", total}, {"frictionloss_before", f0}};
        continue;
      }
      w.kept_why[data] = "the joint's frictionloss " + fmt(f0) + " + fc " + fmt(value["fc"]) + " = " + fmt(total) +
                         " < 0, which MuJoCo's frictionloss cannot be: written as the plugin declaration";
    }
    if (hinge_or_slide && type == "spring" && value.count("k") && value.count("f0")) {
      const bool hinge = m->jnt_type[j] == mjJNT_HINGE;
      const double unit = hinge && degrees ? 180 / M_PI : 1.0;   // file units per model unit (rad or m)
      const double k0 = current("stiffness", m->jnt_stiffness[j]);
      const double r0 = current("springref", m->qpos_spring[m->jnt_qposadr[j]] * unit) / unit;
      const double k = k0 + value["k"];
      if (k > 0) {
        const double r = (k0 * r0 + value["f0"]) / k;
        w.edits.joint_attributes[joint]["stiffness"] = k;
        w.edits.joint_attributes[joint]["springref"] = r * unit;
        w.as_mjcf[data] = {{"joint", joint}, {"stiffness", k}, {"springref", r}, {"stiffness_before", k0}, {"springref_before", r0},
                           {"springref_unit", hinge ? "rad" : "m"}, {"springref_in_file", r * unit}};
        continue;
      }
      w.kept_why[data] = "the joint's stiffness " + fmt(k0) + " + k " + fmt(value["k"]) + " = " + fmt(k) +
                         " is not positive, which MuJoCo's stiffness cannot be: written as the plugin declaration";
    }
    w.edits.texts.push_back(text);
  }
  return w;
}

WrittenForm Diagnosis::written_form(const MjcfEdits& edits) const {
  if (!degrees_) degrees_ = mjcf_angles_in_degrees(opt_.model);
  if (!defined_joints_) defined_joints_ = mjcf_defined_joints(opt_.model);
  return mujoco_form(reg_->model(), *degrees_, *defined_joints_, edits, frictionloss_joints_);
}

std::string Diagnosis::write_model(const MjcfEdits& edits, std::vector<std::string>& notes, const MjcfEdits* takers) const {
  return edit_mjcf(opt_.model, written_form(with_take_over(edits, takers)).edits, notes);
}

// report.json: per written effect how extended.xml holds it, and the notes on what plain MuJoCo
// simulates and what it ignores. Returns the names of the plugin texts left (needs_spml_plugins).
nlohmann::json Diagnosis::report_written_form(const MjcfEdits& edits, std::vector<std::string>& notes) {
  nlohmann::json& causes = result_.report["causes"];
  const WrittenForm w = written_form(edits);
  std::vector<std::string> native, ignored;
  for (auto& c : causes) {
    // What a friction takes over is said only where extended.xml writes it (own_friction.cc).
    if (!kept_cause(c)) c.erase("replaces_model_friction");
    if (!c.contains("declaration") || !kept_cause(c)) continue;
    const std::string data = c["declaration"].get<std::string>();
    const std::string what = c["effect"].get<std::string>() + "@" + c["joints"][0].get<std::string>();
    if (c.contains("replaces_model_friction"))
      notes.push_back(what + " replaces the model's own friction level on its joint (" + c["replaces_model_friction"].dump() +
                      "): extended.xml states that level as 0");
    if (const auto it = w.as_mjcf.find(data); it != w.as_mjcf.end()) {
      c["written_as"] = "mjcf";
      c["mjcf"] = it->second;
      native.push_back(what + " (" + (it->second.contains("damping") ? "damping" : it->second.contains("frictionloss") ? "frictionloss" : "stiffness, springref") + ")");
      continue;
    }
    bool declared = false;
    for (const auto& t : w.edits.texts) declared |= t.second == data;
    if (!declared) continue;   // not in the file (a joint name a declaration cannot hold)
    c["written_as"] = "plugin";
    if (const auto why = w.kept_why.find(data); why != w.kept_why.end()) {
      c["written_as_why"] = why->second;
      notes.push_back(what + ": " + why->second);
    }
    ignored.push_back(what);
  }
  if (!native.empty()) {
    std::string list;
    for (const auto& n : native) list += (list.empty() ? "" : ", ") + n;
    notes.push_back("written as MuJoCo's own joint attributes (causes[].written_as \"mjcf\"), which plain MuJoCo simulates: " + list);
  }
  nlohmann::json names = nlohmann::json::array();
  for (const auto& [name, data] : w.edits.texts) names.push_back(name);
  if (!names.empty()) {
    std::string list;
    for (const auto& n : ignored) list += (list.empty() ? "" : ", ") + n;
    notes.push_back("extended.xml declares " + std::to_string(names.size()) + " spml force plugin(s) (needs_spml_plugins): plain MuJoCo "
                    "ignores these <custom><text> elements" + (list.empty() ? "" : " (" + list + ")") +
                    "; simulate with spml (ForceEffects) to see them");
  }
  return names;
}

// A Coulomb level is fitted as the ideal -fc*sign(qd). MuJoCo's frictionloss is a soft
// constraint: its torque switches with qd + qdd*dmax*timeconst/2 (9.5 ms ahead at the default
// solref and solimp), not with qd, so the two differ where the motion reverses fast. Which one
// extended.xml states is the data's choice: per named `coulomb`, the written model's fit-split
// residual on its joint with the level as frictionloss against as the declaration;
// frictionloss, which plain MuJoCo simulates, where it fits better. (A vertical slide carrying a
// hinge whose frictionloss of 0.15 the model lacked, 3-8 Hz moves: the declaration's written
// model left 0.78 % of the hinge's torque on a fresh log, frictionloss at the same level 0.34 %,
// the true model 0.28 %.) Levels refitted later keep the form chosen here.
void Diagnosis::choose_coulomb_form(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes,
                                    std::pair<Eigen::VectorXd, Eigen::VectorXd>& written) {
  for (auto& c : result_.report["causes"]) {
    if (c.value("effect", "") != "coulomb" || !kept_cause(c) || !c.contains("declaration")) continue;
    const std::string joint = c["joints"][0].get<std::string>();
    const auto at = std::find(out_joints_.begin(), out_joints_.end(), joint);
    if (at == out_joints_.end() || frictionloss_joints_.count(joint)) continue;
    frictionloss_joints_.insert(joint);
    if (!written_form(edits).as_mjcf.count(c["declaration"].get<std::string>())) {   // not a joint frictionloss can hold
      frictionloss_joints_.erase(joint);
      continue;
    }
    const std::string text_before = result_.extended_mjcf;
    std::vector<std::string> tried_notes = notes;
    auto tried = write_scored(ext_path, edits, tried_notes);
    const Eigen::Index o = at - out_joints_.begin();
    const auto rows = [&](const Eigen::VectorXd& pred) { return (fit_.b - pred).segment(o * fit_.N, fit_.N).squaredNorm(); };
    const double declared = rows(written.first), frictionloss = rows(tried.first);
    const double norm = fit_.b.segment(o * fit_.N, fit_.N).norm();
    const bool better = frictionloss < declared - rss_floor(fit_.b);
    c["written_form_check"] = {{"split", fit_.name},
                               {"rel_error_fit_declaration", std::sqrt(declared) / norm},
                               {"rel_error_fit_frictionloss", std::sqrt(frictionloss) / norm},
                               {"frictionloss", better}};
    if (better) {
      written = std::move(tried);
      notes = tried_notes;
    } else {
      frictionloss_joints_.erase(joint);
      result_.extended_mjcf = text_before;
      write_text_atomic(ext_path, result_.extended_mjcf);
    }
  }
}

}  // namespace spml::diagnose_detail
