#include "commands.h"
#include "spml/force_effects.h"
#include "spml/parse.h"

namespace spml::cli {

std::uint64_t seed_option(const std::string& option, const std::string& text) {
  const auto v = parse_seed(text);
  if (!v) throw CLI::ValidationError(option, "'" + text + "' is not a seed (a whole number from 0 to 18446744073709551615)");
  return *v;
}

long row_cap_option(const std::string& option, const std::string& text) {
  if (text == "all") return 0;
  const auto v = parse_integer(text, 1, 1000000000000LL);
  if (!v) throw CLI::ValidationError(option, "'" + text + "' is neither 'all' nor a whole number of rows >= 1");
  return static_cast<long>(*v);
}

std::pair<int, int> shard_option(const std::string& option, const std::string& text) {
  const auto slash = text.find('/');
  const auto n = slash == std::string::npos ? std::nullopt : parse_integer(text.substr(slash + 1), 1, 1000000);
  const auto k = n ? parse_integer(text.substr(0, slash), 1, *n) : std::nullopt;
  if (!k) throw CLI::ValidationError(option, "'" + text + "': expected K/N with whole numbers 1 <= K <= N");
  return {static_cast<int>(*k), static_cast<int>(*n)};
}

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

void add_plugin_paths(const std::vector<std::string>& paths) {
  for (const auto& p : paths) force_plugins().add(p, true);
}

}  // namespace spml::cli
