// Human-readable views of a diagnose report (report.json is the contract; these only read it).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace spml::diagnose_detail {

std::string report_summary(const nlohmann::json& report);    // a few lines for the terminal
// report.md; with_plots: link plots/residuals.png and plots/states.png
std::string report_markdown(const nlohmann::json& report, bool with_plots = true);

}  // namespace spml::diagnose_detail
