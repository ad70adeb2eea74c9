// spml bench / spml compare / spml learners: run learners on a dataset, print the results
// beside the paper's tables, list what is installed.
#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "spml/learners/compare.h"
#include "spml/learners/evaluate.h"
#include "spml/force_effects.h"

namespace spml::cli {
namespace {

void load_learners(LearnerRegistry& registry, const std::vector<std::string>& extra) {
  registry.add_default_path();
  for (const auto& p : extra) registry.add(p);
  for (const auto& w : registry.warnings()) std::cerr << "spml: warning: " << w << "\n";
}

const char* kPathHelp = "Extra learner library or folder (also $SPML_LEARNER_PATH, ':'-separated)";

// One key of a learner's or force plugin's table, for --json (bounds null where unbounded).
nlohmann::json key_json(const spml_config_key& k) {
  static const char* types[] = {"unknown", "number", "integer", "numbers", "text"};
  auto bound = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  return {{"name", k.name}, {"type", types[k.type >= 1 && k.type <= 4 ? k.type : 0]}, {"min", bound(k.min)},
          {"max", bound(k.max)}, {"default", k.default_value ? nlohmann::json(k.default_value) : nlohmann::json()},
          {"help", k.help ? k.help : ""}};
}

nlohmann::json learner_flags(std::uint32_t f) {
  static const std::pair<std::uint32_t, const char*> names[] = {
      {SPML_LEARNER_USES_MODEL, "uses_model"},       {SPML_LEARNER_VARIANCE, "variance"},
      {SPML_LEARNER_PARAMETRIC, "parametric"},       {SPML_LEARNER_NONPARAMETRIC, "nonparametric"},
      {SPML_LEARNER_DETERMINISTIC, "deterministic"}, {SPML_LEARNER_NEEDS_PRIOR, "needs_prior"},
      {SPML_LEARNER_NEEDS_TRUTH, "needs_truth"},     {SPML_LEARNER_PROGRESS, "progress"}};
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [bit, name] : names)
    if (f & bit) out.push_back(name);
  return out;
}

}  // namespace

void add_bench(CLI::App& app) {
  auto* cmd = app.add_subcommand("bench", "Fit learners on a dataset's train split and score every test split");
  auto data = std::make_shared<std::string>();
  auto learners = std::make_shared<std::string>("all");
  auto out = std::make_shared<std::string>();
  auto reps = std::make_shared<int>(5);
  auto seed = std::make_shared<std::string>("1");
  auto paths = std::make_shared<std::vector<std::string>>();
  auto plugin_paths = std::make_shared<std::vector<std::string>>();
  auto sets = std::make_shared<std::vector<std::string>>();
  auto train_max = std::make_shared<std::string>("all");
  auto test_max = std::make_shared<std::string>("5000");
  auto model = std::make_shared<std::string>();
  auto shard = std::make_shared<std::string>("1/1");
  cmd->add_option("--data", *data, "spml/1 dataset")->required();
  cmd->add_option("--model", *model, "MJCF whose regressor is the parametric model (default: the dataset's own)");
  cmd->add_option("--plugin-path", *plugin_paths, "Extra force-plugin library or folder (also $SPML_PLUGIN_PATH)");
  cmd->add_option("--learners", *learners, "Comma-separated learner names, or 'all'")->capture_default_str();
  cmd->add_option("--out", *out, "Output folder (results.csv, predictions.h5, units/)")->required();
  cmd->add_option("--reps", *reps, "Repetitions with seeds seed..seed+reps-1")->capture_default_str()->check(CLI::Range(1, 1000));
  cmd->add_option("--seed", *seed, "Seed of the first repetition")->capture_default_str();
  cmd->add_option("--learner-path", *paths, kPathHelp);
  cmd->add_option("--set", *sets,
                  "key=value for every learner that accepts the key (e.g. max_evals=200), or LEARNER.key=value for "
                  "one learner of the run (e.g. GP.max_evals=200; it wins over an unscoped value)");
  auto quiet = std::make_shared<bool>(false);
  cmd->add_flag("--quiet,-q", *quiet, "No progress output (errors and the closing line only)");
  auto heartbeat = std::make_shared<double>(5);
  cmd->add_option("--heartbeat", *heartbeat,
                  "Seconds between progress lines during one long fit: fraction done and ETA where the learner reports "
                  "its progress, else 'still fitting' (0: none)")
      ->capture_default_str()
      ->check(finite_number(0, 1e6));
  cmd->add_option("--train-max", *train_max, "Use at most this many training rows, evenly strided, or 'all'")
      ->capture_default_str();
  cmd->add_option("--test-max", *test_max, "Score at most this many rows per test split, evenly strided, or 'all'")
      ->capture_default_str();
  cmd->add_option("--shard", *shard,
                  "K/N: fit only the K-th of N deterministic slices of the (learner, repetition) units; "
                  "combine the N output folders with spml merge")
      ->capture_default_str();
  cmd->callback([=] {
    BenchOptions o;
    std::tie(o.shard, o.shards) = shard_option("--shard", *shard);
    o.seed = seed_option("--seed", *seed);
    o.train_max = row_cap_option("--train-max", *train_max);
    o.test_max = row_cap_option("--test-max", *test_max);
    for (const auto& kv : *sets) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0) throw CLI::ValidationError("--set", "'" + kv + "': expected key=value");
      for (const auto& [k, v] : o.config.values)
        if (k == kv.substr(0, eq))
          throw CLI::ValidationError("--set", "'" + k + "' is given twice (" + k + "=" + v + " and " + kv + "): give it once");
      o.config.values.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    }
    o.data = *data;
    o.model = *model;
    o.out = *out;
    o.reps = *reps;
    o.other_inputs = *plugin_paths;   // folders among them are never one of the files bench writes
    o.other_inputs.insert(o.other_inputs.end(), paths->begin(), paths->end());
    try {
      o.check();   // the library's own check: the C++ API refuses what the command line refuses
    } catch (const LearnerError& e) {
      throw CLI::ValidationError(e.what());
    }
    add_plugin_paths(*plugin_paths);
    LearnerRegistry registry;
    load_learners(registry, *paths);
    o.learners = registry.expand(*learners);
    try {
      check_config(registry, o.learners, o.config);   // a typo in --set is a command-line error
    } catch (const LearnerError& e) {
      throw CLI::ValidationError(e.what());
    }
    if (!*quiet) o.log = [](const std::string& line) { std::cerr << line << std::endl; };
    o.heartbeat_seconds = *heartbeat;
    const BenchReport r = run_bench(registry, o, *learners == "all");
    if (!*quiet)
      for (const auto& s : r.skipped) std::cerr << "skipped " << s << "\n";
    std::cout << "wrote " << *out << "/results.csv and " << *out << "/predictions.h5 (" << r.units_run << " fits run, "
              << r.units_cached << " reused";
    if (o.shards > 1)
      std::cout << "; shard " << o.shard << "/" << o.shards << ": the results hold only learners whose units all ran here, "
                << r.units_elsewhere << " units belong to other shards: combine with spml merge";
    std::cout << ")\n";
    if (!r.failed.empty()) {
      std::string all;
      for (const auto& f : r.failed) all += "\n  " + f;
      throw LearnerError(std::to_string(r.failed.size()) + " learner(s) failed:" + all);
    }
  });
}

void add_merge(CLI::App& app) {
  auto* cmd = app.add_subcommand("merge", "Combine the output folders of a sharded spml bench into one, as if unsharded");
  auto dirs = std::make_shared<std::vector<std::string>>();
  auto out = std::make_shared<std::string>();
  auto paths = std::make_shared<std::vector<std::string>>();
  auto plugin_paths = std::make_shared<std::vector<std::string>>();
  cmd->add_option("dirs", *dirs, "Output folders of spml bench --shard 1/N .. N/N")->required();
  cmd->add_option("--out", *out, "Folder for the merged results.csv, predictions.h5 and units/")->required();
  cmd->add_option("--learner-path", *paths, kPathHelp);
  cmd->add_option("--plugin-path", *plugin_paths, "Extra force-plugin library or folder (also $SPML_PLUGIN_PATH)");
  cmd->callback([=] {
    add_plugin_paths(*plugin_paths);
    LearnerRegistry registry;
    load_learners(registry, *paths);
    const BenchReport r = merge_bench(registry, *dirs, *out, [](const std::string& line) { std::cerr << line << std::endl; });
    std::cout << "wrote " << *out << "/results.csv and " << *out << "/predictions.h5 from " << r.units_cached << " units of "
              << dirs->size() << " shard folders\n";
  });
}

void add_compare(CLI::App& app) {
  auto* cmd = app.add_subcommand("compare", "Print results beside the paper's tables, with deltas and rank agreement");
  auto results = std::make_shared<std::vector<std::string>>();
  auto published = std::make_shared<std::string>(default_published_dir());
  cmd->add_option("--results", *results, "results.csv from spml bench (repeatable)")->required();
  cmd->add_option("--published", *published, "Folder of the paper's tables")->capture_default_str();
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "Print one JSON document (format spml-compare/1) instead of the tables");
  cmd->callback([=] {
    std::vector<ResultRow> rows;
    for (const auto& f : *results) {
      auto r = read_results(f);
      rows.insert(rows.end(), r.begin(), r.end());
    }
    if (*json) std::cout << json_output(compare_json(rows, *published), "compare --json");
    else std::cout << compare_report(rows, *published);
  });
}

void add_learners(CLI::App& app) {
  auto* cmd = app.add_subcommand("learners", "List the learners found on the search path");
  auto paths = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--learner-path", *paths, kPathHelp);
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "Print one JSON document: every learner with its flags and key table");
  cmd->callback([=] {
    LearnerRegistry registry;
    load_learners(registry, *paths);
    if (*json) {
      nlohmann::json list = nlohmann::json::array();
      for (const auto& n : registry.plugin_names()) {
        const spml_learner* l = registry.plugin(n);
        nlohmann::json keys = nlohmann::json::array();
        for (const spml_config_key* k = l->config_keys; k && k->name; ++k) keys.push_back(key_json(*k));
        list.push_back({{"name", n}, {"summary", l->summary ? l->summary : ""}, {"file", registry.plugin_file(n)},
                        {"flags", learner_flags(l->flags)}, {"config_keys", keys}});
      }
      std::cout << json_output(nlohmann::json{{"learners", list}, {"compositions", {"A-B", "it-A-B"}}}, "learners --json");
      return;
    }
    for (const auto& n : registry.plugin_names()) {
      const spml_learner* l = registry.plugin(n);
      std::cout << n << "\t" << l->summary << "\t[" << registry.plugin_file(n) << "]\n";
    }
    std::cout << "plus compositions A-B and it-A-B (A parametric, B non-parametric), e.g. LLS-GP, it-SVR-GP\n";
  });
}

void add_plugins(CLI::App& app) {
  auto* cmd = app.add_subcommand("plugins", "List the force plugins found, with their keys and shape parameters");
  auto paths = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--plugin-path", *paths, "Extra force-plugin library or folder (also $SPML_PLUGIN_PATH)");
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "Print one JSON document: every plugin with its keys and shape parameters");
  cmd->callback([=] {
    add_plugin_paths(*paths);
    const PluginCatalog& catalog = force_plugins();
    for (const auto& w : catalog.warnings()) std::cerr << "spml: warning: " << w << "\n";
    if (*json) {
      static const char* domains[] = {"absolute", "position_range", "top_speed"};
      nlohmann::json list = nlohmann::json::array();
      for (const auto& n : catalog.names()) {
        const auto* p = static_cast<const spml_force_plugin*>(catalog.find(n));
        nlohmann::json keys = nlohmann::json::array(), shapes = nlohmann::json::array();
        for (const spml_config_key* k = p->config_keys; k && k->name; ++k) keys.push_back(key_json(*k));
        for (const spml_shape_param* sp = p->shape_params; sp && sp->key; ++sp)
          shapes.push_back({{"key", sp->key}, {"lo", sp->lo}, {"hi", sp->hi},
                            {"domain", domains[sp->domain == SPML_SHAPE_POSITION ? 1 : sp->domain == SPML_SHAPE_SPEED ? 2 : 0]},
                            {"log_scale", static_cast<bool>(sp->log_scale)}, {"integer", static_cast<bool>(sp->integer)}});
        list.push_back({{"name", n}, {"summary", p->summary ? p->summary : ""}, {"file", catalog.file_of(n)},
                        {"linear", p->regressor != nullptr}, {"config_keys", keys}, {"shape_params", shapes},
                        {"abi_revision", catalog.revision_of(n)}, {"independent", force_plugin_independent(*p)}});
      }
      std::cout << json_output(nlohmann::json{{"plugins", list}}, "plugins --json");
      return;
    }
    for (const auto& n : catalog.names()) {
      const auto* p = static_cast<const spml_force_plugin*>(catalog.find(n));
      std::cout << n << "\t" << p->summary << "\t[" << catalog.file_of(n) << "]\n"
                << "    ABI revision " << catalog.revision_of(n)
                << (force_plugin_independent(*p) ? ", instances independent: diagnose runs it on several threads\n"
                                                                       : ", one thread\n");
      for (const spml_config_key* k = p->config_keys; k && k->name; ++k)
        std::cout << "    " << k->name << (k->default_value ? " = " + std::string(k->default_value) : std::string(" (required)"))
                  << "  " << k->help << "\n";
      for (const spml_shape_param* sp = p->shape_params; sp && sp->key; ++sp)
        std::cout << "    shape " << sp->key << " in [" << sp->lo << ", " << sp->hi << "]"
                  << (sp->domain == SPML_SHAPE_POSITION ? " of the position range" : sp->domain == SPML_SHAPE_SPEED ? " of the top speed" : "")
                  << (sp->log_scale ? ", log scale" : "") << (sp->integer ? ", whole numbers" : "") << "\n";
    }
  });
}

}  // namespace spml::cli
