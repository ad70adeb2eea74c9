// Each spml subcommand registers itself on the shared CLI11 app. Handlers throw
// std::exception on failure; main() prints "spml: error: ..." and exits non-zero.
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace spml::cli {

void add_info(CLI::App& app);
void add_import(CLI::App& app);
void add_generate(CLI::App& app);
void add_regressor(CLI::App& app);
void add_identify(CLI::App& app);
void add_bench(CLI::App& app);
void add_merge(CLI::App& app);
void add_compare(CLI::App& app);
void add_plot(CLI::App& app);
void add_learners(CLI::App& app);
void add_plugins(CLI::App& app);
void add_diagnose(CLI::App& app);
void add_check_plugin(CLI::App& app);

// Option values that CLI11 would convert too leniently ("-1" into 2^64-1) are taken as
// text and parsed here, with messages naming the option.
std::uint64_t seed_option(const std::string& option, const std::string& text);
// "K/N" with 1 <= K <= N.
std::pair<int, int> shard_option(const std::string& option, const std::string& text);
// The one check of every floating-point option: the text must be a finite number (no nan,
// inf, trailing junk) within [lo, hi] (lo excluded when lo_open). A CLI11 validator, so a bad
// value is a command-line error (exit 2) naming the option.
CLI::Validator finite_number(double lo, double hi, bool lo_open = false);
// The same check on text taken as a string option; returns the number.
double finite_option(const std::string& option, const std::string& text, double lo, double hi, bool lo_open = false);
// A row cap: a whole number >= 1, or "all" (returned as 0).
long row_cap_option(const std::string& option, const std::string& text);
// s as one word for /bin/sh (single quotes; a quote inside becomes '\''): the plot
// scripts are run through std::system.
std::string shell_quote(const std::string& s);
// j as --json prints it (indented, newline); throws naming `source`, the field and the text when
// a text is not UTF-8 (JSON holds nothing else: a Latin-1 joint name, a folder name).
std::string json_output(const nlohmann::json& j, const std::string& source);
// --plugin-path folders or files, added to the process's force-plugin catalog.
void add_plugin_paths(const std::vector<std::string>& paths);

}  // namespace spml::cli
