// Loading spml plugin libraries - learners and force plugins alike: dlopen, the ABI
// version check, the search order, the error class and configuration checks live here once.
//
// Search order (the same for both kinds, first wins on nothing: a name found twice is an error):
//   1. the plugins shipped with spml: <folder of the spml libraries>/spml/<kind folder>
//      (build/lib/spml/... in the build tree, <prefix>/lib/spml/... once installed);
//   2. the folders in the kind's environment variable ($SPML_LEARNER_PATH,
//      $SPML_PLUGIN_PATH; ':'-separated);
//   3. folders or files given on the command line (--learner-path, --plugin-path).
// A library in a folder that cannot be loaded is skipped with a warning naming the file;
// a library named explicitly (a file) that cannot be loaded is an error. A folder named in
// the environment that does not exist is a warning, one named on the command line an error.
#pragma once

#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "spml/abi.h"

namespace spml {

// Any problem finding, loading or configuring a plugin; the message names the file or element.
class PluginError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One kind of plugin: how its libraries are recognised and where they are looked for.
struct PluginKind {
  std::string label;        // "learner", "force plugin" (for messages)
  std::string prefix;       // symbol prefix: "spml_learner" -> spml_learner_abi_version, spml_learner_get
  int abi_version = 0;
  std::string env_var;      // "SPML_LEARNER_PATH"
  std::string folder;       // "learners" -> <libdir>/spml/learners
};

// The folder holding spml's shared libraries (found from this library's own location, so
// an installed or moved tree works without compiled-in paths) and spml's data folder.
std::string spml_lib_dir();
std::string spml_share_dir();   // <prefix>/share/spml: mjcf/, published/

// A loaded library: its ABI version checked, its entries listed. Kept loaded while any
// copy of the shared_ptr lives.
class PluginLibrary {
 public:
  PluginLibrary(const std::string& file, const PluginKind& kind);   // throws PluginError naming the file
  ~PluginLibrary();
  PluginLibrary(const PluginLibrary&) = delete;
  PluginLibrary& operator=(const PluginLibrary&) = delete;
  const std::string& file() const { return file_; }
  const std::vector<const void*>& entries() const { return entries_; }
  // The ABI revision the library declares (<prefix>_abi_revision, an optional symbol; 0
  // without it): which appended members its entries carry.
  int revision() const { return revision_; }

 private:
  std::string file_;
  void* handle_ = nullptr;
  int revision_ = 0;
  std::vector<const void*> entries_;
};

// Every entry's common head, as both ABIs lay it out.
struct PluginEntryHead {
  int32_t abi_version;
  const char* name;
  const char* summary;
};

// All plugins of one kind found on the search path, by name.
class PluginCatalog {
 public:
  // `check` returns "" for a usable entry or what is wrong with it.
  using Check = std::string (*)(const void* entry);
  PluginCatalog(PluginKind kind, Check check);
  void add_default_path();                               // 1. and 2. above
  void add(const std::string& folder_or_file, bool from_command_line = true);

  const void* find(const std::string& name) const;       // nullptr if unknown
  std::string file_of(const std::string& name) const;
  int revision_of(const std::string& name) const;        // its library's revision(); 0 if unknown
  const std::vector<std::string>& names() const { return order_; }   // load order
  const std::vector<std::string>& warnings() const { return warnings_; }
  const PluginKind& kind() const { return kind_; }
  // "unknown learner 'X' (available: ...; skipped: ...)" for messages.
  std::string unknown(const std::string& name) const;

 private:
  void load(const std::string& file, bool strict);
  PluginKind kind_;
  Check check_;
  std::vector<std::shared_ptr<PluginLibrary>> libraries_;
  std::map<std::string, std::pair<const void*, std::shared_ptr<PluginLibrary>>> entries_;
  std::vector<std::string> order_, warnings_;
};

// Checks `value` against a key's type and bounds; "" when fine, else the problem.
std::string check_config_value(const spml_config_key& key, const std::string& value);
// The key named `name` in a {NULL}-terminated table, or nullptr.
const spml_config_key* find_config_key(const spml_config_key* table, const std::string& name);
// `given` followed by every key of `table` that it leaves out and that has a default (the
// one place defaults are filled in, for both plugin kinds: a key without a default stays out).
std::vector<std::pair<std::string, std::string>> with_defaults(const spml_config_key* table,
                                                               std::vector<std::pair<std::string, std::string>> given);
// "a, b, c" of a table, for messages.
std::string config_key_list(const spml_config_key* table);

}  // namespace spml
