// The state one diagnose run carries from stage to stage. Each stage lives in its own file, in
// the order the data flows:
//   load.cc        model, dataset, splits (fit / test / cross)
//   runs.cc        several records of one robot stacked, their boundaries kept
//   prepare.cc     one split made ready: columns, base regressor, targets, the model's prediction,
//                  the parallel filter (filtering.cc)
//   estimate.cc    least-squares refits of the base parameters and causes, residuals on any split
//   candidates.cc  the force plugins as candidate causes, and their regressor columns
//   shape_search.cc  the shape of one candidate (grid, zoom, plateau middle, local polish)
//   selection.cc   forward selection, backward elimination, the `parameters` decision
//   written_parameters.cc  the physically consistent parameters extended.xml states
//   written_form.cc  a spring and viscous friction written as MuJoCo's stiffness/springref and damping
//   confirm.cc     causes whose written form makes rollouts worse (and whose removal mends them) are rejected
//   verify.cc      the written model: extended.xml, its own inverse dynamics, rollouts (rollouts.csv)
//   report_json.cc report.json (causes, metrics, cross-tests) and series.csv
// Issue #22 (stages of their own, hooked in where marked "#22"):
//   delay.cc       an offset between torques and states, estimated and corrected first
//   stateful_fit.cc  stateful plugins (LuGre stick_slip) fitted by simulation along the log
//   unexplained.cc the GP (ARD) on the final residual: structure no candidate explains
// own_friction.cc  the model's own friction level on a joint, taken over by a named friction
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <map>
#include <sstream>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "design.h"
#include "spml/envs/mjcf_edit.h"
#include "filtering.h"
#include "report.h"
#include "spml/diagnose.h"
#include "spml/envs/consistent_identification.h"
#include "spml/envs/mjcf_regressor.h"
#include "spml/force_effects.h"

namespace spml::diagnose_detail {

using Clock = std::chrono::steady_clock;
using Declarations = std::vector<std::pair<std::string, std::string>>;   // <custom><text> name and data, as MjcfEdits::texts
inline double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::string fmt(double v, int precision = 4);
std::string integer_text(double v);

// Root mean square of a stacked vector (0 when empty).
inline double rms(const Eigen::VectorXd& v) { return v.size() ? std::sqrt(v.squaredNorm() / static_cast<double>(v.size())) : 0.0; }

// A model as given (or one of its declared forces) predicting torques this many times the
// measured ones' RMS is refused: a value off by orders of magnitude leaves nothing to diagnose,
// and beyond it squares overflow and every score is NaN.
constexpr double kAbsurdTorqueRatio = 1e6;

// One split as diagnose uses it: its rows, the stacked base regressor, the stacked torques and
// what the model as given predicts.
struct SplitData {
  std::string name;
  Split split;
  std::unique_ptr<JointColumns> cols;
  BlockColumns base;
  Eigen::VectorXd b, given, y0;   // targets, prediction of the model as given, b - given
  // What the model as given adds beyond its regressor, stacked (in given; empty: none): MuJoCo's
  // frictionloss torque - the regressor's fl*sign(qd), and the forces of declared plugins that
  // have no regressor columns (stateful or nonlinear: simulated along the split as declared).
  Eigen::VectorXd friction;
  Eigen::VectorXd soft;        // MuJoCo's frictionloss beyond its ideal level (part of friction; empty: none)
  Eigen::VectorXd own_level;   // the model's own friction levels per output, stacked (own_friction.cc; empty: none)
  Eigen::Index N = 0;
  ParallelFilter sos;             // the parallel filter on this split's time base (empty: none)
  std::vector<Eigen::Index> runs; // first rows of the records after the first (several --data)
  const SplitData* continues = nullptr;   // the split whose record this one continues (a hold-out from its end; stateful plugins carry their state)
};

// A candidate cause: one plugin on one joint, with its shape chosen.
struct Candidate {
  const spml_force_plugin* plugin = nullptr;
  int joint = -1;                 // model joint index
  std::string joint_name;
  std::vector<const spml_shape_param*> shape;
  std::vector<std::pair<std::string, std::string>> fixed;   // non-shape keys it is made with
  std::vector<double> shape_values;                         // absolute values, chosen
  std::vector<std::pair<double, double>> shape_range;       // absolute search range
  BlockColumns fit_cols;
  bool searched = false;
  bool skipped = false;           // its plugin failed (non-finite columns): not a candidate
  Gain gain;
  double delta_bic = -std::numeric_limits<double>::infinity();
  // #22: a stateful plugin fitted by simulation (stateful_fit.cc): every key is a shape value,
  // fit_cols is its simulated force (one column).
  bool stateful = false;
  std::vector<double> stateful_se;            // per shape key, absolute
  Eigen::MatrixXd stateful_cov;               // per pair of shape keys, absolute (stateful_errors); infinite on a key that does not move the force
  std::vector<std::string> not_identifiable;  // keys with a relative standard error above 50 %, or that far apart between equally good fits
  bool profiled = false;                      // profile_once ran
  bool transients_checked = false;            // mark_short_transients ran
  double written_scale = 1;                   // the written model's factor on its levels (refit_written_effects)
  std::vector<bool> at_edge;                  // per shape key: a side of it the plugin refuses at the fit (stateful_errors)
  std::string refusal;                        // profile_once: why the profile says it is not this effect (empty: it may be)
  bool break_away_loose = false;              // joins only by rolling out closer (rolls_out_better): a small loose gap of a level (profile_once), a key at an end (settle_levels)
  std::string at_range_end;                   // settle_levels: the keys at an end of their range or at the plugin's edge
  std::string lost_to_static;                 // the last held-out comparison it lost to the static frictions (note_lost), for not_tried
  std::string resolution;                     // profile_once: the Stribeck hump's loose keys, the speeds the parallel filter resolves, and a band that resolves more; keys of a transient shorter than it resolves

  // Is key (of shape key k) in not_identifiable; put it there once.
  bool loose(const std::string& key) const { return std::find(not_identifiable.begin(), not_identifiable.end(), key) != not_identifiable.end(); }
  bool loose(size_t k) const { return loose(shape[k]->key); }
  void mark_loose(const std::string& key) {
    if (!loose(key)) not_identifiable.push_back(key);
  }
};

bool is_stateful(const spml_force_plugin& p);   // #22: advance/reset and no regressor
// Whether a candidate's plugin calls must stay on one thread (parallel_for's `serial`): unless
// its library flags the instances independent, each thread then walking its own.
inline bool one_thread(const Candidate& c) { return !force_plugin_independent(*c.plugin); }

// `parameters`' part of the edits: joint attributes, body inertials, and the declared plugins'
// own texts with their re-identified parameters (identified_model_edits).
// A cause of report.json that extended.xml holds: neither superseded by a later one nor rejected.
inline bool kept_cause(const nlohmann::json& c) { return !c.contains("superseded_by") && !c.contains("rejected"); }
inline bool writes_parameters(const MjcfEdits& e) { return !e.joint_attributes.empty() || !e.inertials.empty() || !e.replaced_texts.empty(); }
inline void drop_parameters(MjcfEdits& e) {
  e.joint_attributes.clear();
  e.inertials.clear();
  e.replaced_texts.clear();
}

// The <custom><text> name a named effect is declared under in extended.xml.
inline constexpr const char* kDiagnosedPrefix = "spml.plugin.diagnosed_";
inline std::string declaration_name(const Candidate& c) { return kDiagnosedPrefix + std::string(c.plugin->name) + "_" + c.joint_name; }
// Its declaration in extended.xml, with the plugin's own configuration text.
inline std::string declaration_text(const Candidate& c, const std::string& config) {
  return "type=" + std::string(c.plugin->name) + " joints=" + c.joint_name + " " + config;
}

// Does a velocity change sign between two consecutive rows (through zero or onto it)? A
// reversal, for every rule that looks at rows near one.
inline bool reverses(double before, double after) { return (before > 0 && after <= 0) || (before < 0 && after >= 0); }

// #22: a delay worth correcting removes a tenth of the held-out residual (delay.cc).
inline constexpr double kMinDelayGain = 0.1;

// #22: the offset between torques and states (delay.cc).
// #22: the box a stateful candidate is searched in (logarithms of its keys), and which keys are
// levels (stateful_fit.cc).
struct StatefulSpace {
  std::vector<double> lb, ub;
  std::vector<bool> level;
};

struct DelayResult {
  double seconds = 0, stderr_ = std::numeric_limits<double>::infinity(), delta_bic = 0, range = 0;
  double band_hz = 0;        // the search's low-pass (search_band; 0: the data's whole band)
  bool named = false;
  bool withheld = false;   // evidence and held-out gain pass, but the data cannot be trusted with it (raw differences)
  bool corrected = false;  // not named (an offset of 0.2-1 ms, the logger's half tick), but resolved and corrected
  std::string why;
  Eigen::VectorXd y0_fit, y0_test;   // the fit and test targets before the correction (baseline)
  // Each corrected split's torques, targets and residual of the other side of the correction
  // (swap_delay: before it while corrected, after it while not).
  struct Other {
    SplitData* split;
    Eigen::MatrixXd Y;
    Eigen::VectorXd b, y0;
  };
  std::vector<Other> other;
  std::string note;                  // the note that says it was corrected
  std::vector<std::pair<std::string, std::pair<double, double>>> own;   // each joint's own offset and standard error (estimate_delay) ...
  double own_about = 0;                                                   // ... to first order about this first estimate
  std::vector<std::string> left_out; // joints whose own offset disagreed, left out of the search
};

// The delay search's signals on a split, through the search's band (delay.cc, delay_signals).
struct DelaySignals {
  BlockColumns base;
  std::vector<BlockColumns> nuisance;
  Eigen::VectorXd torques;   // net of MuJoCo's frictionloss correction
};

// The delay search's stacked residual at an offset and its derivative there (delay.cc).
struct ShiftSlope {
  Eigen::VectorXd r, J;
};

struct Cause {
  int candidate;
  double delta_bic;
  std::string superseded_by;
};

// The model's own dry-friction level on a joint (own_friction.cc): MuJoCo's frictionloss and
// the declared plugin parameters whose force there is a pure level.
struct OwnLevel {
  double frictionloss = 0;
  double declared = 0;                         // the plugin parameters' level together
  std::vector<std::pair<size_t, int>> params;  // (declared instance, its parameter index)
  std::vector<std::string> names;              // their standard parameter names (coulomb:j, plugin:...)
  bool any() const { return frictionloss != 0 || declared != 0; }
};

// The base block and targets of a fit with some causes (own_friction.cc: taken_base).
struct TakenBase {
  std::optional<BlockColumns> base;   // the base without the own levels the causes take over (none: fit_.base)
  Eigen::VectorXd y;                  // the targets, those levels' force returned
};

// A selection's state (select() makes two and keeps one): the candidates as searched, the
// causes chosen, what was not tried.
struct Selection {
  std::vector<Candidate> cands;
  std::vector<Cause> causes;
  nlohmann::json not_tried;
};

// What the offset searched again beside the chosen stateful causes is (offset_beside): the
// first estimate (put back), the same named delay better estimated (the causes stand), or
// another kind of offset (the causes are chosen again).
enum class OffsetBeside { same, refined, changed };

// The parameters extended.xml states when `parameters` is named (written_parameters.cc).
struct WrittenParameters {
  ConsistentIdentification id;      // standard parameters; id.extra: the kept effects' coefficients
  Eigen::VectorXd prediction_fit;   // its torques on the fit split (through the parallel filter)
  bool two_stage = false;           // fitted on the columns projected onto the iv instruments
  Eigen::VectorXd joint_weights;    // each joint's row weight in that fit (design.h: output_weights)
};
nlohmann::json written_parameters_json(const WrittenParameters& w, const std::vector<std::string>& joints);

// The edits as extended.xml holds them (written_form.cc): diagnosed `spring` and `viscous`
// declarations turned into the joint's stiffness/springref and damping.
struct WrittenForm {
  MjcfEdits edits;                                  // what edit_mjcf gets
  std::map<std::string, nlohmann::json> as_mjcf;    // declaration data -> the joint attributes it became
  std::map<std::string, std::string> kept_why;      // declaration data -> why it stays a plugin text
};
// The edits with every diagnosed spring (stiffness k > 0 in total) and viscous declaration
// (damping >= 0 in total) on a hinge or slide joint of m turned into that joint's attributes, on
// top of what the edits already write there or else m's own values; `degrees`: the file states
// hinge angles in degrees (springref is written in them); `defined`: the joints the file itself
// defines (others keep their declarations: their attributes cannot be written);
// `frictionloss_joints`: the joints whose diagnosed exact Coulomb level (coulomb, smooth 0) is
// written as MuJoCo's frictionloss, on top of the joint's own, when that total is >= 0 (the
// form is chosen by the data: Diagnosis::choose_coulomb_form).
WrittenForm mujoco_form(const mjModel* m, bool degrees, const std::vector<std::string>& defined, const MjcfEdits& edits,
                        const std::set<std::string>& frictionloss_joints = {});

// "effect@joint" (or "parameters") of every cause rejected in simulation (confirm.cc).
nlohmann::json rejected_causes(const nlohmann::json& causes);

// The split with its torque columns in `order` (matched by name); throws naming `file` when
// the names differ.
Split in_column_order(const Split& s, const std::vector<std::string>& order, const std::string& file);


// Evidence for the larger of two nested fits (Bayesian information criterion, n equations -
// the effective number where residuals are autocorrelated - dk more parameters): positive when
// the drop of the residual sum of squares pays for them. Sums of squares below `floor` (the
// rounding level of the targets) count as `floor`: exact data give no evidence from rounding.
double delta_bic(double n, double rss_smaller, double rss_larger, double dk, double floor);
// The Wald statistic of the fit's coefficients at..at+cols against zero under its covariance
// (the determined ones; directions the covariance leaves unbounded count nothing).
double wald(const Fit& f, Eigen::Index at, Eigen::Index cols);

// The held-out test: the residual sum of squares falls by at least the fraction min_gain
// (sums below `floor` count as `floor`).
bool gains_on_test(double rss_before, double rss_after, double min_gain, double floor);
// The delay's held-out test (delay.cc): the residual `after` (the shift applied) removes
// `min_gain` of `before`'s sum of squares, or of the geometric mean of each joint's own
// (per_output_ratio) with at least half the joints gaining it on their own, counted over the
// outputs with rows weighed in w (N rows each).
bool delay_gains_on_test(const Eigen::VectorXd& before, const Eigen::VectorXd& after, const Eigen::VectorXd& w, const Eigen::VectorXd& b,
                         Eigen::Index N, double min_gain);
// Which outputs' own offsets (seconds, standard error) agree on one delay (delay.cc).
std::vector<bool> agreeing_outputs(const std::vector<std::pair<double, double>>& own, size_t least);

// The held-out likelihood with one noise variance per joint: the geometric mean over outputs
// (N rows each) of the residual `after`'s sum of squares relative to `before`'s, each output's
// sums below the rounding level of its part of b counting as that level; 1 for no outputs.
double per_output_ratio(const Eigen::VectorXd& after, const Eigen::VectorXd& before, const Eigen::VectorXd& b, Eigen::Index N);
// Each output's ratio of the geometric mean above, in output order.
std::vector<double> output_ratios(const Eigen::VectorXd& after, const Eigen::VectorXd& before, const Eigen::VectorXd& b, Eigen::Index N);
// exp of the mean log (1 for none).
double geometric_mean(const std::vector<double>& x);

// The rounding level of a stacked target b: (1e-8 |b|)^2, far below any measured residual.
inline double rss_floor(const Eigen::VectorXd& b) { return 1e-16 * b.squaredNorm(); }

class Diagnosis {
 public:
  explicit Diagnosis(const DiagnoseOptions& o) : opt_(o) {}
  DiagnoseResult run(const std::string& out_dir);

 private:
  // load.cc
  void load();
  void choose_splits(const Dataset& ds, const std::string& file, Split& fit_part, Split& test_part);
  // runs.cc
  void load_more_records(Split& fit_part, Split& test_part, std::vector<Eigen::Index>& fit_runs, std::vector<Eigen::Index>& test_runs);
  void load_cross();
  void map_outputs();
  void note_frictionloss();
  void note_limits();
  Eigen::VectorXd frictionloss_correction(const SplitData& d, const mjModel* m) const;
  void add_declared_forces(const SplitData& d, Eigen::VectorXd& into) const;
  // prepare.cc
  // `filtered` false: the parallel filter is not applied (a replay at the import's own rate, chain_bias.cc).
  SplitData prepare(const Split& s, const std::vector<Eigen::Index>& runs = {}, const SplitData* continues = nullptr, bool filtered = true);
  void plan_parallel_filter();
  void weigh_second_pass();
  void apply_filter(SplitData& d) const;
  // candidates.cc
  void find_candidates();
  void add_candidates(const spml_force_plugin& p, const std::vector<const spml_shape_param*>& shape,
                      const std::vector<std::pair<std::string, std::string>>& fixed);
  bool bound_wavenumber(Candidate& c, double stroke, double median_speed);
  std::vector<std::pair<std::string, std::string>> config_of(const Candidate& c, const std::vector<double>& shape) const;
  BlockColumns columns(const PluginInstance& inst, const SplitData& s, bool filtered = true) const;
  BlockColumns columns_of(const Candidate& c, const SplitData& s) const;
  // "" when the plugin accepts its fitted parameters (written back through write_config and
  // created again), else its reason: a negative band level is not a friction band.
  // `damping`: the joint's damping the fit stands beside (NaN: the MJCF's), see within_damping.
  std::string refused(int candidate, const Eigen::VectorXd& theta, double damping = std::numeric_limits<double>::quiet_NaN()) const;
  double refitted_damping(int joint, const Fit& f) const;   // NaN when damping is no base parameter of its own
  static std::string outside_its_form(const Candidate& c, const Eigen::VectorXd& theta);
  std::string injects_energy(const Candidate& c, const Eigen::VectorXd& theta, double damping) const;
  bool within_damping(const Eigen::VectorXd& col, int joint, double coef, double damping) const;
  Eigen::Ref<const Eigen::VectorXd> fit_qd(Eigen::Index output) const;   // the fit split's q̇ of an output's joint
  bool opposes_motion(const Eigen::VectorXd& col) const;   // its force opposes q̇ at every row, and acts at one
  double rate_of(const Eigen::VectorXd& col) const;        // s when col = s q̇ wherever it is nonzero, else 0
  // shape_search.cc
  double search_shape(Candidate& c, const Fit& current);
  // estimate.cc
  std::vector<const BlockColumns*> blocks(const std::vector<int>& causes, bool base_free) const;
  Fit refit(const std::vector<int>& causes, bool base_free, bool robust = false, const Eigen::VectorXd* weights = nullptr) const;
  Eigen::VectorXd residual_on(const SplitData& s, const std::vector<int>& causes, bool base_free, const Fit& f) const;
  double rss_on(const Eigen::VectorXd& r, const std::vector<int>& outputs, Eigen::Index N) const;
  std::vector<int> outputs_of(int candidate) const;
  // selection.cc
  void select();
  void forward_backward();
  void score_candidates(const Fit& current, const std::vector<int>& chosen, const std::set<int>& research, std::vector<int>& order);
  bool nests(int larger, int smaller) const;
  std::vector<int> in_place(int candidate, const std::vector<int>& chosen) const;
  bool dissipates(const Candidate& c) const;
  bool evidence_holds(int candidate, const Fit& smaller, const Fit& larger) const;
  bool cause_needed(size_t i, const std::vector<size_t>& set, bool base_free) const;
  void eliminate_backward(bool base_free = true);
  void decide_parameters();
  // `on`: a split prepared like the fit split (chain_bias.cc's replay) fitted in its place, on the same instruments.
  Fit iv_refit(const std::vector<int>& causes, const Eigen::VectorXd& mask = Eigen::VectorXd(), const SplitData* on = nullptr);
  Eigen::VectorXd away_from_reversals(double* half_width_s = nullptr) const;
  std::vector<int> kept_effects() const;
  // report_json.cc
  nlohmann::json metrics(const Eigen::VectorXd& r_fit, const Eigen::VectorXd& r_test) const;
  nlohmann::json per_joint(const Eigen::VectorXd& r, Eigen::Index N) const;
  nlohmann::json cross_errors(const std::vector<int>& causes, bool base_free, const Fit& f) const;
  void build_report(const std::string& out_dir);
  nlohmann::json parameters_cause(MjcfEdits& edits, std::vector<std::string>& notes) const;
  nlohmann::json reads_as_well(const Eigen::VectorXd& change, const std::set<std::string>& joints) const;
  nlohmann::json effect_cause(size_t i, const Fit& final_fit, bool free, MjcfEdits& edits, std::vector<std::string>& notes,
                              nlohmann::json& cross_after) const;
  nlohmann::json cross_report(const Fit& final_fit, bool free, const nlohmann::json& cross_after) const;
  void write_series(const std::string& out_dir, const Eigen::VectorXd& final_pred_fit, const Eigen::VectorXd& final_test) const;
  // written_parameters.cc
  WrittenParameters consistent_parameters() const;
  // written_form.cc
  WrittenForm written_form(const MjcfEdits& edits) const;
  // `takers`: the edits whose causes take over their joints' own levels (own_friction.cc; default: edits)
  std::string write_model(const MjcfEdits& edits, std::vector<std::string>& notes, const MjcfEdits* takers = nullptr) const;
  nlohmann::json report_written_form(const MjcfEdits& edits, std::vector<std::string>& notes);
  void choose_coulomb_form(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes,
                           std::pair<Eigen::VectorXd, Eigen::VectorXd>& written);
  // confirm.cc
  bool confirm_in_simulation(const std::string& ext_path, MjcfEdits& edits);
  void note_rejections(const MjcfEdits& edits, std::vector<std::string>& notes);
  // delay.cc (#22)
  void estimate_delay();
  ShiftSlope shift_slope(double d, const std::function<Eigen::VectorXd(double)>& projected) const;
  std::vector<std::pair<double, double>> offsets_per_output(double d, const ShiftSlope& at) const;
  void delay_decide(double d, const ShiftSlope& at, const std::function<Eigen::VectorXd(double)>& projected,
                    const DelaySignals& fit, const Eigen::VectorXd& wf);
  double search_band() const;
  ParallelFilter search_filter(const SplitData& s) const;
  DelaySignals delay_signals(const SplitData& s) const;
  double uniform_step(const SplitData& s) const;
  Eigen::VectorXd targets_at(const SplitData& s, double d) const;
  Eigen::VectorXd net_of_frictionloss(const SplitData& s) const;
  BlockColumns coulomb_nuisance(const SplitData& s) const;
  std::vector<BlockColumns> delay_nuisance(const SplitData& s) const;
  Eigen::VectorXd sliding_rows(const SplitData& s, double band_hz = 0) const;
  BlockColumns offset_column(const SplitData& s) const;
  OffsetBeside offset_beside(const std::vector<int>& stateful, DelayResult& first);
  void choose(const Selection& fresh);
  Selection set_aside(const Selection& fresh);
  Selection choose_again(const Selection& fresh);
  void restore(Selection&& s);
  void swap_delay();
  void drop_delay(bool rivals);
  double free_parameters(const std::vector<int>& causes, const Fit& f) const;
  nlohmann::json delay_report() const;
  nlohmann::json delay_cause() const;
  // stateful_fit.cc (#22)
  void add_stateful_candidates(const spml_force_plugin& p);
  BlockColumns simulated_columns(const PluginInstance& inst, const SplitData& s, bool filtered = true) const;
  double stateful_drop(const Candidate& c, const Fit& current, const std::vector<double>& x, Eigen::VectorXd* force = nullptr) const;
  std::vector<double> drops_at(const Candidate& c, const Fit& current, const std::vector<std::vector<double>>& points) const;
  void fit_stateful(Candidate& c, const Fit& current);
  std::map<std::string, double> static_start(const Candidate& c, const Fit& current) const;
  double scan_shape_keys(const Candidate& c, const Fit& current, const std::vector<bool>& level, const std::vector<double>& lb,
                         const std::vector<double>& ub, std::vector<double>& x) const;
  void polish_stateful(const Candidate& c, const Fit& current, const std::vector<double>& lb, const std::vector<double>& ub,
                       std::vector<double>& x, const std::vector<bool>& held = {}, int evals_per_key = 0) const;   // 0: the full polish
  std::vector<std::string> profile_stateful(const Candidate& c, const Fit& current, const std::vector<bool>& level,
                                            const std::vector<double>& lb, const std::vector<double>& ub, const std::vector<double>& x) const;
  std::vector<double> grid_start(const Candidate& c, const Fit& current, const std::vector<bool>& level, const std::vector<double>& lb,
                                 const std::vector<double>& ub, const std::vector<double>& x) const;
  int stateful_rival(int accepted, const std::vector<int>& order, const std::vector<int>& chosen, Fit& next, Eigen::VectorXd& next_test);
  void settle_levels(Candidate& c, const Fit& current, const std::vector<bool>& level, std::vector<double>& x);
  bool is_level(const spml_shape_param* sp) const;
  StatefulSpace stateful_space(const Candidate& c) const;
  void profile_once(int k, const Fit& current);
  int principal_level(const Candidate& c, const std::vector<bool>& level) const;
  bool gap_loose(const Candidate& c, size_t k, size_t principal) const;
  std::vector<Eigen::Index> reversal_rows(int joint) const;
  double reversal_crossing(int joint, double v) const;
  bool unresolved_speed(int joint, double v) const;
  double key_transient(const Candidate& c, size_t k, const Eigen::MatrixXd& fitted, const std::vector<Eigen::Index>& reversals) const;
  void mark_short_transients(Candidate& c);
  std::string resolution_note(int joint, const std::string& keys) const;
  bool shaped(const Candidate& c) const;
  bool beats_static(const Candidate& c, double bar, double rss) const;
  double stateful_gain(const Candidate& c) const;   // the held-out gain beats_static asks of it
  void note_lost(int k, double bar, double rss, double gain);
  void refuse_profiled(int k);
  bool stateful_joins(int k, const Fit& current, const std::vector<int>& chosen, double bar, double rss, const std::vector<int>& rivals,
                      const std::vector<int>& beside);
  Declarations declared(const std::vector<int>& causes, const Fit& f) const;
  bool holds_level_friction(const Candidate& c) const;
  std::pair<Eigen::Index, Eigen::Index> level_friction_columns(const Candidate& c) const;
  bool rolls_out_better(int k, const std::vector<int>& rivals, const std::vector<int>& beside);
  void chosen_around(int k, const std::vector<int>& chosen, std::vector<int>& nested, std::vector<int>& beside) const;
  double static_bar(int joint, const std::vector<int>& order, const std::vector<int>& chosen, const Fit& before, const std::vector<int>& outs,
                    double bar, int except = -1, std::vector<int>* passing = nullptr) const;
  BlockColumns key_columns(const Candidate& c, std::vector<size_t>* keys = nullptr, const std::vector<bool>& only = {}) const;
  std::vector<double> scaled_keys(const Candidate& c, double a) const;
  bool scales_with_keys(const Candidate& c) const;
  void stateful_errors(Candidate& c, const Fit& current, const std::vector<double>& x) const;
  void stateful_keys(const Candidate& c, nlohmann::json& params, nlohmann::json& se) const;
  void stateful_report(const Candidate& c, double amplitude, nlohmann::json& params, nlohmann::json& se, nlohmann::json& j) const;
  Eigen::VectorXd written_stateful(const SplitData& s, const mjModel* ext) const;
  // own_friction.cc
  void find_own_levels();
  Eigen::VectorXd own_level_force(const SplitData& s, const Eigen::VectorXd& soft) const;
  bool takes_over(int k) const;
  std::vector<int> taken_over(const std::vector<int>& causes) const;
  Eigen::VectorXd returned_levels(const SplitData& s, const std::vector<int>& causes) const;
  bool own_level_parameter(int i, const std::vector<int>& joints) const;
  std::optional<BlockColumns> base_without_taken(const BlockColumns& base, const std::vector<int>& causes) const;
  TakenBase taken_base(const std::vector<int>& causes, const SplitData* on = nullptr) const;
  bool taken_level(int i, const std::vector<int>& causes) const;
  Fit level_held(int k, const Fit& current, const std::vector<int>& chosen) const;
  MjcfEdits with_take_over(const MjcfEdits& e, const MjcfEdits* takers = nullptr) const;
  nlohmann::json replaced_friction(int k) const;
  // unexplained.cc (#22)
  nlohmann::json unexplained_joint(size_t o, const Eigen::VectorXd& r_fit, const Eigen::VectorXd& r_test, std::ostringstream& csv) const;
  nlohmann::json unexplained(const std::string& out_dir, const Eigen::VectorXd& r_fit, const Eigen::VectorXd& r_test) const;
  nlohmann::json left_unexplained(nlohmann::json& report, const Eigen::VectorXd& r_fit, const Eigen::VectorXd& r_test) const;
  // quantization.cc: the positions' quantization replayed through the import's chain
  struct Requantized {
    std::vector<RowMatrix> states;   // per grid offset: the split's states with a fresh quantization error
    Eigen::Index edge_rows = 0;      // rows at each record's ends the chain's start-up reaches
  };
  Requantized requantized(const SplitData& split, const std::vector<double>& offsets) const;
  std::map<std::string, double> resolution_floor(const SplitData& split) const;
  bool residual_at_floor(const std::string& joint, const Eigen::VectorXd& r) const;
  double low_band_share(const Eigen::VectorXd& r) const;
  nlohmann::json end_of_travel(const std::string& joint, const Eigen::VectorXd& r) const;
  void mark_nearest_candidates(nlohmann::json& report, const Eigen::VectorXd& r_test) const;
  std::set<std::string> nearest_candidate_joints(const std::pair<Eigen::VectorXd, Eigen::VectorXd>& written,
                                                 const std::set<std::string>& among) const;
  // chain_bias.cc: the import's and diagnose's processing replayed on the model's own motion
  struct ImportChain {   // what the dataset records spml import ran its columns through
    std::optional<LowpassRecord> lowpass;
    DecimationRecord decimation;
    int keep() const { return std::max(decimation.keep, 1); }
  };
  ImportChain import_chain() const;
  Eigen::Index chain_edge_rows(const SplitData& s) const;
  std::unique_ptr<SplitData> replayed_chain(const SplitData& s, std::string& why);
  std::optional<Eigen::VectorXd> chain_bias(const std::vector<int>& causes, const Eigen::VectorXd& mask = Eigen::VectorXd());
  // verify.cc
  std::pair<Eigen::VectorXd, Eigen::VectorXd> verify(const std::string& out_dir, MjcfEdits& edits, std::vector<std::string>& notes,
                                                     const Eigen::VectorXd& final_pred_fit);
  std::pair<Eigen::VectorXd, Eigen::VectorXd> write_scored(const std::string& ext_path, MjcfEdits& e, std::vector<std::string>& n);
  void choose_partial(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes,
                      std::pair<Eigen::VectorXd, Eigen::VectorXd>& written);
  bool write_listed_terms(MjcfEdits& edits, bool every, const std::string& why);
  void restore_superseded(size_t rejected, size_t first, MjcfEdits& edits, std::vector<std::string>& notes);
  bool refit_written_effects(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes);
  bool guard_held_out(const std::string& ext_path, MjcfEdits& edits, std::vector<std::string>& notes,
                      std::pair<Eigen::VectorXd, Eigen::VectorXd>& written);
  void run_rollouts(const std::string& ext_path, const std::string& out_dir, std::vector<std::string>& notes);
  Eigen::VectorXd written_prediction(const MjcfRegressor& ext, const MjcfRegressor::Base& ebase, const SplitData& s) const;

  DiagnoseOptions opt_;
  DiagnoseResult result_;
  std::unique_ptr<MjcfRegressor> reg_;
  std::unique_ptr<ForceEffects> declared_;   // the model's own plugin declarations (add_declared_forces)
  MjcfRegressor::Base base_;
  Dataset ds_;
  std::string test_name_;
  bool held_out_from_fit_ = false;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> washout_;   // #22: (first row, rows) of the fit split a stateful fit leaves out (load.cc)   // the test split is the last rows of the fit split's record (choose_splits)
  SplitData fit_, test_;
  std::vector<std::pair<std::string, SplitData>> cross_;   // (file, split)
  std::vector<std::string> out_joints_;   // per output: joint name
  std::vector<int> out_joint_index_;      // per output: model joint index
  std::vector<bool> still_;               // per model joint
  std::vector<OwnLevel> own_levels_;      // per model joint (own_friction.cc)
  std::vector<Candidate> cands_;
  nlohmann::json not_tried_ = nlohmann::json::array();
  std::vector<Cause> causes_;
  bool parameters_named_ = false;
  double parameters_delta_bic_ = 0, parameters_n_eff_ = 0;
  double parameters_delta_bic_per_joint_ = 0;   // one noise variance per joint (decide_parameters)
  int parameters_contradicted_ = 0;
  int parameters_contradicted_away_ = -1;   // ... of them, by the rows away from velocity reversals (-1: not checked)
  std::vector<bool> parameters_listed_;     // per base parameter: contradicted, there too where checked (`parameters`' list)
  Eigen::VectorXd written_weights_;     // decide_parameters: each output's row weight in the written fit (design.h: output_weights)
  double parameters_z_ = 3;             // the standard errors beyond which a base parameter contradicts the MJCF (decide_parameters)
  Fit parameters_fit_;                  // the free fit whose estimates decide `parameters` (ls or iv)
  std::string parameters_estimator_;    // "ls" or "iv", as it ran
  std::unique_ptr<SplitData> twin_;     // iv: the fit split on the model's simulated states
  std::unique_ptr<SplitData> replayed_; // the fit split's chain replayed on the model's motion (chain_bias.cc; null: not known, chain_why_)
  bool replay_tried_ = false;
  std::string chain_why_;
  nlohmann::json chain_bias_report_;    // report.json statistics.parameters_chain_bias (decide_parameters)
  nlohmann::json instruments_;          // iv: the tracking loop's bandwidth and RMS gap per joint
  mutable bool parameters_partial_ = false;   // some re-identified parameter has no MJCF attribute written
  std::optional<WrittenParameters> written_;  // set in build_report when `parameters` is named
  std::vector<std::string> notes_;
  FilterPlan filter_plan_;
  DelayResult delay_;   // #22
  std::vector<int> offset_beside_;   // #22: causes beside the delay search's nuisance (offset_beside)
  mutable std::optional<std::map<std::string, double>> floor_test_;   // resolution_floor(test_), formed on first use (residual_at_floor)
  mutable std::map<std::string, double> gp_share_at_floor_;           // what the GP predicted on joints left at their floor (unexplained)
  mutable std::optional<bool> degrees_;   // the model file's hinge angles in degrees (written_form.cc)
  mutable std::optional<std::vector<std::string>> defined_joints_;   // the joints the model file itself defines (written_form.cc)
  std::set<std::string> frictionloss_joints_;   // joints whose Coulomb level extended.xml states as frictionloss (choose_coulomb_form)
  // #22: the states the stateful simulations read, one per thread at a time, kept between calls
  // (making one costs more than a whole pass along a split).
  struct SimDataPool {
    std::mutex mutex;
    std::vector<std::shared_ptr<mjData>> free;
  };
  mutable std::shared_ptr<SimDataPool> sim_data_ = std::make_shared<SimDataPool>();
  std::deque<spml_shape_param> synthesized_;   // #22: the level keys of stateful plugins, searched as shapes
};

}  // namespace spml::diagnose_detail
