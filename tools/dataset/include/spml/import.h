// Turning foreign tables (CSV with a header row, MATLAB .mat files) into spml/1 datasets.
#pragma once

#include <string>
#include <vector>

#include "spml/dataset.h"

namespace spml {

// Named columns of equal length, as read from a CSV or .mat file.
struct Table {
  std::string source;                    // file name, for messages
  std::vector<std::string> names;
  std::vector<Eigen::VectorXd> columns;
  std::map<std::string, double> scalars; // 1x1 variables of a .mat file (gains, constants)
  Eigen::Index rows() const { return columns.empty() ? 0 : columns.front().size(); }
};

Table read_csv_table(const std::string& path);
Table read_mat_table(const std::string& path);

// A split of the imported rows: [begin, end). Bounds are given as row numbers or percentages
// ("train:0:64%", "test:64%:", "all::").
struct SplitRange {
  std::string name;
  std::string begin, end;
};
SplitRange parse_split_range(const std::string& text);

// Which columns become X, Y and t. Each entry is "source" or "name=source" or
// "name=source*factor", where factor is a number or a scalar of the table.
struct ImportSpec {
  std::vector<std::string> x, y;
  std::string t;
  std::vector<SplitRange> splits;   // empty: a single split "train" with every row
};

Dataset table_to_dataset(const Table& table, const ImportSpec& spec);

}  // namespace spml
