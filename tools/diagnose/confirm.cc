// Stage 6b, confirmation in simulation: a cause whose written form makes the model's open-loop
// rollouts worse is not a gain. Rollouts of the model as given and of the written model start
// from the same measured states (rollout.h). While some joint's mean end error is larger than
// the model as given's, the kept causes on those joints are taken out of the written model one
// at a time, the last chosen first, then all of them together; a cause goes (rejected, with
// both rollout errors in report.json) when the model without it does better on those joints
// and, over all joints, in rollout error relative to the model as given. So a real cause,
// which its own joint's rollouts need, stays; one whose own joint rolls out worse with it and
// better without it goes whatever it does for the others (an end stop read as an armature
// rolled its own joint 7 % worse and was kept for a coupled joint's 13 %: a compensation, not
// a cause; no hidden LuGre, Coulomb, delay or damping error of the seed tables, about 230
// draws, rolled out worse on its own joint). (Only "worse beyond noise", a paired mean beyond
// two standard errors, started the trials before: an end stop read as re-identified link
// masses and a spring rolled out 1.6 and 1.5 times worse on two joints of a review's draw,
// within the 20 windows' noise, and was kept; on a fresh log of that robot it was 3 times
// worse held out.) A cause whose joints all keep structure that a GP over the states predicts,
// a third or more of what the causes took there, is the nearest candidate of an effect outside
// the vocabulary: it goes when the joints it rolls out worse, whichever, roll out better
// without it (cubic damping read as a linear damping rolled a coupled joint 24 % worse).
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <set>

#include "diagnosis.h"
#include "rollout.h"
#include "spml/matrix_file.h"

namespace spml::diagnose_detail {
namespace {

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

}  // namespace

// Over its own joints together: a `parameters` cause listing three joints, worse on one by
// 25 % and better on the two others by half, is needed by its joints (a review's end stop;
// judged on the worse one alone, it was rejected). A nearest candidate (`nearest`: its joints
// keep structure a GP predicts, unexplained.cc) is judged on the worse joints alone: what it
// gives its own joint is what any function of that joint's states would give.
bool better_without_cause(const RolloutResult& before, const RolloutResult& with, const RolloutResult& without,
                          const std::vector<bool>& worse, const std::vector<bool>& own, bool nearest, bool* own_rule) {
  bool own_worse = false;
  for (size_t j = 0; j < worse.size() && j < own.size(); ++j) own_worse = own_worse || (worse[j] && own[j]);
  const bool own_better = own_worse && relative_total(before, without, &own) < relative_total(before, with, &own);
  if (own_rule) *own_rule = own_better;
  return relative_total(before, without, &worse) < relative_total(before, with, &worse) &&
         (nearest || own_better || relative_total(before, without) < relative_total(before, with));
}

namespace {

// The edits without one cause's part: an effect's declaration, or every parameter edit.
MjcfEdits without_cause(const MjcfEdits& edits, const nlohmann::json& cause) {
  MjcfEdits out = edits;
  if (cause["effect"] == "parameters") {
    drop_parameters(out);
  } else {
    const std::string decl = cause.value("declaration", "");
    out.texts.erase(std::remove_if(out.texts.begin(), out.texts.end(), [&](const auto& t) { return t.second == decl; }), out.texts.end());
  }
  return out;
}

// Which of `joints` the cause lists.
std::vector<bool> joint_flags(const nlohmann::json& cause, const std::vector<std::string>& joints) {
  std::vector<bool> out(joints.size(), false);
  for (const auto& j : cause["joints"])
    for (size_t k = 0; k < joints.size(); ++k) out[k] = out[k] || joints[k] == j.get<std::string>();
  return out;
}

bool on_joints(const nlohmann::json& cause, const std::vector<std::string>& joints, const std::vector<bool>& flag) {
  const std::vector<bool> listed = joint_flags(cause, joints);
  for (size_t k = 0; k < joints.size(); ++k)
    if (flag[k] && listed[k]) return true;
  return false;
}

}  // namespace

nlohmann::json rejected_causes(const nlohmann::json& causes) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& c : causes) {
    if (c.contains("rejected"))
      out.push_back(c["effect"].get<std::string>() + (c["effect"] == "parameters" ? "" : "@" + c["joints"][0].get<std::string>()));
    // Bound to a name: items() of a temporary would iterate a json that died (ASan: stack-use-after-scope).
    const nlohmann::json terms = c.value("rejected_joint_terms", nlohmann::json::object());
    for (const auto& [joint, r] : terms.items()) out.push_back("parameters@" + joint);
  }
  return out;
}

// After rejections: parameters_written follows what is left, and a note says what went.
void Diagnosis::note_rejections(const MjcfEdits& edits, std::vector<std::string>& notes) {
  nlohmann::json& R = result_.report;
  const nlohmann::json rejected = rejected_causes(R["causes"]);
  if (!writes_parameters(edits))
    R["parameters_written"] = "none";
  else if (rejected.dump().find("parameters@") != std::string::npos)
    R["parameters_written"] = "partial";
  notes.push_back("rejected in simulation (causes[].rejected): " + rejected.dump() + " made the rollouts of the written model worse "
                  "on their joints (or, where a GP still predicts much of their joint's residual, on any joint), and the model without "
                  "them rolls out better there; extended.xml leaves them out, and `final` and extended_check are of the model without them");
}

// Returns true when a cause (or a joint's part of `parameters`) was rejected; edits and the file
// at ext_path are then without it.
bool Diagnosis::confirm_in_simulation(const std::string& ext_path, MjcfEdits& edits) {
  if (opt_.rollouts < 3) return false;
  nlohmann::json& causes = result_.report["causes"];
  auto write = [&](const MjcfEdits& e) {
    std::vector<std::string> ignored;
    write_text_atomic(ext_path, write_model(e, ignored));
  };
  bool rejected_any = false;
  try {
    const RolloutResult before = rollout(opt_.model, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
    RolloutResult with = rollout(ext_path, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
    std::vector<bool> worse;
    // Writes `trial` (the edits without a cause whose joints are `own`); keeps it when its
    // rollouts do better (better_without_cause).
    auto better_without = [&](const MjcfEdits& trial, nlohmann::json& record, const std::vector<bool>& own, bool nearest) {
      write(trial);
      RolloutResult without = rollout(ext_path, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
      bool own_better = false;
      if (!better_without_cause(before, with, without, worse, own, nearest, &own_better)) return false;
      record = {{"reason", own_better ? "its written form makes the rollouts of its own joints worse, and without it they roll out better: "
                                        "what it gives other joints is a compensation, not a cause; extended.xml leaves it out"
                           : nearest ? "every joint it lists keeps structure that a GP over the logged states predicts, a third or more of "
                                       "what the written causes take there (the nearest candidate of an effect it does not hold), and the joints "
                                       "its written form makes roll out worse roll out better without it; extended.xml leaves it out"
                                     : "its written form makes the rollouts worse on its joints, and the model without it rolls out better; extended.xml leaves it out"},
                {"rollout_error_with", per_joint_errors(with)}, {"rollout_error_without", per_joint_errors(without)}};
      edits = trial;
      with = std::move(without);
      return rejected_any = true;
    };
    // A kept cause on a worse joint. `parameters` lists the joints of its contradicted base
    // parameters, but the inertials it writes act on every joint (a hidden Coulomb level on a
    // slide made 27x worse rollouts on the hinge before it, with `parameters` listing the slide
    // only, and nothing rejected).
    auto on_worse = [&](const nlohmann::json& c) {
      const bool everywhere = c["effect"] == "parameters" && !edits.inertials.empty();
      return kept_cause(c) && (everywhere || on_joints(c, before.joints, worse));
    };
    for (bool dropped = true; dropped;) {
      dropped = false;
      worse = worse_joints(before, with);
      if (std::find(worse.begin(), worse.end(), true) == worse.end()) break;
      // The joints of kept causes where the model as it stands is the nearest candidate of
      // something else (unexplained.cc); scored without moving result_'s text of extended.xml.
      // Such a cause is tried whichever joints are worse: an end stop read as an offset on its
      // joint rolled the two joints after it 25 and 6 % worse (stop seed 211, 30 s).
      std::set<std::string> tried_joints, nearest;
      for (const auto& c : causes)
        if (kept_cause(c) && (c["effect"] == "parameters" || c.contains("declaration")))
          for (const auto& j : c["joints"]) tried_joints.insert(j.get<std::string>());
      if (!tried_joints.empty()) {
        MjcfEdits copy = edits;
        std::vector<std::string> ignored;
        const std::string text = result_.extended_mjcf;
        try {
          nearest = nearest_candidate_joints(write_scored(ext_path, copy, ignored), tried_joints);
        } catch (const std::exception&) {
          // not scored: every cause is judged by the rule for all
        }
        result_.extended_mjcf = text;
      }
      // A cause is a nearest candidate when every joint it lists is: `parameters` re-identified
      // on the real Panda's 7 joints (held out 6.76 -> 3.07 %), one of whose joints rolled out
      // 11 % worse and three kept a velocity structure beside their Coulomb friction, went on
      // that joint alone, and every cause after it (3.26 % written before, 6.76 % after).
      auto is_nearest = [&](const std::vector<bool>& own) {
        bool any = false;
        for (size_t j = 0; j < own.size(); ++j)
          if (own[j]) {
            if (!nearest.count(before.joints[j])) return false;
            any = true;
          }
        return any;
      };
      auto nearest_cause = [&](const nlohmann::json& c) { return kept_cause(c) && is_nearest(joint_flags(c, before.joints)); };
      nlohmann::json record;
      for (auto i = static_cast<std::ptrdiff_t>(causes.size()) - 1; i >= 0 && !dropped; --i) {
        nlohmann::json& c = causes[static_cast<size_t>(i)];
        const std::vector<bool> own = joint_flags(c, before.joints);
        if (!on_worse(c) && !nearest_cause(c)) continue;
        if (c["effect"] != "parameters") {
          if (c.contains("declaration") && (dropped = better_without(without_cause(edits, c), record, own, is_nearest(own))))
            c["rejected"] = record;
          continue;
        }
        // A joint's own terms first (its armature, damping, ... back to the MJCF's), then all.
        for (size_t j = 0; j < worse.size() && !dropped; ++j) {
          if (!worse[j] || !edits.joint_attributes.count(before.joints[j])) continue;
          MjcfEdits trial = edits;
          trial.joint_attributes.erase(before.joints[j]);
          std::vector<bool> just(worse.size(), false);
          just[j] = true;
          if ((dropped = better_without(trial, record, just, is_nearest(just)))) {
            c["rejected_joint_terms"][before.joints[j]] = record;
            // Written as its listed terms alone (write_listed_terms), the joint's may be all of it.
            if (!writes_parameters(edits)) c["rejected"] = record;
          }
        }
        if (!dropped && writes_parameters(edits) && (dropped = better_without(without_cause(edits, c), record, own, is_nearest(own))))
          c["rejected"] = record;
      }
      if (dropped) continue;
      // None alone: the causes on the worse joints together. A spring and re-identified link
      // masses read from an end stop (a review's draw) each held the other up - the rollouts
      // 7 and 6 times worse without either alone, 5 times better without both - and were kept.
      // Nearest candidates among them, judged as one (stop seed 211: an offset and mass moments
      // read from its end stop).
      MjcfEdits trial = edits;
      std::vector<nlohmann::json*> together;
      bool any_nearest = false;
      for (auto& c : causes) {
        if (c["effect"] != "parameters" && !c.contains("declaration")) continue;
        const bool near = nearest_cause(c);
        if (!on_worse(c) && !near) continue;
        trial = without_cause(trial, c);
        together.push_back(&c);
        any_nearest = any_nearest || near;
      }
      if (together.size() > 1 && (dropped = better_without(trial, record, std::vector<bool>(worse.size(), false), any_nearest)))
        for (nlohmann::json* c : together) (*c)["rejected"] = record;
    }
  } catch (const std::exception&) {
    // Rollouts impossible (no time stamps, a split shorter than one horizon): run_rollouts says so.
  }
  write(edits);
  return rejected_any;
}

namespace {

bool is_diagnosed(const std::pair<std::string, std::string>& text) { return text.first.rfind(kDiagnosedPrefix, 0) == 0; }

}  // namespace

// A cause rejected from the written model gives its place back to the one it superseded on its
// joint (a Stribeck curve refused with fs < fc once fitted with the written parameters, the
// Coulomb friction it had nested written in its stead): left out, a review's extended.xml held
// no friction at all, 1.07 % held out where Coulomb alone had left 0.227 %. The restored cause
// is written with its path's parameters and then fitted again like every written effect.
void Diagnosis::restore_superseded(size_t rejected, size_t first, MjcfEdits& edits, std::vector<std::string>& notes) {
  nlohmann::json& causes = result_.report["causes"];
  const Candidate& r = cands_[static_cast<size_t>(causes_[rejected].candidate)];
  for (size_t s = 0; s < causes_.size(); ++s) {
    const Candidate& c = cands_[static_cast<size_t>(causes_[s].candidate)];
    if (s == rejected || c.joint != r.joint || causes_[s].superseded_by != r.plugin->name || c.stateful) continue;
    nlohmann::json& sj = causes[first + s];
    PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, c.shape_values), "diagnose");
    const auto pnames = inst.param_names();
    Eigen::VectorXd theta(inst.nparam());
    for (int k = 0; k < inst.nparam(); ++k) theta[k] = sj["params"].value(pnames[static_cast<size_t>(k)], 0.0);
    inst.set_params(theta);
    const std::string config = inst.config_text();
    if (config.empty()) continue;
    causes_[s].superseded_by.clear();
    sj.erase("superseded_by");
    edits.texts.emplace_back(declaration_name(c), declaration_text(c, config));
    sj["declaration"] = edits.texts.back().second;
    sj["restored"] = {{"reason", "the " + std::string(r.plugin->name) + " on " + r.joint_name + " that superseded it is rejected; extended.xml writes this cause in its place"}};
    notes.push_back(std::string(c.plugin->name) + " on " + c.joint_name + " is written again in place of the rejected " + r.plugin->name + " that had superseded it");
    return;
  }
}

// The written effects are fitted again, by least squares on the fit split, against what the
// written model without them predicts: amplitudes fitted jointly with parameters that are then
// not written (refused inertials, rejected terms) belong to another model. A cause whose
// amplitudes the plugin then refuses (a negative friction level, fs < fc) is rejected and the
// rest fitted again without it. Returns true when a declaration changed.
bool Diagnosis::refit_written_effects(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes) {
  nlohmann::json& causes = result_.report["causes"];
  // report.json lists `delay` (when named), then `parameters` (when named), then the effects.
  // (Offset by `parameters` alone, a named delay shifted every effect by one: a LuGre fit beside
  // a delay was never refitted with the written model, its amplitude 1.0036 not folded into
  // its keys and params_written missing; a review's draw.)
  const size_t first = (delay_.named ? 1 : 0) + (parameters_named_ ? 1 : 0);
  bool changed = false;
  // A stateful cause (#22) has one amplitude, its simulated force's, written in its keys where
  // the force scales with them (scales_with_keys, one simulation each: checked once here);
  // otherwise it keeps the keys its simulation fit found. Kept as fitted beside least-squares
  // parameters that extended.xml then states in their consistent form, LuGre's written model
  // left more of the joint's held-out error (true damping 0.35 beside LuGre: a median 1.5
  // times as much; the Panda's joint 7, 10.4 % against 9.8 %).
  std::vector<bool> refittable(causes_.size());
  for (size_t i = 0; i < causes_.size(); ++i) {
    const Candidate& c = cands_[static_cast<size_t>(causes_[i].candidate)];
    refittable[i] = !c.stateful || (causes_[i].superseded_by.empty() && scales_with_keys(c));
  }
  for (bool again = true; again;) {
    again = false;
    std::vector<size_t> live;
    for (size_t i = 0; i < causes_.size(); ++i) {
      const nlohmann::json& cj = causes[first + i];
      if (causes_[i].superseded_by.empty() && cj.contains("declaration") && !cj.contains("rejected") && refittable[i]) live.push_back(i);
    }
    if (live.empty()) break;
    MjcfEdits bare = edits;
    // Without the effects refitted here; a stateful one not refitted stays in, so `rest` is net of its force.
    std::vector<std::string> refitted;
    for (size_t i : live) refitted.push_back(causes[first + i]["declaration"].get<std::string>());
    bare.texts.erase(std::remove_if(bare.texts.begin(), bare.texts.end(),
                                    [&](const auto& t) { return is_diagnosed(t) && std::find(refitted.begin(), refitted.end(), t.second) != refitted.end(); }),
                     bare.texts.end());
    std::vector<std::string> ignored;
    write_text_atomic(ext_path, write_model(bare, ignored, &edits));   // the levels the refitted effects take over stay taken
    const MjcfRegressor ext(ext_path);
    const Eigen::VectorXd rest = fit_.b - written_prediction(ext, ext.base_parameters(), fit_);
    std::vector<const BlockColumns*> blocks;
    for (size_t i : live) blocks.push_back(&cands_[static_cast<size_t>(causes_[i].candidate)].fit_cols);
    const Fit f = fit_blocks(blocks, rest, false);
    Eigen::Index off = 0;
    for (size_t i : live) {
      const Candidate& c = cands_[static_cast<size_t>(causes_[i].candidate)];
      Eigen::VectorXd theta(c.fit_cols.cols);
      for (Eigen::Index k = 0; k < theta.size(); ++k) theta[k] = f.determined[static_cast<size_t>(off + k)] ? f.coef[off + k] : 0.0;
      off += c.fit_cols.cols;
      nlohmann::json& cj = causes[first + i];
      auto text = std::find_if(edits.texts.begin(), edits.texts.end(), [&](const auto& t) { return t.second == cj["declaration"].get<std::string>(); });
      if (text == edits.texts.end()) continue;
      const std::string why = refused(causes_[i].candidate, theta);
      if (!why.empty()) {
        // A later cause on the same joint joined on the evidence left beside this one: when the
        // two fitted together make this one refused, the later one goes (a marginal band, Delta
        // BIC 36, beside a hidden Stribeck curve of Delta BIC 1093 had the curve refused).
        size_t drop = i;
        for (size_t k : live)
          if (k > i && cands_[static_cast<size_t>(causes_[k].candidate)].joint == c.joint) drop = k;
        nlohmann::json& dj = causes[first + drop];
        auto dtext = std::find_if(edits.texts.begin(), edits.texts.end(), [&](const auto& t) { return t.second == dj["declaration"].get<std::string>(); });
        if (dtext != edits.texts.end()) edits.texts.erase(dtext);
        if (drop == i) {
          dj["rejected"] = {{"reason", "fitted with the parameters extended.xml states, " + why + "; extended.xml leaves it out"},
                            {"summary", "refused once fitted with the written parameters"}};
          restore_superseded(i, first, edits, notes);
        } else
          dj["rejected"] = {{"reason", "fitted beside it with the parameters extended.xml states, the earlier " + std::string(c.plugin->name) + " on " +
                                           c.joint_name + " is refused (" + why + "); extended.xml leaves this later cause out"},
                            {"summary", "made an earlier cause on its joint refused"}};
        again = changed = true;
        break;
      }
      const std::vector<double> keys = c.stateful ? scaled_keys(c, theta[0]) : c.shape_values;
      PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, keys), "diagnose");
      nlohmann::json pw = nlohmann::json::object();
      if (c.stateful) {
        cands_[static_cast<size_t>(causes_[i].candidate)].written_scale = theta[0];
        for (size_t k = 0; k < keys.size(); ++k) pw[c.shape[k]->key] = keys[k];
      } else {
        inst.set_params(theta);
        const auto pnames = inst.param_names();
        for (Eigen::Index k = 0; k < theta.size(); ++k) pw[pnames[static_cast<size_t>(k)]] = theta[k];
      }
      const std::string decl = declaration_text(c, inst.config_text());
      changed |= decl != text->second;
      text->second = decl;
      cj["declaration"] = decl;
      cj["params_written"] = pw;
    }
  }
  if (changed && parameters_named_ && result_.report["parameters_written"] != "all")
    notes.push_back("the effects were fitted jointly with re-identified parameters that extended.xml does not keep (all): their amplitudes "
                    "(causes[].params_written) are fitted again with the parameters it states");
  return changed;
}

// The written model must not predict the held-out split worse than the model as given, over
// the joints or on any one: then the re-identified parameters are written as the terms they
// list alone, then not at all (the effects fitted again with the MJCF's own), and if that is
// still worse, every cause goes: extended.xml is the model as given, and the notes say why.
bool Diagnosis::guard_held_out(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes,
                               std::pair<Eigen::VectorXd, Eigen::VectorXd>& written) {
  nlohmann::json& R = result_.report;
  const double given = test_.y0.squaredNorm();
  // Worse beyond rounding (the model as given written back predicts `given` to the last digits)
  // under either noise model: one variance for all joints (the sum of squares in N m^2) or one
  // per joint (the sum over joints of the log of each joint's sum relative to its own as given).
  // Under the first alone, an end stop on a base joint read as its links' mass moments was
  // written with the other joints' held-out torque 2.5-5 times worse (geometric mean), and
  // cubic damping as the joints' damping with them 1.2-5.9 times worse, on 20 of 60 draws.
  // One joint alone may not become much worse either, whatever the others gain: a weak cable
  // read as `parameters` wrote the hand's mass 0.25 -> 0.078 kg, and the wrist, which no cause
  // lists, predicted its held-out torque 6.8 times worse (RMS) inside a geometric mean of 0.5.
  // The bar is its RMS doubled (sum of squares x4): a held-out split's own scatter moves a
  // joint's RMS by a few percent; of 550 kept reports of earlier reviews and probes, only that
  // one moved a joint by more than 1.15 times (and two seed-table damping draws' consistent
  // fits, 3.1 times, now written as their listed terms: write_listed_terms).
  constexpr double kOneJointWorse = 4.0;
  struct Verdict {
    bool in_total = false, by_joints = false;
    double geometric = 1, worst = 1;   // each joint's sum of squares against its own as given
    size_t worst_joint = 0;
    bool worse() const { return in_total || by_joints || worst > kOneJointWorse; }
  };
  auto judge = [&] {
    Verdict v;
    const Eigen::VectorXd r = test_.b - written.second;
    const std::vector<double> ratios = output_ratios(r, test_.y0, test_.b, test_.N);
    if (!ratios.empty()) {
      v.worst_joint = static_cast<size_t>(std::max_element(ratios.begin(), ratios.end()) - ratios.begin());
      v.worst = ratios[v.worst_joint];
    }
    v.geometric = geometric_mean(ratios);
    v.in_total = r.squaredNorm() > given + rss_floor(test_.b);
    v.by_joints = v.geometric > 1 + 1e-9;
    return v;
  };
  auto worse = [&] { return judge().worse(); };
  const Verdict v = judge();
  if (!v.worse()) return false;
  const std::string wname = v.worst_joint < out_joints_.size() ? out_joints_[v.worst_joint] : "?";
  const std::string why = "the written model predicts the held-out split '" + test_name_ + "' worse (relative error " +
                          fmt((test_.b - written.second).norm() / test_.b.norm(), 8) + ", each joint's sum of squares " +
                          fmt(v.geometric, 4) + " times its own as given, geometric mean; " + wname + "'s " + fmt(std::sqrt(v.worst), 3) +
                          " times its RMS as given) than the model as given (relative error " + fmt(std::sqrt(given) / test_.b.norm(), 8) + ")";
  // Said as it was judged: on the total, joint by joint (a review read "test error after
  // 6.25 % REJECTED: held-out error worse" against 12.6 % as given; its joints were 20 and 16
  // times worse than their own), or on one joint.
  const nlohmann::json record = {
      {"reason", why + "; extended.xml leaves it out"},
      {"summary", v.in_total    ? "held-out error worse than the model as given"
                  : v.by_joints ? "held-out error worse than the model as given joint by joint (each joint's against its own, geometric mean " +
                                      fmt(v.geometric, 3) + " times)"
                                : "held-out error on " + wname + " " + fmt(std::sqrt(v.worst), 3) + " times its own as given (RMS)"}};
  std::vector<std::string> ignored;
  if (parameters_named_ && writes_parameters(edits)) {
    // First the terms `parameters` lists alone, where it was not written so (write_listed_terms):
    // a damping error (0.35 for 0.5, seed-table draw 213) written with every body re-identified
    // beside it left a light joint's held-out torque 3.1 times worse (RMS).
    if (R["parameters_written"] != "listed" && write_listed_terms(edits, false, why)) {
      notes.push_back(why + ": extended.xml writes only the terms `parameters` lists, keeps the MJCF's inertials and other terms, "
                      "and fits the effects again");
      refit_written_effects(ext_path, edits, notes);
      written = write_scored(ext_path, edits, ignored);
      if (!worse()) return true;
    }
    drop_parameters(edits);
    R["causes"][delay_.named ? 1 : 0]["rejected"] = record;   // `parameters`, after a named `delay`
    R["parameters_written"] = "none";
    notes.push_back(why + ": the re-identified parameters are left out and the effects fitted again with the MJCF's own");
    refit_written_effects(ext_path, edits, notes);
    written = write_scored(ext_path, edits, ignored);
    if (!worse()) return true;
  }
  for (auto& c : R["causes"])
    if (kept_cause(c)) c["rejected"] = record;
  MjcfEdits none;
  none.comment = edits.comment;
  edits = none;
  R["parameters_written"] = "none";
  written = write_scored(ext_path, edits, ignored);
  notes.push_back(why + " with its causes: none is written (causes[].rejected), extended.xml is the model as given");
  return true;
}


// The declarations of `causes` fitted together against the model as given (`f`: refit(causes,
// false)): a static friction with its fitted parameters, a stateful one with its keys at the
// fitted amplitude - what extended.xml would write for them beside the MJCF's parameters.
Declarations Diagnosis::declared(const std::vector<int>& causes, const Fit& f) const {
  Declarations out;
  Eigen::Index off = 0;
  for (int k : causes) {
    const Candidate& c = cands_[static_cast<size_t>(k)];
    const Eigen::VectorXd theta = f.coef.segment(off, c.fit_cols.cols);
    off += c.fit_cols.cols;
    PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, c.stateful ? scaled_keys(c, theta[0]) : c.shape_values), "diagnose");
    if (!c.stateful) inst.set_params(theta);
    if (const std::string config = inst.config_text(); !config.empty()) out.emplace_back(declaration_name(c), declaration_text(c, config));
  }
  return out;
}

// Does the model as given with stateful candidate k roll out closer to the measured positions
// on its joint, over the test split, than with each static friction of `rivals` (no friction
// when there is none), each beside the chosen causes `beside` on the joint that k does not
// replace and fitted with them against the model as given? The test of a stateful fit whose break-away the
// data leave loose (profile_once: break_away_loose): a dry friction sticks in simulation too,
// and where the bristles only stand in for that, a static friction simulates as well. Closer
// means the paired differences of the windows' end errors average beyond two standard errors
// (the mean alone let a hidden Coulomb friction of delay_coulomb draw 17 be `stick_slip` by
// 1 %), over 60 windows whatever --rollouts asks of the report's rollouts (a test whose power
// followed that option named LuGre on a review's log at 100 windows and not at 20). Without
// rollouts (--rollouts 0) or where they fail, it is not named.
bool Diagnosis::rolls_out_better(int k, const std::vector<int>& rivals, const std::vector<int>& beside) {
  namespace fs = std::filesystem;
  constexpr int kWindows = 60;   // 20 left a LuGre fit 2.6 times closer at paired t 1.5 (a review's shoulder)
  constexpr double kPairedT = 2;
  Candidate& c = cands_[static_cast<size_t>(k)];
  // Beside a chosen friction of a level on the joint that it does not replace, such a fit is a
  // second dry friction of the joint: not named. (A hidden asymmetric friction of the realistic
  // draws, raw differences: the static fit took half of its Coulomb level, and LuGre with
  // fs = fc and its bristles at the top of their ranges took the rest and rolled out closer.)
  for (int q : beside)
    if (holds_level_friction(cands_[static_cast<size_t>(q)])) {
      c.lost_to_static = "fitted by simulation, but what the data determine of it is a dry friction, beside " + std::string(cands_[static_cast<size_t>(q)].plugin->name) +
                         " on " + c.joint_name + ", itself one: not a second friction of the joint";
      return false;
    }
  if (opt_.rollouts <= 0) {
    c.lost_to_static = "fitted by simulation, but what the data determine of it a static friction may simulate as well, and --rollouts 0 leaves that untested";
    return false;
  }
  static std::atomic<int> serial{0};   // diagnoses may run side by side in one process (the Python module)
  const fs::path path = fs::temp_directory_path() / ("spml-rival-" + std::to_string(::getpid()) + "-" + std::to_string(serial++) + ".xml");
  // The end error of each window on the joint.
  auto errors_with = [&](int q) {
    MjcfEdits e;
    std::vector<int> causes = beside;
    if (q >= 0) causes.push_back(q);   // q < 0: beside them alone
    if (!causes.empty()) e.texts = declared(causes, refit(causes, false));
    std::vector<std::string> ignored;
    write_text_atomic(path.string(), edit_mjcf(opt_.model, with_take_over(e), ignored));
    const RolloutResult r = rollout(path.string(), test_.split, kWindows, opt_.rollout_seconds, test_.runs);
    const auto j = static_cast<size_t>(std::find(r.joints.begin(), r.joints.end(), c.joint_name) - r.joints.begin());
    Eigen::VectorXd out(static_cast<Eigen::Index>(r.window_error.size()));
    for (size_t w = 0; w < r.window_error.size(); ++w) out[static_cast<Eigen::Index>(w)] = j < r.window_error[w].size() ? r.window_error[w][j] : HUGE_VAL;
    return out;
  };
  // Closer than every rival: the paired differences' mean beyond two standard errors. (The
  // mean alone let a LuGre fit of a hidden Coulomb friction join by 1 %.)
  double mine = 0, theirs = 0, least_t = HUGE_VAL;
  std::string worst;
  try {
    const Eigen::VectorXd e_k = errors_with(k);
    mine = e_k.mean();
    for (int q : rivals.empty() ? std::vector<int>{-1} : rivals) {
      const Eigen::VectorXd e_q = errors_with(q);
      const Eigen::VectorXd d = e_q - e_k;
      const double n = static_cast<double>(d.size());
      const double se = std::sqrt((d.array() - d.mean()).square().sum() / std::max(n - 1, 1.0) / n);
      const double t = n > 1 && se > 0 ? d.mean() / se : (d.mean() > 0 ? HUGE_VAL : -HUGE_VAL);
      if (!(t >= least_t)) least_t = std::isnan(t) ? -HUGE_VAL : t, theirs = e_q.mean(), worst = q < 0 ? "no friction" : cands_[static_cast<size_t>(q)].plugin->name;
    }
  } catch (const std::exception&) {
    least_t = -HUGE_VAL;
  }
  std::error_code ignored;
  fs::remove(path, ignored);
  if (least_t > kPairedT) return true;
  c.lost_to_static = "fitted by simulation, but " +
                     (c.at_range_end.empty() ? std::string("its break-away is not determined") : c.at_range_end + " ran to the end of the declared range or the edge of what the effect accepts") +
                     " (" + comma_list(c.not_identifiable) + " loose), and the model as given with it does not roll out closer on " + c.joint_name + " than with " + worst +
                     " beyond the windows' noise (" + std::to_string(kWindows) + " windows of " + fmt(opt_.rollout_seconds) + " s: mean end error " + fmt(mine) +
                     " against " + fmt(theirs) + ", paired t " + fmt(least_t, 3) + ", needs " + fmt(kPairedT, 2) + ")";
  return false;
}

}  // namespace spml::diagnose_detail
