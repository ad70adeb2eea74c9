// JSON holds only UTF-8 text; nlohmann::json throws a bare "invalid UTF-8 byte at index N" when
// asked to print anything else. Every JSON output (bench.json, --json) is checked with this
// first, so the error can name the field, the text and the byte.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "spml/dataset.h"   // utf8_problem

namespace spml {

struct JsonUtf8Problem {
  std::string field;   // the nearest object key above the text ("" at the top)
  std::string text;    // the text (a value or a key) that is not UTF-8
  std::string why;     // utf8_problem(text); "" when the whole document is UTF-8
};

inline JsonUtf8Problem json_utf8_problem(const nlohmann::json& j, const std::string& field = "") {
  if (j.is_string()) {
    const std::string& text = j.get_ref<const std::string&>();
    if (std::string why = utf8_problem(text); !why.empty()) return {field, text, why};
  } else if (j.is_object()) {
    for (const auto& [k, v] : j.items()) {
      if (std::string why = utf8_problem(k); !why.empty()) return {field, k, why};
      if (auto p = json_utf8_problem(v, k); !p.why.empty()) return p;
    }
  } else if (j.is_array()) {
    for (const auto& v : j)
      if (auto p = json_utf8_problem(v, field); !p.why.empty()) return p;
  }
  return {};
}

}  // namespace spml
