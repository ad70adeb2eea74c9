// Human-readable views of a diagnose report (report.json is the contract; these only read it).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace spml::diagnose_detail {

std::string report_summary(const nlohmann::json& report);    // a few lines for the terminal
std::string report_markdown(const nlohmann::json& report);   // report.md

}  // namespace spml::diagnose_detail
