// spml check-plugin LIB... [--json]: the contract suite (spml/check_plugin.h) on each library.
// One line per clause as it finishes; exit 1 when any clause fails.
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <stdexcept>

#include "commands.h"
#include "spml/check_plugin.h"
#include "spml/parse.h"

namespace spml::cli {
namespace {

// A plugin that crashes takes the checker with it; name the clause it crashed in first.
void on_crash(int sig) {
  const char* clause = check::running_clause();
  const char head[] = "FAIL  ";
  const char tail[] = ": the plugin crashed (fatal signal)\n";
  (void)!write(STDOUT_FILENO, head, sizeof head - 1);
  (void)!write(STDOUT_FILENO, clause, std::strlen(clause));
  (void)!write(STDOUT_FILENO, tail, sizeof tail - 1);
  signal(sig, SIG_DFL);
  raise(sig);
}

void name_crashes() {
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) signal(sig, on_crash);
}

}  // namespace

void add_check_plugin(CLI::App& app) {
  auto* cmd = app.add_subcommand("check-plugin", "Run the plugin contract suite on learner or force-plugin libraries");
  auto files = std::make_shared<std::vector<std::string>>();
  auto json = std::make_shared<bool>(false);
  auto seed = std::make_shared<std::string>("1");
  cmd->add_option("LIB", *files, "Plugin library files (.so), learner or force plugin")->required()->check(CLI::ExistingFile);
  cmd->add_flag("--json", *json, "Print one JSON document instead of lines");
  cmd->add_option("--seed", *seed, "Seed of the synthetic data and states (default 1)");
  auto sets = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--set", *sets, "KEY=VALUE for every plugin that has the key (e.g. steps=300 for a faster BNN check); repeatable")
      ->expected(1)
      ->allow_extra_args(false);
  cmd->callback([=] {
    check::CheckOptions options;
    options.seed = seed_option("--seed", *seed);
    for (const auto& kv : *sets) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0) throw CLI::ValidationError("--set", "'" + kv + "': expected key=value");
      options.config.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    }
    if (!*json) options.on_clause = [](const check::Clause& c) { std::cout << "  " << check::clause_line(c) << std::endl; };
    name_crashes();
    const auto t0 = std::chrono::steady_clock::now();
    nlohmann::json libraries = nlohmann::json::array();
    int failed = 0, clauses = 0;
    for (const auto& f : *files) {
      const std::string file = std::filesystem::absolute(f).string();
      if (!*json) std::cout << file << std::endl;
      const check::LibraryReport r = check::check_library(file, options);
      for (const auto& c : r.clauses) {
        ++clauses;
        if (c.verdict == check::Verdict::kFail) ++failed;
      }
      if (*json) libraries.push_back(check::to_json(r));
      else std::cout << "  " << (r.passed() ? "passed" : "FAILED") << " (" << r.kind << ", " << number_text(r.seconds, 3) << " s)\n";
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (*json)
      std::cout << nlohmann::json{{"libraries", libraries}, {"clauses", clauses}, {"failed", failed}, {"seconds", seconds}}.dump(2) << "\n";
    else
      std::cout << files->size() << " libraries, " << clauses << " clauses, " << failed << " failed, in " << number_text(seconds, 3) << " s\n";
    if (failed) throw std::runtime_error("check-plugin: " + std::to_string(failed) + " of " + std::to_string(clauses) + " clauses failed");
  });
}

}  // namespace spml::cli
