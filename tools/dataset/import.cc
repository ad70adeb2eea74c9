#include "spml/import.h"

#include <matio.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace spml {
namespace {

[[noreturn]] void fail(const std::string& msg) { throw DatasetError(msg); }

bool parse_double(const std::string& text, double& value) {
  if (text.empty()) return false;
  char* end = nullptr;
  value = std::strtod(text.c_str(), &end);
  return end && *end == '\0';
}

Eigen::Index parse_bound(const std::string& text, Eigen::Index rows, Eigen::Index fallback, const std::string& where) {
  if (text.empty()) return fallback;
  double v = 0;
  if (text.back() == '%') {
    if (!parse_double(text.substr(0, text.size() - 1), v) || v < 0 || v > 100)
      fail(where + ": bad percentage '" + text + "'");
    return static_cast<Eigen::Index>(std::llround(v / 100.0 * static_cast<double>(rows)));
  }
  if (!parse_double(text, v) || v < 0 || v != std::floor(v)) fail(where + ": bad row number '" + text + "'");
  if (v > static_cast<double>(rows)) fail(where + ": row " + text + " is past the end (" + std::to_string(rows) + " rows)");
  return static_cast<Eigen::Index>(v);
}

// "name=source*factor" -> column values and the output name.
Eigen::VectorXd resolve_column(const Table& table, const std::string& spec, std::string& name) {
  std::string rhs = spec;
  auto eq = spec.find('=');
  if (eq != std::string::npos) {
    name = spec.substr(0, eq);
    rhs = spec.substr(eq + 1);
  }
  double factor = 1.0;
  auto star = rhs.find('*');
  if (star != std::string::npos) {
    std::string f = rhs.substr(star + 1);
    rhs = rhs.substr(0, star);
    auto it = table.scalars.find(f);
    if (it != table.scalars.end())
      factor = it->second;
    else if (!parse_double(f, factor))
      fail(table.source + ": factor '" + f + "' in '" + spec + "' is neither a number nor a scalar of the file");
  }
  if (eq == std::string::npos) name = rhs;
  for (size_t i = 0; i < table.names.size(); ++i)
    if (table.names[i] == rhs) return table.columns[i] * factor;
  std::string have;
  for (const auto& n : table.names) have += (have.empty() ? "" : ", ") + n;
  fail(table.source + ": no column '" + rhs + "' (available: " + have + ")");
}

}  // namespace

Table read_csv_table(const std::string& path) {
  std::ifstream in(path);
  if (!in) fail(path + ": cannot open");
  Table t;
  t.source = path;
  std::string line;
  size_t lineno = 0;
  std::vector<std::vector<double>> cols;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    auto cells = split_list(line);
    if (t.names.empty()) {
      t.names = cells;
      for (size_t i = 0; i < cells.size(); ++i)
        if (cells[i].empty()) fail(path + ":" + std::to_string(lineno) + ": header column " + std::to_string(i + 1) + " has no name");
      cols.resize(cells.size());
      continue;
    }
    if (cells.size() != t.names.size())
      fail(path + ":" + std::to_string(lineno) + ": " + std::to_string(cells.size()) + " fields, header has " +
           std::to_string(t.names.size()));
    for (size_t i = 0; i < cells.size(); ++i) {
      double v;
      if (!parse_double(cells[i], v))
        fail(path + ":" + std::to_string(lineno) + ": column '" + t.names[i] + "': '" + cells[i] + "' is not a number");
      cols[i].push_back(v);
    }
  }
  if (t.names.empty()) fail(path + ": empty file (expected a header row)");
  for (auto& c : cols) t.columns.push_back(Eigen::Map<Eigen::VectorXd>(c.data(), static_cast<Eigen::Index>(c.size())));
  return t;
}

Table read_mat_table(const std::string& path) {
  mat_t* mat = Mat_Open(path.c_str(), MAT_ACC_RDONLY);
  if (!mat) fail(path + ": not a readable MATLAB .mat file");
  Table t;
  t.source = path;
  std::vector<std::pair<std::string, Eigen::VectorXd>> vectors;
  matvar_t* var;
  while ((var = Mat_VarReadNext(mat)) != nullptr) {
    bool numeric = var->class_type == MAT_C_DOUBLE || var->class_type == MAT_C_SINGLE ||
                   (var->class_type >= MAT_C_INT8 && var->class_type <= MAT_C_UINT64);
    if (numeric && var->rank == 2 && !var->isComplex && var->data) {
      size_t n = var->dims[0] * var->dims[1];
      if (var->dims[0] == 1 || var->dims[1] == 1) {
        Eigen::VectorXd v(static_cast<Eigen::Index>(n));
        for (size_t i = 0; i < n; ++i) {
          switch (var->data_type) {
            case MAT_T_DOUBLE: v[i] = static_cast<const double*>(var->data)[i]; break;
            case MAT_T_SINGLE: v[i] = static_cast<const float*>(var->data)[i]; break;
            case MAT_T_INT32: v[i] = static_cast<const int32_t*>(var->data)[i]; break;
            case MAT_T_UINT8: v[i] = static_cast<const uint8_t*>(var->data)[i]; break;
            default: v[i] = std::nan("");
          }
        }
        if (n == 1) t.scalars[var->name] = v[0];
        vectors.emplace_back(var->name, v);
      }
    }
    Mat_VarFree(var);
  }
  Mat_Close(mat);
  // Columns are the vectors of the most common length (the records); others stay scalars.
  std::map<Eigen::Index, int> count;
  for (auto& [n, v] : vectors) if (v.size() > 1) count[v.size()]++;
  Eigen::Index len = 0;
  int best = 0;
  for (auto& [l, c] : count) if (c > best) { best = c; len = l; }
  for (auto& [n, v] : vectors)
    if (v.size() == len) { t.names.push_back(n); t.columns.push_back(v); }
  if (t.names.empty()) fail(path + ": no numeric vector variables found");
  return t;
}

SplitRange parse_split_range(const std::string& text) {
  auto parts = split_list(text, ':');
  if (parts.size() != 3 || parts[0].empty())
    fail("split '" + text + "': expected NAME:BEGIN:END (rows or percentages, e.g. train:0:64% or test:64%:)");
  return {parts[0], parts[1], parts[2]};
}

Dataset table_to_dataset(const Table& table, const ImportSpec& spec) {
  if (spec.x.empty() || spec.y.empty()) fail(table.source + ": choose at least one X and one Y column");
  Dataset ds;
  const Eigen::Index N = table.rows();
  std::vector<Eigen::VectorXd> xs, ys;
  std::vector<std::string> xn, yn;
  for (const auto& s : spec.x) { std::string n; xs.push_back(resolve_column(table, s, n)); xn.push_back(n); }
  for (const auto& s : spec.y) { std::string n; ys.push_back(resolve_column(table, s, n)); yn.push_back(n); }
  Eigen::VectorXd tcol;
  if (!spec.t.empty()) { std::string n; tcol = resolve_column(table, spec.t, n); }
  std::vector<SplitRange> ranges = spec.splits;
  if (ranges.empty()) ranges.push_back({"train", "", ""});
  for (const auto& r : ranges) {
    const std::string where = table.source + ": split '" + r.name + "'";
    Eigen::Index b = parse_bound(r.begin, N, 0, where), e = parse_bound(r.end, N, N, where);
    if (e <= b) fail(where + ": empty row range [" + std::to_string(b) + ", " + std::to_string(e) + ")");
    Split s;
    s.name = r.name;
    s.x_columns = xn;
    s.y_columns = yn;
    s.X.resize(e - b, static_cast<Eigen::Index>(xs.size()));
    s.Y.resize(e - b, static_cast<Eigen::Index>(ys.size()));
    for (size_t j = 0; j < xs.size(); ++j) s.X.col(j) = xs[j].segment(b, e - b);
    for (size_t j = 0; j < ys.size(); ++j) s.Y.col(j) = ys[j].segment(b, e - b);
    if (tcol.size()) s.t = tcol.segment(b, e - b);
    ds.splits.push_back(std::move(s));
  }
  ds.provenance["source"] = table.source;
  ds.provenance["generator"] = "spml import";
  validate(ds, table.source);
  return ds;
}

}  // namespace spml
