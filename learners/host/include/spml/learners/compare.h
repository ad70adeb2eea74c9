// `spml compare`: our results.csv beside the paper's tables (data/published), with per-row
// deltas and rank agreement.
#pragma once

#include <string>
#include <vector>

namespace spml {

struct ResultRow {
  std::string scenario, split, algo;
  int output = 0;
  double rmse_mean = 0, rmse_std = 0, rmse_min = 0, rmse_max = 0;
  double nllh_mean = 0, nllh_std = 0, nllh_min = 0, nllh_max = 0;
  std::string warnings;
};

// Reads a results.csv written by `spml bench`; throws naming the file, line and column.
std::vector<ResultRow> read_results(const std::string& path);
// Reads one of the paper's tables (algo,rmsemean,...; "-" = not given, "inf").
std::vector<ResultRow> read_published_table(const std::string& path);

std::string default_published_dir();

// Paper spellings that differ from ours ("SPGP-from-zeroes").
std::string canonical_algo(const std::string& name);

// Rank agreement between two score lists over the same items (lower is better).
double spearman_rho(const std::vector<double>& a, const std::vector<double>& b);
double kendall_tau(const std::vector<double>& a, const std::vector<double>& b);

// The printed comparison for every (scenario, split, output) group in `results`.
std::string compare_report(const std::vector<ResultRow>& results, const std::string& published_dir);

}  // namespace spml
