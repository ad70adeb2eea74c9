// The shared evaluator: scores, repetitions, and `spml bench` (fit every learner on a
// dataset's train split, predict every test split, aggregate over repetitions).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "spml/dataset.h"
#include "spml/learners/learner.h"

namespace spml {

// Per output: root-mean-square error, and the mean negative log predictive density of a
// Gaussian with the predicted variance (noise included); +inf without a variance.
struct Scores {
  std::vector<double> rmse, nllh;
};
Scores score(const RowMatrix& Y, const LearnerPrediction& p);

// mean, std (population, ddof = 0 as numpy; exactly 0 when all values are equal), min, max.
struct Summary {
  double mean = 0, std = 0, min = 0, max = 0;
};
Summary summarize(const std::vector<double>& values);

struct BenchOptions {
  std::string data;                 // spml/1 file
  std::string model;                // MJCF giving the parametric model ("" = the dataset's own)
  std::vector<std::string> learners;
  int reps = 5;
  std::uint64_t seed = 1;           // repetition r runs with seed + r
  std::string out;                  // folder for results.csv, predictions.h5, units/
  LearnerConfig config;             // key=values for every learner that accepts them
  Eigen::Index train_max = 0;       // 0: all training rows; else an even stride down to at most this
  Eigen::Index test_max = 5000;     // likewise per test split (0: all)
  std::function<void(const std::string&)> log;   // progress lines; may be empty
  // While one unit fits longer than this, a line every this many seconds: the fraction done,
  // the fit's and the run's ETA when the learner reports progress (SPML_LEARNER_PROGRESS),
  // else "still fitting"; 0: none. Called from a second thread while the fit runs.
  double heartbeat_seconds = 5;
  // Sharding: the (learner, repetition) units are numbered in run order and this run fits
  // only those with number % shards == shard - 1; units of other shards are used when
  // already present in out/units and left alone otherwise.
  int shard = 1, shards = 1;
  bool reuse_only = false;          // fit nothing: every unit must already be in out/units (merge)
  // merge: the shard folders, shard k's at k - 1; unit u is read from folder u % size() (the
  // shard that fitted it) and copied into out/units. Empty: units are read from out/units.
  std::vector<std::string> unit_sources;
  // Other files the run reads (force-plugin and learner libraries): like data and model, they
  // must not be among the files the run writes into out.
  std::vector<std::string> other_inputs;

  // Throws LearnerError naming the option (as the command line spells it) when a value is out
  // of range; run_bench() calls it, and so does `spml bench` before it loads anything.
  void check() const;
};

struct BenchReport {
  std::vector<std::string> failed;    // "learner: message"
  std::vector<std::string> skipped;   // learners "all" left out, with the reason
  int units_run = 0, units_cached = 0;
  int units_elsewhere = 0;            // units of other shards not present here
};

// Runs (or resumes) a benchmark. Every (learner, repetition) unit is kept in out/units with a
// key hashed from the data it saw (train and test values, columns, the model's regressor
// and coefficients) and the settings that shape it (learner, seed, config, row caps); a
// rerun reuses a unit only when its key matches, and refits it otherwise (also when the
// file is unreadable). Config values are checked against the learners' key tables before
// anything is fitted or written. results.csv and predictions.h5 are rewritten atomically
// from the finished units.
BenchReport run_bench(const LearnerRegistry& registry, const BenchOptions& options, bool all_requested = false);

// --set keys: `key` goes to every learner that accepts it, `LEARNER.key` (e.g. `GP.max_evals`)
// only to that learner of the run (as named in the learner list, compositions included) and
// wins over an unscoped value of the same key. config_for() is what one learner receives.
LearnerConfig config_for(const LearnerConfig& config, const std::string& learner);
// Throws LearnerError naming the entry: a scope that is not one of `learners`, a key no
// learner in scope accepts, a value outside a key's table. run_bench() calls it; `spml bench`
// calls it first, so these are command-line errors (exit 2).
void check_config(const LearnerRegistry& registry, const std::vector<std::string>& learners, const LearnerConfig& config);

// Builds in `out` what one unsharded `spml bench` would have written, from the shard folders
// of one sharded run: checks that their bench.json agree (data, settings, learners), copies
// each unit from the folder of the shard that fitted it into out/units (stale units another
// folder holds are ignored) and aggregates them without fitting anything. `out` must not be
// one of the shard folders. Throws naming
// the folder, field or unit that is missing or disagrees.
BenchReport merge_bench(const LearnerRegistry& registry, const std::vector<std::string>& shard_dirs,
                        const std::string& out, const std::function<void(const std::string&)>& log);

// Rows actually used from a split of `rows` rows with a cap of `max` (0 = all): an even stride.
std::vector<Eigen::Index> strided_rows(Eigen::Index rows, Eigen::Index max);

}  // namespace spml
