#include "report.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <set>
#include <sstream>

namespace spml::diagnose_detail {
namespace {

std::string num(double v, int precision = 4) {
  std::ostringstream s;
  s.precision(precision);
  s << v;
  return s.str();
}
std::string pct(double v) { return num(100 * v, 3) + " %"; }

// "name value ± se (was prior)" lines of a cause's parameters.
// A key the data do not determine is shown to three figures and said so, without an error (one
// of equally good fits: LuGre's fs and vs on a log without break-away were printed with one); a
// value that extended.xml states otherwise (refitted with the parameters it writes) is shown
// beside it, and a joint term of `parameters` rejected on its joint says so.
// Named values as one phrase: "S1.c 5.011"; one level deeper for the model's own level a
// friction takes over (causes[].replaces_model_friction): "frictionloss 0.69" or
// "spml.plugin.c shoulder.fc 0.69".
std::string values_text(const nlohmann::json& own) {
  std::string out;
  for (const auto& [what, v] : own.items()) {
    if (v.is_number()) out += (out.empty() ? "" : ", ") + what + " " + num(v.get<double>());
    else
      for (const auto& [p, x] : v.items()) out += (out.empty() ? "" : ", ") + what + " " + p + " " + num(x.get<double>());
  }
  return out;
}

// A superseded cause: by the later effect named, or, where no single later one holds it,
// "redundant" in report.json - said in words here ("superseded by redundant" read as if an
// effect of that name had replaced it).
std::string superseded_text(const nlohmann::json& c) {
  const std::string by = c["superseded_by"].get<std::string>();
  return by == "redundant" ? "dropped: not needed beside the other causes" : "superseded by " + by;
}

std::string params_text(const nlohmann::json& c, const std::string& sep) {
  std::string out;
  const nlohmann::json loose = c.value("not_identifiable", nlohmann::json::array());
  // What extended.xml states: an effect's params_written; for `parameters`, the consistent fit's
  // joint terms (an armature estimated at -0.09 is written 0), except on joints whose terms were
  // rejected (left at the MJCF's).
  // A rejected cause is not in extended.xml: nothing of it is said to be there.
  const bool in_file = !c.contains("rejected");
  nlohmann::json written = in_file ? c.value("params_written", nlohmann::json::object()) : nlohmann::json::object();
  const nlohmann::json rejected = c.value("rejected_joint_terms", nlohmann::json::object());
  auto rejected_term = [&](const std::string& name) {   // "damping:joint6" on a joint whose terms were rejected
    const auto colon = name.rfind(':');
    return colon != std::string::npos && rejected.contains(name.substr(colon + 1));
  };
  if (in_file && c.contains("written") && c["written"].contains("terms"))
    for (const auto& [name, term] : c["written"]["terms"].items())
      if (term.contains("value") && !rejected_term(name)) written[name] = term["value"];
  for (auto it = c["params"].begin(); it != c["params"].end(); ++it) {
    const bool free = c["effect"] != "parameters" && std::find(loose.begin(), loose.end(), it.key()) != loose.end();
    out += (out.empty() ? "" : sep) + it.key() + " " + (free ? num(it.value().get<double>(), 3) + " (not identifiable)" : num(it.value().get<double>()));
    if (!free && c["stderr"].contains(it.key()) && c["stderr"][it.key()].is_number()) out += " ± " + num(c["stderr"][it.key()].get<double>(), 2);
    if (c.contains("prior") && c["prior"].contains(it.key())) out += " (MJCF: " + num(c["prior"][it.key()].get<double>()) + ")";
    if (written.contains(it.key()) && written[it.key()].is_number()) {
      const double v = it.value().get<double>(), w = written[it.key()].get<double>();
      if (std::fabs(w - v) > 1e-3 * std::fabs(v)) out += "; extended.xml: " + num(w);
    } else if (rejected_term(it.key())) {
      out += "; rejected, extended.xml keeps the MJCF's";
    } else if (in_file && c.contains("written") && c["written"].contains("listed_only")) {
      out += "; not written, extended.xml keeps the MJCF's";   // the listed terms alone (write_listed_terms)
    }
  }
  const nlohmann::json shape = c.value("shape", nlohmann::json::object());
  for (auto it = shape.begin(); it != shape.end(); ++it)
    out += (out.empty() ? "" : sep) + it.key() + " " + num(it.value().get<double>());
  return out;
}

// A named delay (not the logger's half tick, corrected without a name: its "before" differs
// in the third digit and says nothing).
bool delay_named(const nlohmann::json& r) { return r.contains("delay") && r["delay"].value("named", false); }

// "95 % of its residual's energy lies in the tenth of the rows at the upper end of its travel
// (q:J >= 1.93)": left_unexplained's `at_an_end`.
std::string at_an_end_text(const nlohmann::json& e) {
  const bool upper = e["end"] == "upper";
  return pct(e["energy"].get<double>()) + " of its residual's energy lies in the " + pct(e["rows"].get<double>()) + " of the rows at the " +
         (upper ? "upper" : "lower") + " end of its travel (" + e["input"].get<std::string>() + (upper ? " >= " : " <= ") +
         num(e["beyond"].get<double>(), 4) + ")";
}

// ", roll 13.4 % of its own": the joint farthest off relative to its own torque, where there
// are several. The pooled error weighs joints by their torque: a review's light wrist roll was
// 13.4 % off, 37 times its noise, behind a pooled 0.198 %.
std::string worst_joint_text(const nlohmann::json& per_joint) {
  std::string worst;
  double at = -1;
  for (const auto& [joint, rel] : per_joint.items())
    if (rel.is_number() && rel.get<double>() > at) worst = joint, at = rel.get<double>();
  return per_joint.size() > 1 && at >= 0 ? " (worst joint " + worst + ": " + pct(at) + " of its own)" : "";
}

}  // namespace

std::string report_summary(const nlohmann::json& r) {
  std::ostringstream s;
  s << "diagnose " << r["model"].get<std::string>() << " on " << r["data"].get<std::string>() << " (fit '"
    << r["fit_split"].get<std::string>() << "', test '" << r["test_split"].get<std::string>() << "')\n";
  s << "  model as given: relative error on test " << pct(r["baseline"]["rel_error_test_all"].get<double>())
    << worst_joint_text(r["baseline"]["rel_error_test"]) << "\n";
  int rank = 0;
  for (const auto& c : r["causes"]) {
    s << "  " << ++rank << ". " << c["effect"].get<std::string>();
    if (c["effect"] == "delay") s << " " << num(1e3 * c["params"]["seconds"].get<double>()) << " ms";   // #22
    else if (c["effect"] != "parameters") s << " on " << c["joints"][0].get<std::string>();
    else if (r.contains("statistics") && r["statistics"].contains("parameters_z"))   // the family-wise bar (selection.cc)
      s << " (" << c["params"].size() << " beyond " << num(r["statistics"]["parameters_z"].get<double>(), 3) << " standard errors)";
    s << "  (dBIC " << num(c["delta_bic"].get<double>(), 5) << ", test error after " << pct(c["rel_error_test_after_all"].get<double>()) << ")";
    if (c.contains("superseded_by")) s << "  " << superseded_text(c);
    if (c.contains("rejected")) s << "  REJECTED: " << c["rejected"].value("summary", "in simulation, rollouts worse with it");
    if (c.contains("nearest_candidate"))
      s << "  nearest candidate: " << c["nearest_candidate"]["joint"].get<std::string>() << " keeps structure it does not hold (unexplained)";
    if (c.contains("replaces_model_friction")) s << "  replaces the model's own level " << values_text(c["replaces_model_friction"]);
    if (c["effect"] != "parameters" && c.contains("not_identifiable") && !c["not_identifiable"].empty())   // an effect's keys (strings)
      s << "  not identifiable from these data: " << comma_list(c["not_identifiable"].get<std::vector<std::string>>());
    for (const auto& a : c.value("reads_as_well", nlohmann::json::array()))
      s << "  reads as well as " << a["effect"].get<std::string>() << " on " << a["joint"].get<std::string>() << " (the log cannot tell them apart)";
    s << "\n";
  }
  if (r["causes"].empty()) s << "  no cause found: nothing passes the evidence and held-out tests\n";
  if (r.contains("delay") && r["delay"].value("withheld", false))   // #22: measured, not trusted on these data
    s << "  delay " << num(1e3 * r["delay"]["seconds"].get<double>()) << " ms measured, not named: raw differences (see report.json delay.why)\n";
  s << "  final: relative error on test " << pct(r["final"]["rel_error_test_all"].get<double>()) << worst_joint_text(r["final"]["rel_error_test"])
    << "\n";
  for (const auto& c : r.value("cross", nlohmann::json::array()))
    s << "  cross " << c["data"].get<std::string>() << " '" << c["split"].get<std::string>() << "': " << pct(c["rel_error_given"].get<double>())
      << " as given" << (c.contains("rel_error_given_as_measured") && delay_named(r) ? " (" + pct(c["rel_error_given_as_measured"].get<double>()) + " before the delay's correction)" : "")
      << " -> " << pct(c["rel_error_final"].get<double>()) << " extended.xml\n";
  for (const auto& n : r["not_identifiable"]) s << "  not identifiable: " << n["joint"].get<std::string>() << "\n";
  for (const auto& u : r.value("unexplained", nlohmann::json::array()))   // #22
    if (u.contains("share"))
      s << "  unexplained on " << u["joint"].get<std::string>() << ": a GP on the residual explains " << pct(u["share"].get<double>())
        << " of it held out, mostly through " << u["inputs"][0].get<std::string>()
        << (u.contains("at_an_end") ? "; " + at_an_end_text(u["at_an_end"]) : std::string()) << "\n";
  for (const auto& l : r.value("left_unexplained", nlohmann::json::array()))   // #22
    s << "  left on " << l["joint"].get<std::string>() << ": "
      << (l.value("split", "") == "fit" ? pct(l["rel_error_fit"].get<double>()) + " of its torque on the fit split (" + pct(l["rel_error_test"].get<double>()) + " held out)"
                                        : pct(l["rel_error_test"].get<double>()) + " of its held-out torque")
      << ", held by no cause in extended.xml and not predicted from the logged states enough to be `unexplained`"
      << (l.contains("at_an_end") ? "; " + at_an_end_text(l["at_an_end"]) : std::string()) << "\n";
  for (const auto& f : r.value("at_resolution_floor", nlohmann::json::array()))
    s << "  at the encoders' floor on " << f["joint"].get<std::string>() << ": " << pct(f["rel_error_test"].get<double>())
      << " of its held-out torque left, what the positions' quantization alone leaves (RMS " << num(f["rmse_test"].get<double>()) << ", floor "
      << num(f["floor_rmse"].get<double>()) << ")\n";
  return s.str();
}

// " N·m", " rad", ... from report.json's joint_units; empty where the report has none.
static std::string unit_of(const nlohmann::json& r, const std::string& joint, const char* what) {
  if (!r.contains("joint_units") || !r["joint_units"].contains(joint)) return "";
  return " " + r["joint_units"][joint].value(what, "");
}

// The bodies `parameters`' listed terms name (m:flange, Iyy:hand + ...), beside its joints: a
// review's payload read "parameters on J1, J2" where the wrist and flange changed most.
static std::string parameter_bodies_text(const nlohmann::json& c) {
  std::set<std::string> bodies;
  const nlohmann::json joints = c.value("joints", nlohmann::json::array());
  const nlohmann::json params = c.value("params", nlohmann::json::object());   // bound: items() of a temporary outlives it
  for (const auto& [name, v] : params.items())
    for (const auto& subject : term_subjects(name))
      if (std::find(joints.begin(), joints.end(), subject) == joints.end()) bodies.insert(subject);
  std::string out;
  for (const auto& b : bodies) out += (out.empty() ? " and bodies " : ", ") + b;
  return out;
}

// What extended.xml holds of `parameters` (its `written`): the listed terms alone, or the
// consistent fit's bodies, those moved beyond two standard errors named with their mass and
// centre of mass (a review's cable was written as an upper arm of 12.45 kg for 4, which
// report.md showed only as base-parameter sums).
static std::string written_parameters_text(const nlohmann::json& w) {
  if (w.contains("listed_only")) return "   - extended.xml holds the terms above alone, every inertial the MJCF's\n";
  std::string changed;
  int bodies = 0;
  const nlohmann::json all = w.value("bodies", nlohmann::json::object());
  for (const auto& [name, b] : all.items()) {
    ++bodies;
    if (!b.value("changed", false)) continue;
    changed += std::string(changed.empty() ? "" : "; ") + name + " mass " + num(b["prior_mass"].get<double>()) + " → " + num(b["mass"].get<double>()) +
               " kg, centre of mass (" + num(b["com"][0].get<double>(), 3) + ", " + num(b["com"][1].get<double>(), 3) + ", " +
               num(b["com"][2].get<double>(), 3) + ")";
  }
  if (bodies == 0) return "";
  return "   - extended.xml holds " + std::to_string(bodies) + " bodies re-identified (the physically consistent fit)" +
         (changed.empty() ? ", none moved beyond two standard errors" : "; moved beyond two standard errors: " + changed) + "\n";
}

std::string report_markdown(const nlohmann::json& r, bool with_plots) {
  std::ostringstream s;
  s << "# spml diagnose\n\n";
  s << "- model: `" << r["model"].get<std::string>() << "`\n- data: `" << r["data"].get<std::string>() << "` (fit split `"
    << r["fit_split"].get<std::string>() << "`, " << r["rows"]["fit"] << " rows; test split `" << r["test_split"].get<std::string>()
    << "`, " << r["rows"]["test"] << " rows)\n";
  if (!r.value("extended_mjcf", "").empty()) s << "- extended model: `" << r["extended_mjcf"].get<std::string>() << "`\n";
  s << "\n## Residual per joint (test split)\n\n| joint | RMSE as given | RMSE final | rel. error as given | rel. error final |\n|---|---|---|---|---|\n";
  for (const auto& j : r["joints"]) {
    const std::string n = j.get<std::string>();
    const std::string u = unit_of(r, n, "torque");
    s << "| " << n << " | " << num(r["baseline"]["rmse_test"][n].get<double>()) << u << " | " << num(r["final"]["rmse_test"][n].get<double>()) << u
      << " | " << pct(r["baseline"]["rel_error_test"][n].get<double>()) << " | " << pct(r["final"]["rel_error_test"][n].get<double>()) << " |\n";
  }
  s << "| all | | | " << pct(r["baseline"]["rel_error_test_all"].get<double>()) << " | " << pct(r["final"]["rel_error_test_all"].get<double>()) << " |\n";
  if (r.contains("cross")) {
    s << "\n## Other records (not used for the selection): relative error, all joints\n\n| data | split | as given | after each cause (the fit's) | extended.xml |\n|---|---|---|---|---|\n";
    for (const auto& c : r["cross"]) {
      std::string steps;
      for (const auto& v : c["rel_error_after_each_cause"]) steps += (steps.empty() ? "" : " → ") + pct(v.get<double>());
      s << "| `" << c["data"].get<std::string>() << "` | " << c["split"].get<std::string>() << " | " << pct(c["rel_error_given"].get<double>())
        << (c.contains("rel_error_given_as_measured") && delay_named(r) ? " (" + pct(c["rel_error_given_as_measured"].get<double>()) + " before the delay's correction)" : "")
        << " | " << steps << " | " << pct(c["rel_error_final"].get<double>()) << " |\n";
    }
  }
  s << "\n## Causes, in the order chosen\n\n";
  if (r["causes"].empty()) s << "None: no candidate passed both the evidence test on the fit split and the held-out test.\n";
  int k = 0;
  for (const auto& c : r["causes"]) {
    s << ++k << ". **" << c["effect"].get<std::string>() << "**";
    std::string joints;
    for (const auto& j : c["joints"]) joints += (joints.empty() ? "" : ", ") + j.get<std::string>();
    if (c["effect"] == "parameters") joints += parameter_bodies_text(c);
    s << " on " << joints << " - ΔBIC " << num(c["delta_bic"].get<double>(), 5) << ", test error after "
      << pct(c["rel_error_test_after_all"].get<double>());
    if (c.contains("superseded_by")) s << " (" << superseded_text(c) << ")";
    if (c.contains("rejected")) s << " - **rejected, not in extended.xml**: " << c["rejected"].value("reason", "");
    if (c.contains("nearest_candidate")) s << " - **a nearest candidate**: " << c["nearest_candidate"]["why"].get<std::string>();
    if (c.contains("replaces_model_friction"))
      s << " - replaces the model's own friction level " << values_text(c["replaces_model_friction"]) << " (0 in extended.xml)";
    s << "\n   - " << params_text(c, "\n   - ") << "\n";
    if (c.value("written_as", "") == "mjcf") {   // a spring, viscous or Coulomb friction in MuJoCo's own terms (written_form.cc)
      const auto& m = c["mjcf"];
      s << "   - in extended.xml as MuJoCo's own attributes of joint " << m["joint"].get<std::string>() << ":";
      if (m.contains("damping")) s << " damping " << num(m["damping"].get<double>());
      if (m.contains("frictionloss")) s << " frictionloss " << num(m["frictionloss"].get<double>());
      if (m.contains("stiffness"))
        s << " stiffness " << num(m["stiffness"].get<double>()) << ", springref " << num(m["springref"].get<double>()) << " "
          << m["springref_unit"].get<std::string>();
      s << "\n";
    } else if (c.value("written_as", "") == "plugin") {
      s << "   - in extended.xml as an spml plugin declaration (plain MuJoCo ignores it)\n";
    }
    if (c.contains("written_form_check")) {
      const auto& w = c["written_form_check"];
      s << "   - its joint's fit-split error written as frictionloss " << pct(w["rel_error_fit_frictionloss"].get<double>()) << ", as the declaration "
        << pct(w["rel_error_fit_declaration"].get<double>()) << "\n";
    }
    if (c["effect"] == "parameters" && c.contains("written") && !c.contains("rejected")) s << written_parameters_text(c["written"]);
    if (c.contains("resolution")) s << "   - " << c["resolution"].get<std::string>() << "\n";
    for (const auto& a : c.value("reads_as_well", nlohmann::json::array()))
      s << "   - the torque this change states is what **" << a["effect"].get<std::string>() << "** on " << a["joint"].get<std::string>() << " would predict too ("
        << values_text(a["params"]) << ": " << pct(a["share"].get<double>()) << " of it): this log cannot tell the two apart; extended.xml writes the parameters, "
           "and a log that moves the joint differently (another posture of the joints above it, or a load) would decide\n";
    if (c.contains("not_identifiable") && !c["not_identifiable"].empty() && c["effect"] == "parameters")
      s << "   - not identifiable from this data: " << c["not_identifiable"].size() << " base parameter(s)\n";
  }
  if (r.contains("rollout") && r["rollout"].contains("position_error_before")) {
    const auto& ro = r["rollout"];
    s << "\n## Rollouts (" << ro["windows"] << " windows of " << num(ro["horizon_s"].get<double>()) << " s under the measured torques)\n\n"
      << "| joint | position error as given | extended |\n|---|---|---|\n";
    for (auto it = ro["position_error_before"].begin(); it != ro["position_error_before"].end(); ++it)
      s << "| " << it.key() << " | " << num(it.value().get<double>()) << unit_of(r, it.key(), "position") << " | "
        << num(ro["position_error_after"][it.key()].get<double>()) << unit_of(r, it.key(), "position") << " |\n";
  } else if (r.contains("rollout")) {
    s << "\nRollouts skipped: " << r["rollout"].value("skipped", "") << "\n";
  }
  if (!r["not_identifiable"].empty()) {
    s << "\n## Not identifiable\n\n";
    for (const auto& n : r["not_identifiable"]) s << "- " << n["joint"].get<std::string>() << ": " << n["reason"].get<std::string>() << "\n";
  }
  if (!r["not_tried"].empty()) {
    s << "\n## Not tried\n\n";
    for (const auto& n : r["not_tried"])
      s << "- " << n["effect"].get<std::string>() << (n.contains("joint") ? " on " + n["joint"].get<std::string>() : "") << ": "
        << n["reason"].get<std::string>() << "\n";
  }
  if (const auto un = r.value("unexplained", nlohmann::json::array()); !un.empty()) {   // #22
    s << "\n## Unexplained\n\n";
    for (const auto& u : un) {
      if (!u.contains("share")) continue;
      std::string inputs;
      for (size_t i = 0; i < u["inputs"].size() && i < 3; ++i) inputs += (inputs.empty() ? "`" : ", `") + u["inputs"][i].get<std::string>() + "`";
      s << "- " << u["joint"].get<std::string>() << ": a GP over the logged states predicts " << pct(u["share"].get<double>())
        << " of the residual extended.xml leaves there, held out (RMS " << num(u["rmse_test"].get<double>()) << unit_of(r, u["joint"].get<std::string>(), "torque")
        << " → " << num(u["rmse_test_with_gp"].get<double>()) << unit_of(r, u["joint"].get<std::string>(), "torque") << "), mostly through " << inputs
        << ": an effect no cause in the vocabulary holds"
        << (u.contains("at_an_end") ? "; " + at_an_end_text(u["at_an_end"]) + ": a stop, a limit or a contact there, or a reversal too sharp "
                                      "for the import's low-pass?" : std::string()) << "\n";
    }
  }
  if (const auto left = r.value("left_unexplained", nlohmann::json::array()); !left.empty()) {   // #22
    s << "\n## Left unexplained\n\n";
    for (const auto& l : left) {
      s << "- " << l["joint"].get<std::string>() << ": extended.xml leaves "
        << (l.value("split", "") == "fit" ? pct(l["rel_error_fit"].get<double>()) + " of its torque on the fit split (held out " +
                                                pct(l["rel_error_test"].get<double>()) + ", under the bar there: within 5 % or at the encoders' floor)"
                                          : pct(l["rel_error_test"].get<double>()) + " of its held-out torque")
        << "; no cause in it holds that, and a GP over the logged states does not predict enough of it to report it as `unexplained`: ";
      if (l.contains("at_an_end"))
        s << at_an_end_text(l["at_an_end"]) << ": a stop, a limit or a contact there (whose force changes over a few encoder counts, too "
             "steeply and in too few rows for the GP), or something only that end of the motion holds, such as a reversal too sharp for the "
             "import's low-pass\n";
      else
        s << "what is missing depends on something the log does not hold (a load, a command, a temperature), or on the "
             "states too steeply for the GP's rows (a rigid stop or contact, whose force changes over a few encoder counts), or, on a "
             "joint whose torque is small against its noise, it is noise\n";
    }
  }
  if (const auto floor = r.value("at_resolution_floor", nlohmann::json::array()); !floor.empty()) {
    s << "\n## At the encoders' floor\n\n";
    for (const auto& f : floor) {
      const std::string j = f["joint"].get<std::string>();
      s << "- " << j << ": extended.xml leaves " << pct(f["rel_error_test"].get<double>()) << " of its held-out torque (RMS "
        << num(f["rmse_test"].get<double>()) << unit_of(r, j, "torque") << "), what the positions' quantization alone leaves through the "
           "derived velocities and accelerations (" << num(f["floor_rmse"].get<double>()) << unit_of(r, j, "torque")
        << ", from the encoder steps spml import recorded): this log determines no more of the joint's torque; finer encoders, or a lower "
           "--lowpass where the motion allows, would\n";
    }
  }
  if (!r["notes"].empty()) {
    s << "\n## Notes\n\n";
    for (const auto& n : r["notes"]) s << "- " << n.get<std::string>() << "\n";
  }
  if (with_plots) s << "\n## Plots\n\n![residuals](plots/residuals.png)\n\n![states](plots/states.png)\n";
  if (with_plots && r.contains("rollout") && r["rollout"].contains("position_error_before")) s << "\n![rollouts](plots/rollouts.png)\n";
  if (with_plots && r.contains("rollout") && !r["rollout"].value("traced", nlohmann::json::array()).empty())   // rollouts.csv
    s << "\n![rollout trajectories](plots/rollouts_trajectories.png)\n";
  if (with_plots && r.value("unexplained", nlohmann::json::array()).size() > 0)   // #22
    s << "\n![unexplained](plots/unexplained.png)\n";
  return s.str();
}

}  // namespace spml::diagnose_detail
