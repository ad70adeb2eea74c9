// Each spml subcommand registers itself on the shared CLI11 app. Handlers throw
// std::exception on failure; main() prints "spml: error: ..." and exits non-zero.
#pragma once

#include <CLI/CLI.hpp>

namespace spml::cli {

void add_info(CLI::App& app);
void add_import(CLI::App& app);
void add_generate(CLI::App& app);
void add_regressor(CLI::App& app);
void add_identify(CLI::App& app);
void add_bench(CLI::App& app);
void add_compare(CLI::App& app);
void add_learners(CLI::App& app);

}  // namespace spml::cli
