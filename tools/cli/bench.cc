// spml bench / spml compare / spml learners: run learners on a dataset, print the results
// beside the paper's tables, list what is installed.
#include <iostream>

#include "commands.h"
#include "spml/learners/compare.h"
#include "spml/learners/evaluate.h"

namespace spml::cli {
namespace {

void load_learners(LearnerRegistry& registry, const std::vector<std::string>& extra) {
  registry.add_default_path();
  for (const auto& p : extra) registry.add(p);
}

const char* kPathHelp = "Extra learner library or folder (also $SPML_LEARNER_PATH, ':'-separated)";

}  // namespace

void add_bench(CLI::App& app) {
  auto* cmd = app.add_subcommand("bench", "Fit learners on a dataset's train split and score every test split");
  auto data = std::make_shared<std::string>();
  auto learners = std::make_shared<std::string>("all");
  auto out = std::make_shared<std::string>();
  auto reps = std::make_shared<int>(5);
  auto seed = std::make_shared<std::uint64_t>(1);
  auto paths = std::make_shared<std::vector<std::string>>();
  auto sets = std::make_shared<std::vector<std::string>>();
  auto train_max = std::make_shared<long>(0);
  auto test_max = std::make_shared<long>(5000);
  cmd->add_option("--data", *data, "spml/1 dataset")->required()->check(CLI::ExistingFile);
  cmd->add_option("--learners", *learners, "Comma-separated learner names, or 'all'")->capture_default_str();
  cmd->add_option("--out", *out, "Output folder (results.csv, predictions.h5, units/)")->required();
  cmd->add_option("--reps", *reps, "Repetitions with seeds seed..seed+reps-1")->capture_default_str();
  cmd->add_option("--seed", *seed, "Seed of the first repetition")->capture_default_str();
  cmd->add_option("--learner-path", *paths, kPathHelp);
  cmd->add_option("--set", *sets, "key=value for every learner that accepts the key (e.g. max_evals=200)");
  cmd->add_option("--train-max", *train_max, "Use at most this many training rows, evenly strided (0 = all)")
      ->capture_default_str();
  cmd->add_option("--test-max", *test_max, "Score at most this many rows per test split, evenly strided (0 = all)")
      ->capture_default_str();
  cmd->callback([=] {
    LearnerRegistry registry;
    load_learners(registry, *paths);
    BenchOptions o;
    o.data = *data;
    o.learners = registry.expand(*learners);
    o.out = *out;
    o.reps = *reps;
    o.seed = *seed;
    o.train_max = *train_max;
    o.test_max = *test_max;
    for (const auto& kv : *sets) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0) throw LearnerError("--set '" + kv + "': expected key=value");
      o.config.values.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    }
    o.log = [](const std::string& line) { std::cerr << line << std::endl; };
    const BenchReport r = run_bench(registry, o, *learners == "all");
    for (const auto& s : r.skipped) std::cerr << "skipped " << s << "\n";
    std::cout << "wrote " << *out << "/results.csv and " << *out << "/predictions.h5 (" << r.units_run << " fits run, "
              << r.units_cached << " reused)\n";
    if (!r.failed.empty()) {
      std::string all;
      for (const auto& f : r.failed) all += "\n  " + f;
      throw LearnerError(std::to_string(r.failed.size()) + " learner(s) failed:" + all);
    }
  });
}

void add_compare(CLI::App& app) {
  auto* cmd = app.add_subcommand("compare", "Print results beside the paper's tables, with deltas and rank agreement");
  auto results = std::make_shared<std::vector<std::string>>();
  auto published = std::make_shared<std::string>(default_published_dir());
  cmd->add_option("--results", *results, "results.csv from spml bench (repeatable)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--published", *published, "Folder of the paper's tables")->capture_default_str();
  cmd->callback([=] {
    std::vector<ResultRow> rows;
    for (const auto& f : *results) {
      auto r = read_results(f);
      rows.insert(rows.end(), r.begin(), r.end());
    }
    std::cout << compare_report(rows, *published);
  });
}

void add_learners(CLI::App& app) {
  auto* cmd = app.add_subcommand("learners", "List the learners found on the search path");
  auto paths = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--learner-path", *paths, kPathHelp);
  cmd->callback([=] {
    LearnerRegistry registry;
    load_learners(registry, *paths);
    for (const auto& n : registry.plugin_names()) {
      const spml_learner* l = registry.plugin(n);
      std::cout << n << "\t" << l->summary << "\t[" << registry.plugin_file(n) << "]\n";
    }
    std::cout << "plus compositions A-B and it-A-B (A parametric, B non-parametric), e.g. LLS-GP, it-SVR-GP\n";
  });
}

}  // namespace spml::cli
