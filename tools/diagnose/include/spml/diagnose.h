// spml diagnose: what an MJCF model gets wrong on measured data, which cause explains it, and
// how much the extended model gains on data the fit never saw.
//
//  1. Baseline: the model as given (its linear plugins included) through inverse dynamics on
//     the measured states; residual per joint on the fit and test splits.
//  2. Candidates: every force plugin found (shipped and on the plugin path) on every joint
//     that moves. Linear parameters enter as regressor columns; shape parameters (band edges,
//     a gear ratio, a Stribeck velocity) are searched over the plugin's own description
//     (spml_shape_param): a grid, then a bounded local refinement (NLopt), with the linear
//     amplitudes solved by least squares at every shape (variable projection).
//  3. Forward selection with the base parameters refitted jointly: at each step the passing
//     candidate with the most evidence per added parameter (Delta BIC / added rank) joins,
//     where passing = Delta BIC above a threshold on the fit split AND a relative drop of the
//     test-split residual on its joints of at least min_gain. Then backward elimination drops
//     causes that later ones made redundant (reported as superseded, not deleted).
//  4. "parameters": the re-identified base parameters are a cause when the data contradict
//     the MJCF's values given the effects found (Delta BIC and test gain as above).
//  5. extended.xml (when parameters are named: a physically consistent fit, every body
//     realizable), report.json, report.json, report.md, per-sample series for plots, rollouts.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "spml/dataset.h"

namespace spml {

struct DiagnoseOptions {
  std::string model;        // MJCF file
  std::string data;         // spml/1 dataset (q:/qd:/qdd:/tau:<joint> columns)
  // Further records of the same robot (--data repeated): fitted together with `data`, each
  // record's test part held out; filters and rollouts stay within each record.
  std::vector<std::string> more_data;
  std::string fit_split = "train";
  std::string test_split;   // "" = the first other split, or a time-ordered hold-out
  double holdout = 0.3;     // fraction held out (the last rows) when the dataset has one split
  double bic_threshold = 10;   // Delta BIC a cause needs on the fit split ("strong" evidence)
  double min_gain = 0.02;      // relative drop of its joints' test residual sum of squares
  int max_causes = 16;
  double still_speed = 1e-3;   // a joint whose |qd| never exceeds this does not move
  double rollout_seconds = 0.1;
  int rollouts = 20;
  // Other datasets (e.g. a validation record) whose every split is scored with the model as
  // given, after each cause and with the final model; they play no part in the selection.
  std::vector<std::string> cross;
  // Ripple (a position-periodic effect) is searched only at wavenumbers whose periods the
  // joint's stroke spans at least this many times; ripple_gear > 0 fixes the wavenumber at
  // the drive's gear ratio instead.
  double min_ripple_periods = 3;
  double ripple_gear = 0;
  // When `parameters` is named, extended.xml states a physically consistent fit (spml identify
  // --estimator consistent) with this weight of its prior toward the MJCF. 100, not identify's
  // 1: measured runs leave link masses loose, and the written model is meant for simulation
  // (Panda: with 1, link2 0.65 -> 5.5 kg and 0.1 s rollouts worse on joints 5-7; with 100
  // masses stay near the MJCF's and only joint 6 is worse, at the same held-out torque error).
  double prior_weight = 100;
  // Estimator of the base parameters whose contradiction of the MJCF names `parameters`:
  // "iv" (instrumental variables, instruments from the model simulated along the fit split:
  // spml/envs/instruments.h) or "ls" (least squares). Causes are selected by least squares.
  std::string estimator = "iv";
  // Threads for the work that can be split (its linear algebra, the simulations of plugins
  // flagged SPML_FORCE_INDEPENDENT): 0, the machine's cores up to four. The numbers do not
  // depend on it. (Process-wide while a diagnosis runs.)
  int threads = 0;

  // Throws std::invalid_argument naming the first option out of its range (every number must
  // be finite; holdout in [0.05, 0.9], min_gain in [0, 1], ...). diagnose() calls it first.
  void check() const;
};

// Where the time went (seconds).
struct DiagnoseTimings {
  double load = 0, baseline = 0, search = 0, refits = 0, rollouts = 0, outputs = 0;
};

struct DiagnoseResult {
  nlohmann::json report;          // the report.json contract (README "Diagnose measured data")
  std::string summary;            // the ranked summary printed by the command
  std::string extended_mjcf;      // text of extended.xml
  DiagnoseTimings timings;
};

// Runs the whole diagnosis and, when out_dir is not empty, writes report.json, report.md,
// extended.xml, series.csv and plots/ there (each file atomically). Throws std::exception with
// a message naming the file, split, column or plugin on bad input.
//
// Outputs are staged in a private folder inside out_dir and moved into place together at the
// end (under a lock, so two runs into one folder leave one run's files, and a stale plots/ is
// removed); before_publish, when given, runs on the staged folder first (the CLI draws the
// plots there). Inputs that are outputs (out_dir/extended.xml as --model) are refused.
DiagnoseResult diagnose(const DiagnoseOptions& options, const std::string& out_dir,
                        const std::function<void(const std::string& staged_dir)>& before_publish = {});

}  // namespace spml
