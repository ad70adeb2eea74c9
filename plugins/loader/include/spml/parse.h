// The one place text becomes numbers in spml (and, for values written to be read back, the
// way back): whole strings only (no trailing junk),
// finite values only, clear messages. Used by the CLI, the dataset import, learner and
// plugin configuration, so that "1e3", " 5" or "abc" mean the same everywhere.
#pragma once

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

namespace spml {

// A finite double spelled out completely by `text`. strtod reports ERANGE both for overflow
// (it returns +-HUGE_VAL, refused as not finite) and for underflow, where it returns the
// nearest double: a subnormal such as 1e-310, or 0 below about 4.9e-324. That is rounding, as
// for any other decimal, so it is accepted.
inline std::optional<double> parse_number(const std::string& text) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text.front()))) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (*end != '\0' || !std::isfinite(v)) return std::nullopt;
  return v;
}

// A whole number in [lo, hi] (no sign tricks: "-1" is not an unsigned 2^64-1).
inline std::optional<long long> parse_integer(const std::string& text, long long lo, long long hi) {
  if (text.empty() || !(std::isdigit(static_cast<unsigned char>(text.front())) || text.front() == '-' || text.front() == '+'))
    return std::nullopt;
  char* end = nullptr;
  errno = 0;
  const long long v = std::strtoll(text.c_str(), &end, 10);
  if (*end != '\0' || errno == ERANGE || v < lo || v > hi) return std::nullopt;
  return v;
}

// An unsigned 64-bit seed: digits only, at most 2^64 - 1.
inline std::optional<std::uint64_t> parse_seed(const std::string& text) {
  if (text.empty() || text.size() > 20) return std::nullopt;
  for (char c : text)
    if (c < '0' || c > '9') return std::nullopt;
  errno = 0;
  char* end = nullptr;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  if (*end != '\0' || errno == ERANGE) return std::nullopt;
  return static_cast<std::uint64_t>(v);
}

// Comma-separated finite numbers; nullopt if any item is not one.
inline std::optional<std::vector<double>> parse_numbers(const std::string& text) {
  std::vector<double> out;
  size_t pos = 0;
  while (true) {
    const size_t comma = text.find(',', pos);
    const auto v = parse_number(text.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos));
    if (!v) return std::nullopt;
    out.push_back(*v);
    if (comma == std::string::npos) return out;
    pos = comma + 1;
  }
}

// The shortest text that parse_number reads back to exactly v (written configurations).
inline std::string exact_text(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

// v for people (reports, tables, messages): `digits` significant digits as printf's %g, or
// with `fixed` that many after the point; "inf", "-inf", "nan" spelled out. For text that is
// read back, exact_text.
inline std::string number_text(double v, int digits = 6, bool fixed = false) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, fixed ? "%.*f" : "%.*g", digits, v);
  return buf;
}

}  // namespace spml
