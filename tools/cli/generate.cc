// spml generate: regenerate the paper's scenarios into spml/1 files.
#include <chrono>
#include <filesystem>
#include <iostream>

#include "commands.h"
#include "spml/envs/scenarios.h"
#include "spml/parse.h"

namespace spml::cli {

void add_generate(CLI::App& app) {
  auto* cmd = app.add_subcommand("generate", "Simulate a scenario of the paper and write its dataset");
  struct Args {
    std::string scenario, out, out_dir;
    bool all = false, quiet = false;
    std::string seed = "1";
    std::string test_stride = "1";
  };
  auto a = std::make_shared<Args>();
  std::string names;
  for (const auto& n : scenario_names()) names += (names.empty() ? "" : ", ") + n;
  auto* sc = cmd->add_option("--scenario,-s", a->scenario, "one of: " + names)->check(CLI::IsMember(scenario_names()));
  auto* all = cmd->add_flag("--all", a->all, "generate every scenario into --out-dir as <scenario>.h5");
  cmd->add_option("--out,-o", a->out, "output file (with --scenario)");
  cmd->add_option("--out-dir", a->out_dir, "output folder (with --all)");
  cmd->add_option("--seed", a->seed, "random seed (same seed, same arrays)");
  cmd->add_option("--test-stride", a->test_stride, "SimDyn: keep every n-th 1 kHz test sample (a whole number >= 1)");
  cmd->add_flag("--quiet,-q", a->quiet, "no progress output");
  sc->excludes(all);
  cmd->callback([a] {
    std::vector<std::pair<std::string, std::string>> jobs;
    if (a->all) {
      if (a->out_dir.empty()) throw std::invalid_argument("--all needs --out-dir");
      std::filesystem::create_directories(a->out_dir);
      for (const auto& n : scenario_names()) jobs.emplace_back(n, (std::filesystem::path(a->out_dir) / (n + ".h5")).string());
    } else {
      if (a->scenario.empty()) throw std::invalid_argument("choose --scenario NAME or --all");
      if (a->out.empty()) throw std::invalid_argument("--scenario needs --out FILE");
      jobs.emplace_back(a->scenario, a->out);
    }
    GenerateOptions opt;
    opt.seed = seed_option("--seed", a->seed);
    const auto stride = parse_integer(a->test_stride, 1, 1000000);
    if (!stride) throw CLI::ValidationError("--test-stride", "'" + a->test_stride + "' is not a whole number in [1, 1000000]");
    opt.test_stride = static_cast<int>(*stride);
    if (!a->quiet)
      opt.progress = [](const std::string& stage, double f) {
        std::cerr << "\r  " << stage << " " << static_cast<int>(100 * f) << "%   " << std::flush;
      };
    auto start_all = std::chrono::steady_clock::now();
    for (const auto& [name, file] : jobs) {
      auto start = std::chrono::steady_clock::now();
      Dataset ds = generate_scenario(name, opt);
      write_dataset(file, ds);
      double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (!a->quiet) std::cerr << "\r";
      std::cout << name << " -> " << file << " (";
      for (size_t i = 0; i < ds.splits.size(); ++i)
        std::cout << (i ? ", " : "") << ds.splits[i].name << " " << ds.splits[i].rows();
      std::cout << " rows) in " << s << " s\n";
    }
    if (jobs.size() > 1)
      std::cout << "all " << jobs.size() << " scenarios in "
                << std::chrono::duration<double>(std::chrono::steady_clock::now() - start_all).count() << " s\n";
  });
}

}  // namespace spml::cli
