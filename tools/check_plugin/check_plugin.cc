// The library-level half of the suite: telling the kind apart, recording clauses, the key
// table clause both kinds share, and the views of a report.
#include <dlfcn.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <set>

#include "detail.h"
#include "spml/force_effects.h"
#include "spml/learners/learner.h"
#include "spml/parse.h"
#include "spml/plugin_loader.h"

namespace spml::check {
namespace {

const char* verdict_word(Verdict v) { return v == Verdict::kPass ? "PASS" : v == Verdict::kFail ? "FAIL" : "SKIP"; }

// Which ABI the library speaks, by the version symbol it exports ("" for neither).
std::string kind_of(const std::string& file, std::string* problem) {
  void* h = dlopen(file.c_str(), RTLD_LAZY | RTLD_LOCAL);
  if (!h) {
    *problem = file + ": cannot be loaded: " + dlerror();
    return "";
  }
  const bool learner = dlsym(h, "spml_learner_abi_version"), force = dlsym(h, "spml_force_plugin_abi_version");
  dlclose(h);
  if (learner && force) *problem = file + ": exports both the learner and the force-plugin entry points; a library is one kind";
  else if (!learner && !force)
    *problem = file + ": exports neither spml_learner_abi_version nor spml_force_plugin_abi_version (not an spml plugin library)";
  return learner && !force ? "learner" : force && !learner ? "force plugin" : "";
}

std::string one_key_problem(const spml_config_key& k, bool force_plugin) {
  const std::string name = k.name;
  if (name.empty() || name.find_first_of(" \t=,") != std::string::npos) return "key '" + name + "': not a word";
  if (force_plugin && (name == "type" || name == "joints")) return "key '" + name + "': reserved for the declaration";
  if (k.type < SPML_VALUE_NUMBER || k.type > SPML_VALUE_TEXT) return "key '" + name + "': unknown value type " + std::to_string(k.type);
  if (k.type != SPML_VALUE_TEXT && (std::isnan(k.min) || std::isnan(k.max) || k.min > k.max))
    return "key '" + name + "': bounds [" + num(k.min) + ", " + num(k.max) + "] are empty";
  if (!k.help || !*k.help) return "key '" + name + "': no help text";
  if (k.default_value)
    if (std::string why = check_config_value(k, k.default_value); !why.empty())
      return "key '" + name + "': default " + why;
  return "";
}

// Every plugin's key table in a library, by plugin name; empty when it does not load (its
// check then fails the abi-version clause, which is where that is reported).
std::vector<std::pair<std::string, const spml_config_key*>> key_tables(const std::string& file, std::shared_ptr<PluginLibrary>* keep) {
  std::string problem;
  const std::string kind = kind_of(file, &problem);
  if (kind.empty()) return {};
  try {
    *keep = std::make_shared<PluginLibrary>(file, kind == "learner" ? learner_plugin_kind() : force_plugin_kind());
  } catch (const PluginError&) {
    return {};
  }
  std::vector<std::pair<std::string, const spml_config_key*>> out;
  for (const void* e : (*keep)->entries())
    out.emplace_back(static_cast<const PluginEntryHead*>(e)->name,
                     kind == "learner" ? static_cast<const spml_learner*>(e)->config_keys : static_cast<const spml_force_plugin*>(e)->config_keys);
  return out;
}

}  // namespace

std::string library_kind(const std::string& file) {
  std::string problem;
  return kind_of(file, &problem);
}

std::vector<std::string> plugin_names(const std::string& file) {
  std::shared_ptr<PluginLibrary> keep;
  std::vector<std::string> out;
  for (const auto& [name, table] : key_tables(file, &keep)) out.push_back(name);
  return out;
}

std::string config_problem(const std::vector<std::string>& files, const std::vector<std::pair<std::string, std::string>>& config) {
  if (config.empty()) return "";
  std::vector<std::shared_ptr<PluginLibrary>> keep(files.size());
  std::vector<std::pair<std::string, const spml_config_key*>> tables;
  for (size_t i = 0; i < files.size(); ++i)
    for (auto& t : key_tables(files[i], &keep[i])) tables.push_back(std::move(t));
  for (const auto& [key, value] : config) {
    bool known = false;
    for (const auto& [plugin, table] : tables)
      if (const spml_config_key* k = find_config_key(table, key)) {
        known = true;
        if (std::string why = check_config_value(*k, value); !why.empty())
          return key + "=" + value + ": " + plugin + "'s key '" + key + "': " + why;
      }
    if (known) continue;
    std::map<std::string, std::string> listed;   // plugin -> its keys
    for (const auto& [plugin, table] : tables) listed[plugin] = config_key_list(table);
    std::string keys;
    for (const auto& [plugin, list] : listed) keys += (keys.empty() ? "" : "; ") + plugin + ": " + (list.empty() ? "(no keys)" : list);
    return key + "=" + value + ": no plugin in " + (files.size() == 1 ? "this library" : "these libraries") +
           " has the key '" + key + "' (" + (keys.empty() ? "no plugin could be loaded" : keys) + ")";
  }
  return "";
}

bool LibraryReport::passed() const {
  for (const auto& c : clauses)
    if (c.verdict == Verdict::kFail) return false;
  return !clauses.empty();
}

std::string num(double v) { return number_text(v, 6); }

void Recorder::record(const std::string& plugin, const std::string& clause, Outcome outcome) {
  report_.clauses.push_back({plugin, clause, outcome.verdict, std::move(outcome.detail)});
  if (options_.on_clause) options_.on_clause(report_.clauses.back());
}

void Recorder::start(const std::string& plugin, const std::string& clause) {
  if (options_.on_start) options_.on_start(plugin, clause);
}

void Recorder::run(const std::string& plugin, const std::string& clause, const std::function<Outcome()>& body) {
  start(plugin, clause);
  Outcome outcome;
  try {
    outcome = body();
  } catch (const std::exception& e) {
    outcome = fail(e.what());
  }
  record(plugin, clause, std::move(outcome));
}

std::vector<std::pair<std::string, std::string>> Recorder::config_for(const spml_config_key* table) const {
  std::vector<std::pair<std::string, std::string>> out;
  for (const auto& [k, v] : options_.config)
    if (const spml_config_key* key = find_config_key(table, k)) {
      if (std::string why = check_config_value(*key, v); !why.empty()) throw PluginError("--set " + k + "=" + v + ": " + why);
      out.emplace_back(k, v);
    }
  return out;
}

std::string key_table_problems(const spml_config_key* table, bool force_plugin) {
  std::string out;
  std::set<std::string> seen;
  for (const spml_config_key* k = table; k && k->name; ++k) {
    std::string why = one_key_problem(*k, force_plugin);
    if (why.empty() && !seen.insert(k->name).second) why = "key '" + std::string(k->name) + "' listed twice";
    if (!why.empty()) out += (out.empty() ? "" : "; ") + why;
  }
  return out;
}

std::unique_ptr<PluginLibrary> load_library(const std::string& file, const PluginKind& kind, Recorder& recorder) {
  std::unique_ptr<PluginLibrary> lib;
  recorder.start("", "abi-version");   // loading runs the library's own code
  try {
    lib = std::make_unique<PluginLibrary>(file, kind);
  } catch (const PluginError& e) {
    recorder.record("", "abi-version", fail(e.what()));
    return nullptr;
  }
  // The revision a library declares by symbol (force plugins; learners say it per entry, by
  // flags): a later one than this spml knows loads too, its further members unread.
  const std::string revision = lib->revision() > 0 ? ", revision " + std::to_string(lib->revision()) : "";
  recorder.record("", "abi-version", pass(kind.label + " ABI version " + std::to_string(kind.abi_version) + revision + ", " +
                                         std::to_string(lib->entries().size()) + " entries"));
  std::string problem;
  std::set<std::string> names;
  for (const void* e : lib->entries()) {
    const auto* head = static_cast<const PluginEntryHead*>(e);
    if (!names.insert(head->name).second) problem += (problem.empty() ? "" : "; ") + std::string("'") + head->name + "' given twice";
    if (!head->summary || !*head->summary) problem += (problem.empty() ? "" : "; ") + std::string("'") + head->name + "' has no summary";
  }
  if (lib->entries().empty()) problem = "the library provides no " + kind.label;
  recorder.record("", "names", problem.empty() ? pass(std::to_string(names.size()) + " unique, non-empty, with summaries")
                                               : fail(problem));
  if (!problem.empty()) return nullptr;
  return lib;
}

LibraryReport check_library(const std::string& file, const CheckOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  LibraryReport report;
  report.file = file;
  Recorder recorder(report, options);
  std::string problem;
  recorder.start("", "abi-version");
  report.kind = kind_of(file, &problem);
  if (report.kind.empty()) recorder.record("", "abi-version", fail(problem));
  else if (report.kind == "learner") check_learners(file, recorder);
  else check_force_plugins(file, recorder);
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return report;
}

std::string clause_line(const Clause& c) {
  std::string line = std::string(verdict_word(c.verdict)) + "  " + (c.plugin.empty() ? "(library)" : c.plugin) + "  " + c.name;
  if (!c.detail.empty()) line += ": " + c.detail;
  return line;
}

nlohmann::json to_json(const LibraryReport& r) {
  nlohmann::json clauses = nlohmann::json::array();
  for (const auto& c : r.clauses)
    clauses.push_back({{"plugin", c.plugin}, {"clause", c.name}, {"verdict", verdict_word(c.verdict)}, {"detail", c.detail}});
  return {{"file", r.file}, {"kind", r.kind}, {"passed", r.passed()}, {"seconds", r.seconds}, {"clauses", clauses}};
}

}  // namespace spml::check
