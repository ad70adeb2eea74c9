// Stage 6, verification: the written model. extended.xml is written from the edits, reloaded,
// and its own inverse dynamics must reproduce the final prediction; rollouts of the model as
// given and of extended.xml under the measured torques, a few windows' trajectories in rollouts.csv.
#include <filesystem>
#include <unistd.h>

#include "diagnosis.h"
#include "rollout.h"
#include "spml/envs/mjcf_regressor.h"
#include "spml/matrix_file.h"

namespace spml::diagnose_detail {

// The written model's own prediction on a split: its inverse dynamics with its declared linear
// plugins, through the split's parallel filter (the same filter as every column).
Eigen::VectorXd Diagnosis::written_prediction(const MjcfRegressor& ext, const MjcfRegressor::Base& ebase, const SplitData& s) const {
  const JointColumns cols(ext, s.split);
  Eigen::VectorXd pred = stacked_base_regressor(ext, ebase, s.split.X, cols, s.name) * ebase.model_values;
  filter_stacked(s.sos, pred, s.N, s.runs, true);
  if (s.friction.size()) pred += s.friction;   // MuJoCo's frictionloss, as in `given` (load.cc)
  // ... at the written model's levels where they differ (a level taken over, a re-identified one).
  bool same = true;
  for (int v = 0; v < ext.model()->nv; ++v) same &= ext.model()->dof_frictionloss[v] == reg_->model()->dof_frictionloss[v];
  if (!same) {
    if (s.soft.size()) pred -= s.soft;
    Eigen::VectorXd soft = frictionloss_correction(s, ext.model());
    if (soft.size()) {
      filter_stacked(s.sos, soft, s.N, {}, true);
      pred += soft;
    }
  }
  pred += written_stateful(s, ext.model());   // #22: stateful plugins are no regressor columns: simulated as declared
  return pred;
}

// Writes one version of the model to ext_path and returns its predictions on the fit and test
// splits (its own inverse dynamics, reloaded with MuJoCo).
std::pair<Eigen::VectorXd, Eigen::VectorXd> Diagnosis::write_scored(const std::string& ext_path, MjcfEdits& e, std::vector<std::string>& n) {
  try {
    result_.extended_mjcf = write_model(e, n);
  } catch (const std::runtime_error& err) {
    if (e.inertials.empty()) throw;
    // A compiler setting that would override written inertials (inertiafromgeom, settotalmass).
    e.inertials.clear();
    n.push_back(std::string(err.what()) + ": the re-identified inertials are not written");
    parameters_partial_ = true;
    result_.extended_mjcf = write_model(e, n);
  }
  write_text_atomic(ext_path, result_.extended_mjcf);
  MjcfRegressor ext(ext_path);
  const auto ebase = ext.base_parameters();
  return std::make_pair(written_prediction(ext, ebase, fit_), written_prediction(ext, ebase, test_));
}

// Re-identified parameters written only in part (inertials refused) are one solution cut in
// two; they may predict worse than the MJCF's own. The version that fits the fit split better
// is kept.
void Diagnosis::choose_partial(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes,
                               std::pair<Eigen::VectorXd, Eigen::VectorXd>& written) {
  nlohmann::json& R = result_.report;
  MjcfEdits effects_only = edits;
  drop_parameters(effects_only);
  std::vector<std::string> notes_none = notes;
  const std::string text_all = result_.extended_mjcf;
  auto none = write_scored(ext_path, effects_only, notes_none);
  const double rss_all = (fit_.b - written.first).squaredNorm(), rss_none = (fit_.b - none.first).squaredNorm();
  // Equal to rounding, the MJCF's own parameters (the smaller change) are kept.
  if (rss_none <= rss_all + rss_floor(fit_.b)) {
    written = std::move(none);
    edits = effects_only;
    notes = notes_none;
    R["parameters_written"] = "none";
    notes.push_back("the re-identified parameters could be written only in part (inertials refused), and that version fits the fit "
                    "split no better (relative error " + fmt(std::sqrt(rss_all) / fit_.b.norm(), 8) + ") than the MJCF's own parameters "
                    "with the effects (" + fmt(std::sqrt(rss_none) / fit_.b.norm(), 8) + "): extended.xml keeps the MJCF's parameters");
    // Said on the cause too, as every other way `parameters` is left out of extended.xml is (a
    // review's report.md had stated "extended.xml: 0.7388" for a damping the file kept at 0.4318).
    R["causes"][delay_.named ? 1 : 0]["rejected"] = {{"reason", notes.back()}, {"summary", "written only in part, and no better than the MJCF's own"}};
  } else {
    result_.extended_mjcf = text_all;
    write_text_atomic(ext_path, result_.extended_mjcf);
  }
}

// `parameters` written as the terms it lists alone, each its joint's own attribute (armature,
// damping, stiffness, a Coulomb level as frictionloss: joint_attribute_term) at the estimate that named it, the MJCF's
// inertials and other terms kept: where `every` listed term is one (parameters_written
// "listed"), or, for the held-out guard, where any is (`why`: the guard's reason; "partial"
// where a listed combination of parameters is then not written). The
// consistent fit re-identifies every body beside them, and the bodies the data do not
// contradict move with the noise: on 30 seed-table draws of a damping error (0.35 for 0.5),
// the damped joint's held-out error was lower written alone on 27 (0.0184 -> 0.0026, 0.0132 ->
// 0.0022 of its torque; the three others within 5 %). Returns whether edits changed.
bool Diagnosis::write_listed_terms(MjcfEdits& edits, bool every, const std::string& why) {
  nlohmann::json& R = result_.report;
  if (!parameters_named_ || !writes_parameters(edits)) return false;
  nlohmann::json& pc = R["causes"][delay_.named ? 1 : 0];
  const nlohmann::json rejected = pc.value("rejected_joint_terms", nlohmann::json::object());
  MjcfEdits listed = edits;
  drop_parameters(listed);
  nlohmann::json terms = nlohmann::json::object();
  bool all = true;
  for (const auto& [name, value] : pc["params"].items()) {
    const auto attr = joint_attribute_term(name);
    const bool attribute = attr && std::find(out_joints_.begin(), out_joints_.end(), attr->joint) != out_joints_.end();
    if (!attribute && every) return false;
    all = all && attribute;
    if (!attribute || rejected.contains(attr->joint)) continue;   // (a joint's terms rejected in simulation stay the MJCF's)
    listed.joint_attributes[attr->joint][attr->attribute] = value.get<double>();
    terms[name] = {{"value", value}, {"prior", pc["prior"].value(name, 0.0)}, {"std_error", pc["stderr"].value(name, 0.0)}};
  }
  if (!writes_parameters(listed)) return false;
  edits = listed;
  pc["written"]["bodies"] = nlohmann::json::object();
  pc["written"]["terms"] = terms;
  pc["written"]["estimator"] = "the listed terms at their estimates";
  pc["written"].erase("joint_weights");
  pc["written"].erase("prior_weight");
  pc["written"]["listed_only"] = {{"reason", every ? "every term `parameters` lists is a joint's own attribute: extended.xml writes them alone, at their "
                                                     "estimates, and keeps the MJCF's inertials and other terms"
                                                   : why + "; extended.xml writes the terms `parameters` lists alone, at their estimates, "
                                                           "and keeps the MJCF's inertials and other terms"}};
  R["parameters_written"] = all ? "listed" : "partial";   // partial: a listed combination of parameters is not written
  return true;
}

// Writes extended.xml and scores it: `final` in report.json is the written model's, reloaded
// with MuJoCo; extended_check says how far it is from the fit's own prediction. Returns the
// written model's predictions on the fit and test splits.
std::pair<Eigen::VectorXd, Eigen::VectorXd> Diagnosis::verify(const std::string& out_dir, MjcfEdits& edits, std::vector<std::string>& notes,
                                                              const Eigen::VectorXd& final_pred_fit) {
  namespace fs = std::filesystem;
  auto t0 = Clock::now();
  nlohmann::json& R = result_.report;
  edits.comment = "extended by spml diagnose from " + opt_.model + " and " + opt_.data + " (fit split '" + opt_.fit_split + "')";
  const std::string ext_path = (out_dir.empty() ? fs::temp_directory_path() / ("spml-extended-" + std::to_string(::getpid()) + ".xml")
                                                : fs::path(out_dir) / "extended.xml").string();
  if (!out_dir.empty()) fs::create_directories(out_dir);
  std::vector<std::string> notes_all = notes;
  std::pair<Eigen::VectorXd, Eigen::VectorXd> written = write_scored(ext_path, edits, notes_all);
  R["parameters_written"] = !parameters_named_ ? "none" : parameters_partial_ ? "partial" : "all";
  if (parameters_partial_) choose_partial(ext_path, edits, notes_all, written);
  if (write_listed_terms(edits, true, "")) written = write_scored(ext_path, edits, notes_all);
  choose_coulomb_form(ext_path, edits, notes_all, written);
  notes = notes_all;
  // The effects are fitted again with the parameters written (and checked by their plugins),
  // before the confirmation in simulation: it judges the model extended.xml states. (Judged at
  // its keys before that refit, 3 % below the amplitude it is written with, a LuGre cause on a
  // review's shoulder rolled out worse than the Coulomb level the model declared there, 0.670
  // against 0.621 mrad, and was rejected; written, the same keys roll out at 0.531.) After a
  // rejection the others are fitted again without it.
  bool changed = refit_written_effects(ext_path, edits, notes);
  std::vector<std::string> again;   // the same edit notes as before, not repeated
  auto scored = write_scored(ext_path, edits, again);
  if (confirm_in_simulation(ext_path, edits)) {
    note_rejections(edits, notes);
    refit_written_effects(ext_path, edits, notes);
    changed = true;
    scored = write_scored(ext_path, edits, again);
  } else {
    // Written again: the rejection trials leave other versions of the model at ext_path (EMPS:
    // the declaration-free model was the published extended.xml, while `final` scored the
    // right one); the text and its scores are those of `scored`.
    write_text_atomic(ext_path, result_.extended_mjcf);
  }
  if (changed) written = std::move(scored);
  // The guard refits the effects with the MJCF's parameters: that model is confirmed in
  // simulation again (an offset fitted beside re-identified mass moments, left alone by them,
  // rolled out 2.35 times worse on every joint of an end-stop draw).
  if (guard_held_out(ext_path, edits, notes, written) && confirm_in_simulation(ext_path, edits)) {
    note_rejections(edits, notes);
    written = write_scored(ext_path, edits, again);
    guard_held_out(ext_path, edits, notes, written);
  }
  R["extended_mjcf"] = out_dir.empty() ? "" : "extended.xml";
  R["extended_check"] = {{"max_abs_deviation", (written.first - final_pred_fit).cwiseAbs().maxCoeff()},
                         {"rms_torque", rms(fit_.b)}};
  R["final"] = metrics(fit_.b - written.first, test_.b - written.second);
  // The cross records scored with extended.xml as written, as `final` is: a cause rejected in
  // simulation or by the held-out guard is not in it (a review's cubic damping read as its
  // joint's damping, rejected: its cross record said 23.2 -> 14 % for a file that is the model
  // as given).
  if (R.contains("cross")) {
    const MjcfRegressor ext(ext_path);
    const auto ebase = ext.base_parameters();
    for (size_t k = 0; k < cross_.size() && k < R["cross"].size(); ++k) {
      const SplitData& s = cross_[k].second;
      R["cross"][k]["rel_error_final"] = (s.b - written_prediction(ext, ebase, s)).norm() / s.b.norm();
    }
  }
  R["needs_spml_plugins"] = report_written_form(edits, notes);   // what stays a plugin text (written_form.cc)
  result_.timings.outputs += since(t0);
  t0 = Clock::now();
  run_rollouts(ext_path, out_dir, notes);
  if (out_dir.empty()) fs::remove(ext_path);
  result_.timings.rollouts += since(t0);
  return written;
}

namespace {

// report.json's rollout.traced: the windows in rollouts.csv, each with its start and both models'
// end errors per joint (what the last row of the window in rollouts.csv shows).
nlohmann::json traced_windows(const RolloutResult& before, const RolloutResult& after, const std::vector<int>& traced) {
  nlohmann::json out = nlohmann::json::array();
  for (const int w : traced) {
    const auto k = static_cast<size_t>(w);
    nlohmann::json b = nlohmann::json::object(), a = nlohmann::json::object();
    for (size_t j = 0; j < before.joints.size(); ++j) {
      b[before.joints[j]] = before.window_error[k][j];
      a[after.joints[j]] = after.window_error[k][j];
    }
    out.push_back({{"window", w}, {"start_s", before.window_start[k]}, {"error_before", b}, {"error_after", a}});
  }
  return out;
}

}  // namespace

// Rollouts of the model as given and of extended.xml; joints whose rollouts the written model
// makes worse are listed (worse_on) and said in the notes. A few windows' trajectories go to
// rollouts.csv (windows_to_trace: the worst of the model as given, a median one, the best).
void Diagnosis::run_rollouts(const std::string& ext_path, const std::string& out_dir, std::vector<std::string>& notes) {
  nlohmann::json& R = result_.report;
  if (opt_.rollouts <= 0) return;
  std::string csv;
  try {
    const RolloutResult before = rollout(opt_.model, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
    const RolloutResult after = rollout(ext_path, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs);
    nlohmann::json b = nlohmann::json::object(), a = nlohmann::json::object(), worse = nlohmann::json::array();
    const std::vector<bool> worse_on = worse_joints(before, after);
    for (size_t j = 0; j < before.joints.size(); ++j) {
      b[before.joints[j]] = before.position_error[j];
      a[after.joints[j]] = after.position_error[j];
      if (worse_on[j]) worse.push_back(before.joints[j]);
    }
    const nlohmann::json rejected = rejected_causes(R["causes"]);
    const std::vector<int> traced = windows_to_trace(before);
    R["rollout"] = {{"split", test_name_}, {"horizon_s", opt_.rollout_seconds}, {"windows", before.windows},
                    {"position_error_before", b}, {"position_error_after", a}, {"worse_on", worse}, {"rejected", rejected},
                    {"traced", traced_windows(before, after, traced)}};
    // A worse joint without a kept cause of its own is moved by the causes of the joints it is
    // coupled to (a review read "the causes on those joints are not confirmed" for an elbow
    // with none, 0.196 against 0.181 mrad).
    nlohmann::json with_cause = nlohmann::json::array(), without = nlohmann::json::array();
    for (const auto& w : worse) {
      bool own = false;
      for (const auto& c : R["causes"])
        if (kept_cause(c) && c["effect"] != "delay")   // a delay moves every joint's data, not one joint
          for (const auto& j : c.value("joints", nlohmann::json::array())) own = own || j == w;
      (own ? with_cause : without).push_back(w);
    }
    if (!with_cause.empty())
      notes.push_back("rollouts of extended.xml end farther from the measured positions than the model as given on " + with_cause.dump() +
                      " (rollout.worse_on): the causes on those joints are not confirmed in simulation");
    if (!without.empty())
      notes.push_back("rollouts of extended.xml end farther from the measured positions than the model as given on " + without.dump() +
                      " (rollout.worse_on), where no cause is named: what changed them is the causes of the joints they are coupled to, and a right "
                      "cause does so too (on 8 of 30 seed-table draws of a damping error, written within 1 % of the truth, a coupled joint rolled "
                      "out 6-34 % worse than with the model as given, as with the true model itself)");
    if (!out_dir.empty())
      csv = rollout_csv(before.joints, rollout_traces(opt_.model, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs, traced),
                        rollout_traces(ext_path, test_.split, opt_.rollouts, opt_.rollout_seconds, test_.runs, traced));
  } catch (const std::exception& e) {
    R["rollout"] = {{"skipped", e.what()}};
  }
  // Outside the try: a file that cannot be written is an error, not a skipped rollout.
  if (!csv.empty()) write_text_atomic((std::filesystem::path(out_dir) / "rollouts.csv").string(), csv);
}

}  // namespace spml::diagnose_detail
