// The spml/1 dataset format: one HDF5 file, one group per split, X/Y matrices with named
// columns, an optional parametric-model description and provenance attributes.
// The README's "Dataset format" section is the normative description; this header is its
// C++ face. Every reader and writer in spml goes through these functions.
#pragma once

#include <Eigen/Core>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "spml/row_matrix.h"

namespace spml {

inline constexpr const char* kFormatName = "spml/1";

// Any problem with a dataset file: the message names the file and, where it applies, the
// group, dataset and rows involved.
class DatasetError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Split {
  std::string name;
  RowMatrix X;                          // [N, D_in]
  RowMatrix Y;                          // [N, D_out]
  std::vector<std::string> x_columns;   // D_in names
  std::vector<std::string> y_columns;   // D_out names
  Eigen::VectorXd t;                    // optional time stamps [s]; size 0 when absent

  Eigen::Index rows() const { return X.rows(); }
  // Index of a column by name, or -1.
  int x_index(const std::string& column) const;
  int y_index(const std::string& column) const;
  // Rows [begin, end) as a split called `name` (same columns, time stamps if any).
  Split slice(Eigen::Index begin, Eigen::Index end, const std::string& name) const;
};

// The parametric model the data was made with (root group "model"). All fields optional.
struct ModelInfo {
  std::string name;                       // e.g. "planar_arm3", "toy", "via"
  std::vector<std::string> param_names;   // M names
  Eigen::VectorXd prior;                  // M values (or empty)
  Eigen::VectorXd truth;                  // M values (or empty)
  std::string mjcf_path;                  // MJCF the data came from, if any
  std::string mjcf_xml;                   // the MJCF text itself, if stored inline
  bool empty() const { return name.empty() && param_names.empty() && mjcf_path.empty() && mjcf_xml.empty(); }
};

struct Dataset {
  std::string source;                              // the file it was read from ("" if made in memory)
  std::vector<Split> splits;
  ModelInfo model;
  std::map<std::string, std::string> provenance;   // root string attributes besides "format"

  const Split* find(const std::string& split) const;
  const Split& get(const std::string& split) const;   // throws DatasetError naming it
};

struct ReadOptions {
  bool allow_nonfinite = false;   // NaN/Inf in X or Y are rejected unless set
};

// Reads and validates a file. Throws DatasetError with a message naming the file, group,
// dataset and (for non-finite values) the first offending rows.
Dataset read_dataset(const std::string& path, const ReadOptions& options = {});

// Checks the in-memory structure with the same rules the reader applies.
void validate(const Dataset& ds, const std::string& where, const ReadOptions& options = {});

// Writes atomically: the file appears complete under `path` or not at all.
void write_dataset(const std::string& path, const Dataset& ds);

// "" for valid UTF-8, else which byte is not (names and attributes must be UTF-8: the format
// says so, and JSON outputs such as bench.json and report.json cannot hold anything else).
std::string utf8_problem(const std::string& text);

// Comma-separated list helpers used for the `columns` attribute.
std::vector<std::string> split_list(const std::string& text, char sep = ',');
std::string join_list(const std::vector<std::string>& items, char sep = ',');

}  // namespace spml
