// Stage 6b, confirmation in simulation: a cause whose written form makes the model's open-loop
// rollouts worse, beyond their noise, is not a gain. Rollouts of the model as given and of the
// written model start from the same measured states (rollout.h); per joint the paired
// difference of their end errors over the windows is "worse beyond noise" when its mean exceeds
// twice its standard error. While some joint is, the kept causes on those joints are taken out
// of the written model one at a time, the last chosen first; a cause goes (rejected, with both
// rollout errors in report.json) when the model without it does better on those joints and,
// over all joints, in rollout error relative to the model as given.
#include <algorithm>
#include <cmath>

#include "diagnosis.h"
#include "rollout.h"
#include "spml/matrix_file.h"

namespace spml::diagnose_detail {
namespace {

std::vector<bool> worse_beyond_noise(const RolloutResult& before, const RolloutResult& after) {
  std::vector<bool> out(before.joints.size(), false);
  const auto W = before.window_error.size();
  for (size_t j = 0; j < out.size(); ++j) {
    double sum = 0, sum2 = 0;
    for (size_t w = 0; w < W; ++w) {
      const double d = after.window_error[w][j] - before.window_error[w][j];
      sum += d, sum2 += d * d;
    }
    const double mean = sum / static_cast<double>(W), var = std::max(sum2 / static_cast<double>(W) - mean * mean, 0.0);
    out[j] = !std::isfinite(mean) || mean > 2 * std::sqrt(var / static_cast<double>(W - 1));
  }
  return out;
}

// Sum over joints of the rollout error relative to the model as given's.
double relative_total(const RolloutResult& before, const RolloutResult& after, const std::vector<bool>* only = nullptr) {
  double s = 0;
  for (size_t j = 0; j < before.joints.size(); ++j)
    if (!only || (*only)[j]) s += after.position_error[j] / std::max(before.position_error[j], 1e-300);
  return std::isfinite(s) ? s : HUGE_VAL;
}

nlohmann::json per_joint_errors(const RolloutResult& r) {
  nlohmann::json j = nlohmann::json::object();
  for (size_t k = 0; k < r.joints.size(); ++k) j[r.joints[k]] = r.position_error[k];
  return j;
}

// The edits without one cause's part: an effect's declaration, or every parameter edit.
MjcfEdits without_cause(const MjcfEdits& edits, const nlohmann::json& cause) {
  MjcfEdits out = edits;
  if (cause["effect"] == "parameters") {
    out.joint_attributes.clear();
    out.inertials.clear();
  } else {
    const std::string decl = cause.value("declaration", "");
    out.texts.erase(std::remove_if(out.texts.begin(), out.texts.end(), [&](const auto& t) { return t.second == decl; }), out.texts.end());
  }
  return out;
}

bool on_joints(const nlohmann::json& cause, const std::vector<std::string>& joints, const std::vector<bool>& flag) {
  for (const auto& j : cause["joints"])
    for (size_t k = 0; k < joints.size(); ++k)
      if (flag[k] && joints[k] == j.get<std::string>()) return true;
  return false;
}

}  // namespace

nlohmann::json rejected_causes(const nlohmann::json& causes) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& c : causes) {
    if (c.contains("rejected"))
      out.push_back(c["effect"].get<std::string>() + (c["effect"] == "parameters" ? "" : "@" + c["joints"][0].get<std::string>()));
    for (const auto& [joint, r] : c.value("rejected_joint_terms", nlohmann::json::object()).items()) out.push_back("parameters@" + joint);
  }
  return out;
}

// After rejections: parameters_written follows what is left, and a note says what went.
void Diagnosis::note_rejections(const MjcfEdits& edits, std::vector<std::string>& notes) {
  nlohmann::json& R = result_.report;
  const nlohmann::json rejected = rejected_causes(R["causes"]);
  if (edits.joint_attributes.empty() && edits.inertials.empty())
    R["parameters_written"] = "none";
  else if (rejected.dump().find("parameters@") != std::string::npos)
    R["parameters_written"] = "partial";
  notes.push_back("rejected in simulation (causes[].rejected): " + rejected.dump() + " made the rollouts of the written model worse "
                  "beyond their noise on their joints; extended.xml leaves them out, and `final` and extended_check are of the model without them");
}

// Returns true when a cause (or a joint's part of `parameters`) was rejected; edits and the file
// at ext_path are then without it.
bool Diagnosis::confirm_in_simulation(const std::string& ext_path, MjcfEdits& edits) {
  if (opt_.rollouts < 3) return false;
  nlohmann::json& causes = result_.report["causes"];
  auto write = [&](const MjcfEdits& e) {
    std::vector<std::string> ignored;
    write_text_atomic(ext_path, edit_mjcf(opt_.model, e, ignored));
  };
  bool rejected_any = false;
  try {
    const RolloutResult before = rollout(opt_.model, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
    RolloutResult with = rollout(ext_path, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
    std::vector<bool> worse;
    // Writes `trial`; keeps it when its rollouts do better on the worse joints and over all.
    auto better_without = [&](const MjcfEdits& trial, nlohmann::json& record) {
      write(trial);
      RolloutResult without = rollout(ext_path, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
      if (!(relative_total(before, without, &worse) < relative_total(before, with, &worse) &&
            relative_total(before, without) < relative_total(before, with)))
        return false;
      record = {{"reason", "its written form makes the rollouts worse beyond their noise on its joints; extended.xml leaves it out"},
                {"rollout_error_with", per_joint_errors(with)}, {"rollout_error_without", per_joint_errors(without)}};
      edits = trial;
      with = std::move(without);
      return rejected_any = true;
    };
    for (bool dropped = true; dropped;) {
      dropped = false;
      worse = worse_beyond_noise(before, with);
      if (std::find(worse.begin(), worse.end(), true) == worse.end()) break;
      nlohmann::json record;
      for (auto i = static_cast<std::ptrdiff_t>(causes.size()) - 1; i >= 0 && !dropped; --i) {
        nlohmann::json& c = causes[static_cast<size_t>(i)];
        if (c.contains("superseded_by") || c.contains("rejected") || !on_joints(c, before.joints, worse)) continue;
        if (c["effect"] != "parameters") {
          if (c.contains("declaration") && (dropped = better_without(without_cause(edits, c), record))) c["rejected"] = record;
          continue;
        }
        // A joint's own terms first (its armature, damping, ... back to the MJCF's), then all.
        for (size_t j = 0; j < worse.size() && !dropped; ++j) {
          if (!worse[j] || !edits.joint_attributes.count(before.joints[j])) continue;
          MjcfEdits trial = edits;
          trial.joint_attributes.erase(before.joints[j]);
          if ((dropped = better_without(trial, record))) c["rejected_joint_terms"][before.joints[j]] = record;
        }
        if (!dropped && (!edits.inertials.empty() || !edits.joint_attributes.empty()) && (dropped = better_without(without_cause(edits, c), record)))
          c["rejected"] = record;
      }
    }
  } catch (const std::exception&) {
    // Rollouts impossible (no time stamps, a split shorter than one horizon): run_rollouts says so.
  }
  write(edits);
  return rejected_any;
}

}  // namespace spml::diagnose_detail
