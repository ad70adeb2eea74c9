#include "commands.h"
#include "spml/force_effects.h"
#include "spml/json_utf8.h"
#include "spml/parse.h"

#include <sstream>

namespace spml::cli {

std::uint64_t seed_option(const std::string& option, const std::string& text) {
  const auto v = parse_seed(text);
  if (!v) throw CLI::ValidationError(option, "'" + text + "' is not a seed (a whole number from 0 to 18446744073709551615)");
  return *v;
}

namespace {

std::string range_text(double lo, double hi, bool lo_open) {
  std::ostringstream s;
  s << (lo_open ? "(" : "[") << lo << ", " << hi << "]";
  return s.str();
}

// "" when `text` is a finite number in the range, else why not.
std::string finite_problem(const std::string& text, double lo, double hi, bool lo_open) {
  const auto v = parse_number(text);
  const std::string range = range_text(lo, hi, lo_open);
  if (!v) return "'" + text + "' is not a finite number (expected one in " + range + ")";
  if (*v < lo || *v > hi || (lo_open && *v == lo)) return "'" + text + "' is outside " + range;
  return "";
}

}  // namespace

CLI::Validator finite_number(double lo, double hi, bool lo_open) {
  return CLI::Validator([=](std::string& text) { return finite_problem(text, lo, hi, lo_open); },
                        "FINITE in " + range_text(lo, hi, lo_open));
}

double finite_option(const std::string& option, const std::string& text, double lo, double hi, bool lo_open) {
  if (const std::string why = finite_problem(text, lo, hi, lo_open); !why.empty()) throw CLI::ValidationError(option, why);
  return *parse_number(text);
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

std::string json_output(const nlohmann::json& j, const std::string& source) {
  if (const JsonUtf8Problem p = json_utf8_problem(j); !p.why.empty())
    throw std::runtime_error(source + ": " + (p.field.empty() ? "" : "--json field '" + p.field + "': ") + "'" + p.text + "' is " +
                             p.why + "; --json prints JSON, which holds only UTF-8 text (run without --json, or rename it)");
  return j.dump(2) + "\n";
}

void add_plugin_paths(const std::vector<std::string>& paths) {
  for (const auto& p : paths) force_plugins().add(p, true);
}

}  // namespace spml::cli
