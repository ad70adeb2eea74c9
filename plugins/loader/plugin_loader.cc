#include "spml/plugin_loader.h"

#include <dlfcn.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "spml/parse.h"

#ifndef SPML_LIB_TO_SHARE
#define SPML_LIB_TO_SHARE "../share/spml"
#endif

namespace spml {

namespace fs = std::filesystem;

std::string spml_lib_dir() {
  static const std::string dir = [] {
    Dl_info info{};
    if (!dladdr(reinterpret_cast<void*>(&spml_lib_dir), &info) || !info.dli_fname)
      throw PluginError("cannot tell where the spml libraries are installed (dladdr failed)");
    return fs::weakly_canonical(fs::path(info.dli_fname)).parent_path().string();
  }();
  return dir;
}

std::string spml_share_dir() {
  if (const char* env = std::getenv("SPML_SHARE_DIR"); env && *env) return env;
  return fs::weakly_canonical(fs::path(spml_lib_dir()) / SPML_LIB_TO_SHARE).string();
}

PluginLibrary::PluginLibrary(const std::string& file, const PluginKind& kind) : file_(file) {
  handle_ = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle_) throw PluginError(file + ": cannot be loaded: " + dlerror());
  const std::string version_symbol = kind.prefix + "_abi_version", get_symbol = kind.prefix + "_get";
  auto version = reinterpret_cast<int32_t (*)()>(dlsym(handle_, version_symbol.c_str()));
  auto get = reinterpret_cast<const void* (*)(int32_t)>(dlsym(handle_, get_symbol.c_str()));
  std::string problem;
  if (!version || !get)
    problem = "missing symbol " + (version ? get_symbol : version_symbol) + " (not an spml " + kind.label + " library?)";
  else if (const int32_t v = version(); v != kind.abi_version)
    problem = kind.label + " ABI version " + std::to_string(v) + ", this spml speaks version " +
              std::to_string(kind.abi_version) + "; rebuild it against this spml";
  if (problem.empty())
    for (int32_t i = 0; const void* e = get(i); ++i) {
      const auto* head = static_cast<const PluginEntryHead*>(e);
      if (head->abi_version != kind.abi_version || !head->name || !*head->name) {
        problem = "entry " + std::to_string(i) + " has ABI version " + std::to_string(head->abi_version) +
                  " or no name";
        break;
      }
      entries_.push_back(e);
    }
  if (problem.empty())
    if (auto revision = reinterpret_cast<int32_t (*)()>(dlsym(handle_, (kind.prefix + "_abi_revision").c_str())))
      revision_ = std::max(0, static_cast<int>(revision()));
  if (!problem.empty()) {
    dlclose(handle_);
    handle_ = nullptr;
    throw PluginError(file + ": " + problem);
  }
}

PluginLibrary::~PluginLibrary() {
  if (handle_) dlclose(handle_);
}

PluginCatalog::PluginCatalog(PluginKind kind, Check check) : kind_(std::move(kind)), check_(check) {}

void PluginCatalog::add_default_path() {
  const fs::path shipped = fs::path(spml_lib_dir()) / "spml" / kind_.folder;
  if (fs::is_directory(shipped)) add(shipped.string(), false);
  if (const char* env = std::getenv(kind_.env_var.c_str())) {
    std::stringstream ss(env);
    std::string dir;
    while (std::getline(ss, dir, ':'))
      if (!dir.empty()) add(dir, false);
  }
}

void PluginCatalog::add(const std::string& where, bool from_command_line) {
  std::error_code ec;
  if (fs::is_directory(where, ec)) {
    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(where, ec))
      if (e.path().extension() == ".so" && e.is_regular_file(ec)) files.push_back(e.path().string());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) load(f, false);
  } else if (fs::is_regular_file(where, ec)) {
    load(where, true);
  } else {
    const std::string msg = where + ": no such " + kind_.label + " library or folder" +
                            (from_command_line ? "" : " (named in $" + kind_.env_var + ")");
    if (from_command_line) throw PluginError(msg);
    warnings_.push_back(msg + "; ignored");
  }
}

void PluginCatalog::load(const std::string& file, bool strict) {
  const std::string canonical = fs::weakly_canonical(file).string();
  for (const auto& lib : libraries_)
    if (lib->file() == canonical) return;
  std::shared_ptr<PluginLibrary> lib;
  try {
    lib = std::make_shared<PluginLibrary>(canonical, kind_);
    for (const void* e : lib->entries()) {
      const auto* head = static_cast<const PluginEntryHead*>(e);
      if (std::string why = check_(e); !why.empty())
        throw PluginError(canonical + ": " + kind_.label + " '" + head->name + "': " + why);
      if (auto it = entries_.find(head->name); it != entries_.end())
        throw PluginError(kind_.label + " '" + std::string(head->name) + "' is provided twice: by " +
                          it->second.second->file() + " and by " + canonical);
    }
  } catch (const PluginError& e) {
    if (strict) throw;
    warnings_.push_back(std::string(e.what()) + "; skipped");
    return;
  }
  for (const void* e : lib->entries()) {
    const std::string name = static_cast<const PluginEntryHead*>(e)->name;
    entries_[name] = {e, lib};
    order_.push_back(name);
  }
  libraries_.push_back(lib);
}

const void* PluginCatalog::find(const std::string& name) const {
  auto it = entries_.find(name);
  return it == entries_.end() ? nullptr : it->second.first;
}

std::string PluginCatalog::file_of(const std::string& name) const {
  auto it = entries_.find(name);
  return it == entries_.end() ? "" : it->second.second->file();
}

int PluginCatalog::revision_of(const std::string& name) const {
  auto it = entries_.find(name);
  return it == entries_.end() ? 0 : it->second.second->revision();
}

std::string PluginCatalog::unknown(const std::string& name) const {
  std::string known;
  for (const auto& n : order_) known += (known.empty() ? "" : ", ") + n;
  std::string msg = "unknown " + kind_.label + " '" + name + "' (available: " + (known.empty() ? "none found" : known);
  for (const auto& w : warnings_) msg += "; " + w;
  return msg + ")";
}

const spml_config_key* find_config_key(const spml_config_key* table, const std::string& name) {
  for (const spml_config_key* k = table; k && k->name; ++k)
    if (name == k->name) return k;
  return nullptr;
}

std::vector<std::pair<std::string, std::string>> with_defaults(const spml_config_key* table,
                                                               std::vector<std::pair<std::string, std::string>> given) {
  const size_t n = given.size();
  for (const spml_config_key* k = table; k && k->name; ++k) {
    if (!k->default_value) continue;
    bool present = false;
    for (size_t i = 0; i < n; ++i) present |= given[i].first == k->name;
    if (!present) given.emplace_back(k->name, k->default_value);
  }
  return given;
}

std::string config_key_list(const spml_config_key* table) {
  std::string out;
  for (const spml_config_key* k = table; k && k->name; ++k) out += (out.empty() ? "" : ", ") + std::string(k->name);
  return out;
}

std::string check_config_value(const spml_config_key& key, const std::string& value) {
  auto bounds = [&](double v) -> std::string {
    if (v >= key.min && v <= key.max) return "";
    std::ostringstream s;
    s << "'" << value << "' is outside [" << key.min << ", " << key.max << "]";
    return s.str();
  };
  switch (key.type) {
    case SPML_VALUE_NUMBER: {
      const auto v = parse_number(value);
      return v ? bounds(*v) : "'" + value + "' is not a finite number";
    }
    case SPML_VALUE_INTEGER: {
      // Bounds clamped to what a long long holds (the table may say +-HUGE_VAL).
      const auto lo = static_cast<long long>(std::max(key.min, -9.2e18)), hi = static_cast<long long>(std::min(key.max, 9.2e18));
      return parse_integer(value, lo, hi) ? ""
                                          : "'" + value + "' is not a whole number in [" + std::to_string(lo) + ", " +
                                                std::to_string(hi) + "]";
    }
    case SPML_VALUE_NUMBERS: {
      const auto v = parse_numbers(value);
      if (!v) return "'" + value + "' is not a comma-separated list of finite numbers";
      for (double x : *v)
        if (std::string b = bounds(x); !b.empty()) return b;
      return "";
    }
    case SPML_VALUE_TEXT:
      return value.empty() || value.find_first_of(" \t\n") != std::string::npos ? "'" + value + "' must be non-empty text without spaces" : "";
  }
  return "key '" + std::string(key.name) + "' has an unknown value type " + std::to_string(key.type);
}

}  // namespace spml
