// What the checker's files share: recording clauses, and the key-table clause both kinds run.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "spml/abi.h"
#include "spml/check_plugin.h"
#include "spml/plugin_loader.h"

namespace spml::check {

struct Outcome {
  Verdict verdict;
  std::string detail;
};
inline Outcome pass(std::string detail = "") { return {Verdict::kPass, std::move(detail)}; }
inline Outcome fail(std::string detail) { return {Verdict::kFail, std::move(detail)}; }
inline Outcome skip(std::string detail) { return {Verdict::kSkip, std::move(detail)}; }

// Collects the clauses of one library; run() announces the clause as it starts (so that a
// checker running it in a child can name the clause a crash, an exit or a hang happened in)
// and turns an exception into a failure of that clause.
class Recorder {
 public:
  Recorder(LibraryReport& report, const CheckOptions& options) : report_(report), options_(options) {}
  void run(const std::string& plugin, const std::string& clause, const std::function<Outcome()>& body);
  void record(const std::string& plugin, const std::string& clause, Outcome outcome);
  void start(const std::string& plugin, const std::string& clause);
  std::uint64_t seed() const { return options_.seed; }
  bool wanted(const std::string& plugin) const { return options_.only_plugin.empty() || options_.only_plugin == plugin; }
  // The --set values for keys of `table`; throws naming the key when a value does not suit it.
  std::vector<std::pair<std::string, std::string>> config_for(const spml_config_key* table) const;

 private:
  LibraryReport& report_;
  const CheckOptions& options_;
};

// The key table clause: "" when every key is well formed, else the problems found.
// `required_allowed`: a key without a default is a required key (force plugins) rather than a
// default worked out from the data (learners); both are fine, the flag only words messages.
std::string key_table_problems(const spml_config_key* table, bool force_plugin);

// Text of a double that reads back exactly (spml/parse.h), for details.
std::string num(double v);

// Loads the library (clause "abi-version") and checks its entries' names (clause "names");
// nullptr when either fails, so that no plugin of it is run.
std::unique_ptr<PluginLibrary> load_library(const std::string& file, const PluginKind& kind, Recorder& recorder);

void check_learners(const std::string& file, Recorder& recorder);
void check_force_plugins(const std::string& file, Recorder& recorder);

}  // namespace spml::check
