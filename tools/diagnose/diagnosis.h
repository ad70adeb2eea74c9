// The state one diagnose run carries from stage to stage. Each stage lives in its own file, in
// the order the data flows:
//   load.cc        model, dataset, splits (fit / test / cross)
//   prepare.cc     one split made ready: columns, base regressor, targets, the model's prediction
//   estimate.cc    least-squares refits of the base parameters and causes, residuals on any split
//   candidates.cc  the force plugins as candidate causes, and their regressor columns
//   shape_search.cc  the shape of one candidate (grid, zoom, plateau middle, local polish)
//   selection.cc   forward selection, backward elimination, the `parameters` decision
//   verify.cc      the written model: extended.xml, its own inverse dynamics, rollouts
//   report_json.cc report.json (causes, metrics, cross-tests) and series.csv
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "design.h"
#include "extended_mjcf.h"
#include "spml/diagnose.h"
#include "spml/envs/mjcf_regressor.h"
#include "spml/force_effects.h"

namespace spml::diagnose_detail {

using Clock = std::chrono::steady_clock;
inline double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::string fmt(double v, int precision = 4);
std::string integer_text(double v);

// One split as diagnose uses it: its rows, the stacked base regressor, the stacked torques and
// what the model as given predicts.
struct SplitData {
  std::string name;
  Split split;
  std::unique_ptr<JointColumns> cols;
  BlockColumns base;
  Eigen::VectorXd b, given, y0;   // targets, prediction of the model as given, b - given
  Eigen::Index N = 0;
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
  Gain gain;
  double delta_bic = -std::numeric_limits<double>::infinity();
};

struct Cause {
  int candidate;
  double delta_bic;
  std::string superseded_by;
};

// Evidence for the larger of two nested fits (Bayesian information criterion, n equations,
// dk more parameters): positive when the drop of the residual sum of squares pays for them.
double delta_bic(double n, double rss_smaller, double rss_larger, double dk);

// The held-out test: the residual sum of squares falls by at least the fraction min_gain.
bool gains_on_test(double rss_before, double rss_after, double min_gain);

class Diagnosis {
 public:
  explicit Diagnosis(const DiagnoseOptions& o) : opt_(o) {}
  DiagnoseResult run(const std::string& out_dir);

 private:
  // load.cc
  void load();
  void choose_splits(Split& fit_part, Split& test_part);
  void load_cross();
  void map_outputs();
  // prepare.cc
  SplitData prepare(const Split& s);
  // candidates.cc
  void find_candidates();
  void add_candidates(const spml_force_plugin& p, const std::vector<const spml_shape_param*>& shape,
                      const std::vector<std::pair<std::string, std::string>>& fixed);
  std::vector<std::pair<std::string, std::string>> config_of(const Candidate& c, const std::vector<double>& shape) const;
  BlockColumns columns(const PluginInstance& inst, const SplitData& s) const;
  BlockColumns columns_of(const Candidate& c, const SplitData& s) const;
  // "" when the plugin accepts its fitted parameters (written back through write_config and
  // created again), else its reason: a negative band level is not a friction band.
  std::string refused(int candidate, const Eigen::VectorXd& theta) const;
  // shape_search.cc
  double search_shape(Candidate& c, const Fit& current);
  // estimate.cc
  std::vector<const BlockColumns*> blocks(const std::vector<int>& causes, bool base_free) const;
  Fit refit(const std::vector<int>& causes, bool base_free) const;
  Eigen::VectorXd residual_on(const SplitData& s, const std::vector<int>& causes, bool base_free, const Fit& f) const;
  double rss_on(const Eigen::VectorXd& r, const std::vector<int>& outputs, Eigen::Index N) const;
  std::vector<int> outputs_of(int candidate) const;
  // selection.cc
  void select();
  void score_candidates(const Fit& current, const std::vector<int>& chosen, const std::set<int>& research, std::vector<int>& order);
  bool cause_needed(size_t i, const std::vector<size_t>& set) const;
  void eliminate_backward();
  void decide_parameters();
  std::vector<int> kept_effects() const;
  // report_json.cc
  nlohmann::json metrics(const Eigen::VectorXd& r_fit, const Eigen::VectorXd& r_test) const;
  nlohmann::json per_joint(const Eigen::VectorXd& r, Eigen::Index N) const;
  nlohmann::json cross_errors(const std::vector<int>& causes, bool base_free, const Fit& f) const;
  void build_report(const std::string& out_dir);
  nlohmann::json parameters_cause(const Fit& final_fit, MjcfEdits& edits, std::vector<std::string>& notes) const;
  void parameter_edits(const Eigen::VectorXd& pi, MjcfEdits& edits, std::vector<std::string>& notes) const;
  void inertial_edit(const Eigen::VectorXd& pi, const std::string& body, MjcfEdits& edits, std::vector<std::string>& notes) const;
  nlohmann::json effect_cause(size_t i, const Fit& final_fit, bool free, MjcfEdits& edits, std::vector<std::string>& notes,
                              nlohmann::json& cross_after) const;
  nlohmann::json cross_report(const Fit& final_fit, bool free, const nlohmann::json& cross_after) const;
  void write_series(const std::string& out_dir, const Eigen::VectorXd& final_pred_fit, const Eigen::VectorXd& final_test) const;
  // verify.cc
  void verify(const std::string& out_dir, MjcfEdits& edits, std::vector<std::string>& notes, const Eigen::VectorXd& final_pred_fit);

  DiagnoseOptions opt_;
  DiagnoseResult result_;
  std::unique_ptr<MjcfRegressor> reg_;
  MjcfRegressor::Base base_;
  Dataset ds_;
  std::string test_name_;
  SplitData fit_, test_;
  std::vector<std::pair<std::string, SplitData>> cross_;   // (file, split)
  std::vector<std::string> out_joints_;   // per output: joint name
  std::vector<int> out_joint_index_;      // per output: model joint index
  std::vector<bool> still_;               // per model joint
  std::vector<Candidate> cands_;
  nlohmann::json not_tried_ = nlohmann::json::array();
  std::vector<Cause> causes_;
  bool parameters_named_ = false;
  double parameters_delta_bic_ = 0;
  std::vector<std::string> notes_;
};

}  // namespace spml::diagnose_detail
