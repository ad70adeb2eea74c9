// `spml compare`: our results.csv beside the paper's tables (data/published), with per-row
// deltas and rank agreement.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "spml/learners/results.h"

namespace spml {

// The paper's tables shipped with spml: <share>/published.
std::string default_published_dir();


// Rank agreement between two score lists over the same items (lower is better).
double spearman_rho(const std::vector<double>& a, const std::vector<double>& b);
double kendall_tau(const std::vector<double>& a, const std::vector<double>& b);

// The printed comparison for every (scenario, split, output) group in `results`.
std::string compare_report(const std::vector<ResultRow>& results, const std::string& published_dir);
// The same as one JSON document (format spml-compare/1): groups[] (scenario, split, output,
// output_index, unit, paper_table, learners[], not_run[], rank_agreement), scoreboard[],
// tables, beats; numbers that are not finite are null.
nlohmann::json compare_json(const std::vector<ResultRow>& results, const std::string& published_dir);

}  // namespace spml
