// spml check-plugin: the contract suite every plugin library passes, in-tree or not (after
// scikit-learn's check_estimator). A library is told apart as a learner or a force-plugin
// library by its exported symbols, loaded through the one loader (spml/plugin_loader.h), and
// every clause of its ABI's contract is run on every plugin it provides:
//   both kinds   the ABI version; unique non-empty names; a key table whose types are valid,
//                whose defaults parse and lie within their own bounds, with help for every key;
//   learners     on seeded synthetic data (check_learner.cc): outputs written and finite,
//                variances > 0, DETERMINISTIC and same-seed repeats identical, coefficients,
//                a query of another width refused, NaN in the fit data refused, the inputs
//                left byte for byte as they were;
//   force plugins on an MJCF with hinge and slide joints (check_force_plugin.cc): no hidden
//                state, only its own joints' dofs written, R(q, qd) theta = force,
//                set_params(get_params()) a no-op, write_config
//                recreates it, shape parameters valid, reset replays the first trajectory.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace spml::check {

enum class Verdict { kPass, kFail, kSkip };

// One clause run on one plugin: its name (e.g. "variance-positive"), and the numbers behind
// the verdict (for a failure: what was expected and what came out).
struct Clause {
  std::string plugin;   // the plugin's name, or "" for a clause about the whole library
  std::string name;
  Verdict verdict = Verdict::kPass;
  std::string detail;
};

struct LibraryReport {
  std::string file;
  std::string kind;     // "learner", "force plugin", or "" when it is neither
  std::vector<Clause> clauses;
  double seconds = 0;
  bool passed() const;
};

struct CheckOptions {
  std::uint64_t seed = 1;                               // every random choice of the checker
  // key=value given to every plugin whose key table has the key (checked against its type and
  // bounds like spml bench's --set; e.g. fewer training steps of a slow learner); the other
  // keys keep their defaults. Plugins without the key ignore it.
  std::vector<std::pair<std::string, std::string>> config;
  std::function<void(const Clause&)> on_clause;         // called as each clause finishes
  // Called as each clause starts (plugin "" for the library's own), before any plugin code of
  // it runs: a child process reports it so that its parent can name the clause it ended in.
  std::function<void(const std::string& plugin, const std::string& clause)> on_start;
  // Only the plugin of this name (its clauses, after the library's own); "" for all of them.
  // The command runs each plugin of a library in a child of its own, two at a time.
  std::string only_plugin;
};

// The names of the plugins a library provides, in its order; empty when it does not load as
// either kind (its check then says why).
std::vector<std::string> plugin_names(const std::string& file);

// "learner" or "force plugin" by the symbols the library exports; "" when it is neither or
// does not load.
std::string library_kind(const std::string& file);

// Runs the suite on one library file. Never throws for a bad plugin (that is a failed clause).
LibraryReport check_library(const std::string& file, const CheckOptions& options = {});

// What is wrong with `config` (--set) for the plugins of `files`, "" when nothing: a key that
// no plugin has (a typo: the message lists every plugin's keys), or a value that does not suit
// the key of a plugin that has it (type, bounds): "KEY=VALUE: ...". A usage error, checked
// before any clause runs.
std::string config_problem(const std::vector<std::string>& files, const std::vector<std::pair<std::string, std::string>>& config);

// "PASS  <plugin>  <clause>: <detail>" (FAIL, SKIP), one line, for people.
std::string clause_line(const Clause& clause);
nlohmann::json to_json(const LibraryReport& report);

}  // namespace spml::check
