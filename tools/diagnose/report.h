// Human-readable views of a diagnose report (report.json is the contract; these only read it).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace spml::diagnose_detail {

std::string report_summary(const nlohmann::json& report);    // a few lines for the terminal
// report.md; with_plots: link plots/residuals.png and plots/states.png
std::string report_markdown(const nlohmann::json& report, bool with_plots = true);

// Names as one line, "a, b, c" (the keys of a message).
inline std::string comma_list(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

// The subjects (joint or body names) of the terms of a base parameter's name, e.g.
// "armature:joint1 + 0.5*Izz:link1" -> joint1, link1: exact names, so joint1 is not joint10.
std::vector<std::string> term_subjects(const std::string& base_name);
// Its terms as standard parameter names, their factors dropped ("damping:joint1", "Izz:link1").
std::vector<std::string> term_names(const std::string& base_name);

}  // namespace spml::diagnose_detail
