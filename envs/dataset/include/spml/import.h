// Turning foreign tables (CSV with a header row, MATLAB .mat files) into spml/1 datasets.
#pragma once

#include "spml/csv.h"

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
  std::vector<std::string> left_out;     // .mat vectors of another length than the columns, "name (n samples)"
  std::vector<size_t> lines;             // CSV: the file line of each row (for messages); else empty
  Eigen::Index rows() const { return columns.empty() ? 0 : columns.front().size(); }
};

Table read_csv_table(const std::string& path, const CsvDialect& dialect = {});
Table read_mat_table(const std::string& path);
// Text logs of whitespace-separated numbers, each holding len(names) consecutive values per
// sample (e.g. 7 joint positions): "FILE=NAMES" with NAMES comma-separated, "{a..b}"
// expanded ("q:joint{1..7}"). Several logs become one table; their sample counts must agree.
Table read_text_logs(const std::vector<std::string>& specs);
// "q:joint{1..3}" -> q:joint1, q:joint2, q:joint3 (one brace group at most per name).
std::vector<std::string> expand_names(const std::string& list);

// A split of the imported rows: [begin, end). Bounds are given as row numbers or percentages
// ("train:0:64%", "test:64%:", "all::").
struct SplitRange {
  std::string name;
  std::string begin, end;
};
SplitRange parse_split_range(const std::string& text);

// Which columns become X, Y and t. Each entry is "source" or "name=source" or
// "name=source*factor", where factor is a number or a scalar of the table.
// Signal conditioning for measured data, applied in this order before the splits are cut
// (all of it needs the time column):
//   1. uneven time stamps (steps more than 1 % off their median): every column linearly
//      interpolated onto a uniform grid with the median step;
//   2. lowpass_hz > 0: zero-phase Butterworth low-pass (order `filter_order`, forward-backward)
//      on every X and Y column;
//   3. derive: for every X column q:<joint>, qd:<joint> by central differences of q unless
//      X has it (measured velocities are kept, filtered), and qdd:<joint> by central
//      differences of qd;
//   4. decimate > 1 (and anti_alias): zero-phase Butterworth low-pass of order kAntiAliasOrder
//      at kAntiAliasShare of the decimated Nyquist frequency on every X and Y column;
//   5. drop_edges samples removed at each end (filter and difference transients);
//   6. every decimate-th sample kept.
constexpr int kAntiAliasOrder = 8;
constexpr double kAntiAliasShare = 0.8;

struct Conditioning {
  double lowpass_hz = 0;
  int filter_order = 4;
  bool derive = false;
  int drop_edges = 0;
  int decimate = 1;
  // Step 4, as signal processing means decimation: keeping every K-th sample of raw
  // differences alone folds their noise, which lies near the old Nyquist frequency, into the
  // band (the parallel decimation of IDIM, Gautier 1997). false: plain subsampling.
  bool anti_alias = true;
  bool any() const { return lowpass_hz > 0 || derive || drop_edges > 0 || decimate > 1; }
};

// The decimation that keeps a band of `lowpass_hz` sampled at `rate_hz`: a rate of ten times
// the band, 200 Hz at least (what spml import's note suggests; 1 or less: none).
int suggested_decimation(double rate_hz, double lowpass_hz);

struct ImportSpec {
  std::vector<std::string> x, y;
  std::string t;
  std::vector<SplitRange> splits;   // empty: a single split "train" with every row
  Conditioning conditioning;
};

Dataset table_to_dataset(const Table& table, const ImportSpec& spec);

}  // namespace spml
