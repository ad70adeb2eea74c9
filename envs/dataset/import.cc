#include "spml/import.h"

#include "spml/csv.h"
#include "spml/parse.h"
#include "spml/signal.h"

#include <matio.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <sstream>

namespace spml {
namespace {

[[noreturn]] void fail(const std::string& msg) { throw DatasetError(msg); }

bool parse_double(const std::string& text, double& value) {
  const auto v = parse_number(text);
  if (v) value = *v;
  return v.has_value();
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

int CsvText::column(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return static_cast<int>(i);
  return -1;
}

CsvText read_csv(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path + ": cannot open");
  std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (content.rfind("\x89HDF\r\n\x1a\n", 0) == 0)
    fail(path + ": is an HDF5 file, not CSV text (import reads CSV or .mat; spml/1 files need no import)");
  if (content.find('\0') != std::string::npos) fail(path + ": is a binary file, not CSV text");
  CsvText t;
  t.source = path;
  std::istringstream lines(content);
  std::string line;
  size_t lineno = 0;
  while (std::getline(lines, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    auto cells = split_list(line);
    const std::string where = path + ":" + std::to_string(lineno);
    if (t.header.empty()) {
      for (size_t i = 0; i < cells.size(); ++i) {
        if (cells[i].empty()) fail(where + ": header column " + std::to_string(i + 1) + " has no name");
        for (size_t j = 0; j < i; ++j)
          if (cells[j] == cells[i]) fail(where + ": header names column '" + cells[i] + "' twice");
      }
      t.header = std::move(cells);
      continue;
    }
    if (cells.size() != t.header.size())
      fail(where + ": " + std::to_string(cells.size()) + " fields, header has " + std::to_string(t.header.size()));
    t.rows.push_back(std::move(cells));
    t.line.push_back(lineno);
  }
  if (t.header.empty()) fail(path + ": empty file (expected a header row)");
  return t;
}

Table read_csv_table(const std::string& path) {
  const CsvText csv = read_csv(path);
  Table t;
  t.source = path;
  t.names = csv.header;
  std::vector<Eigen::VectorXd> cols(csv.header.size(), Eigen::VectorXd(static_cast<Eigen::Index>(csv.rows.size())));
  for (size_t r = 0; r < csv.rows.size(); ++r)
    for (size_t c = 0; c < csv.header.size(); ++c) {
      const auto v = parse_number(csv.rows[r][c]);
      if (!v)
        fail(path + ":" + std::to_string(csv.line[r]) + ": column '" + csv.header[c] + "': '" + csv.rows[r][c] +
             "' is not a finite number");
      cols[c][static_cast<Eigen::Index>(r)] = *v;
    }
  t.columns = std::move(cols);
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

std::vector<std::string> expand_names(const std::string& list) {
  std::vector<std::string> out;
  for (const auto& item : split_list(list)) {
    const auto open = item.find('{'), dots = item.find("..", open == std::string::npos ? 0 : open),
               close = item.find('}', dots == std::string::npos ? 0 : dots);
    if (open == std::string::npos || dots == std::string::npos || close == std::string::npos) {
      out.push_back(item);
      continue;
    }
    const auto a = parse_integer(item.substr(open + 1, dots - open - 1), -1000000, 1000000),
               b = parse_integer(item.substr(dots + 2, close - dots - 2), -1000000, 1000000);
    if (!a || !b || *b < *a || *b - *a > 10000) fail("'" + item + "': expected {first..last} with whole numbers");
    for (long long k = *a; k <= *b; ++k)
      out.push_back(item.substr(0, open) + std::to_string(k) + item.substr(close + 1));
  }
  return out;
}

Table read_text_logs(const std::vector<std::string>& specs) {
  Table t;
  for (const auto& spec : specs) {
    const auto eq = spec.find('=');
    if (eq == std::string::npos || eq == 0) fail("--text '" + spec + "': expected FILE=NAMES");
    const std::string file = spec.substr(0, eq);
    const std::vector<std::string> names = expand_names(spec.substr(eq + 1));
    std::ifstream in(file, std::ios::binary);
    if (!in) fail(file + ": cannot open");
    std::vector<double> values;
    std::string word;
    while (in >> word) {
      const auto v = parse_number(word);
      if (!v) fail(file + ": value " + std::to_string(values.size() + 1) + ": '" + word + "' is not a finite number");
      values.push_back(*v);
    }
    const size_t k = names.size();
    if (values.empty() || values.size() % k != 0)
      fail(file + ": " + std::to_string(values.size()) + " values are not a whole number of samples of " +
           std::to_string(k) + " (" + join_list(names) + ")");
    const auto n = static_cast<Eigen::Index>(values.size() / k);
    if (t.rows() && n != t.rows())
      fail(file + ": " + std::to_string(n) + " samples, but " + t.source + " has " + std::to_string(t.rows()));
    for (size_t c = 0; c < k; ++c) {
      Eigen::VectorXd col(n);
      for (Eigen::Index i = 0; i < n; ++i) col[i] = values[static_cast<size_t>(i) * k + c];
      if (std::find(t.names.begin(), t.names.end(), names[c]) != t.names.end()) fail(file + ": column '" + names[c] + "' named twice");
      t.names.push_back(names[c]);
      t.columns.push_back(std::move(col));
    }
    t.source = t.source.empty() ? file : t.source;
  }
  if (t.names.empty()) fail("no --text logs given");
  return t;
}

namespace {

// Steps 1-5 of Conditioning on the chosen columns (in place), with the time column.
void condition(const Conditioning& c, const std::string& source, Eigen::VectorXd& t, std::vector<Eigen::VectorXd>& xs,
               std::vector<std::string>& xn, std::vector<Eigen::VectorXd>& ys) {
  if (!c.any()) return;
  if (t.size() < 3) fail(source + ": filtering, differentiation, edge dropping and decimation need the time column (--t)");
  for (Eigen::Index i = 1; i < t.size(); ++i)
    if (!(t[i] > t[i - 1])) fail(source + ": time stamps must increase; row " + std::to_string(i) + " does not");
  const double dt = median_step(t);
  if (uneven_steps(t)) {
    const auto n = static_cast<Eigen::Index>(std::floor((t[t.size() - 1] - t[0]) / dt)) + 1;
    const Eigen::VectorXd grid = Eigen::VectorXd::LinSpaced(n, t[0], t[0] + dt * static_cast<double>(n - 1));
    for (auto* cols : {&xs, &ys})
      for (auto& col : *cols) col = interpolate(t, col, grid);
    t = grid;
  }
  if (c.lowpass_hz > 0) {
    const auto sos = butterworth_lowpass(c.filter_order, c.lowpass_hz, 1.0 / dt);
    for (auto* cols : {&xs, &ys})
      for (auto& col : *cols) col = filtfilt(sos, col);
  }
  if (c.derive) {
    const size_t given = xn.size();
    for (size_t j = 0; j < given; ++j) {
      if (xn[j].rfind("q:", 0) != 0) continue;
      const std::string joint = xn[j].substr(2);
      const auto qd_it = std::find(xn.begin(), xn.end(), "qd:" + joint);
      Eigen::VectorXd qd = qd_it != xn.end() ? xs[static_cast<size_t>(qd_it - xn.begin())] : central_difference(xs[j], dt);
      if (qd_it == xn.end()) {
        xs.push_back(qd);
        xn.push_back("qd:" + joint);
      }
      if (std::find(xn.begin(), xn.end(), "qdd:" + joint) == xn.end()) {
        xs.push_back(central_difference(qd, dt));
        xn.push_back("qdd:" + joint);
      }
    }
  }
  const Eigen::Index n = t.size(), drop = c.drop_edges;
  if (2 * drop >= n) fail(source + ": --drop-edges " + std::to_string(drop) + " leaves no rows of " + std::to_string(n));
  auto keep = [&](Eigen::VectorXd& v) {
    Eigen::VectorXd out((n - 2 * drop + c.decimate - 1) / c.decimate);
    for (Eigen::Index i = 0; i < out.size(); ++i) out[i] = v[drop + i * c.decimate];
    v = out;
  };
  keep(t);
  for (auto* cols : {&xs, &ys})
    for (auto& col : *cols) keep(col);
}

}  // namespace

Dataset table_to_dataset(const Table& table, const ImportSpec& spec) {
  if (spec.x.empty() || spec.y.empty()) fail(table.source + ": choose at least one X and one Y column");
  Dataset ds;
  std::vector<Eigen::VectorXd> xs, ys;
  std::vector<std::string> xn, yn;
  for (const auto& s : spec.x) { std::string n; xs.push_back(resolve_column(table, s, n)); xn.push_back(n); }
  for (const auto& s : spec.y) { std::string n; ys.push_back(resolve_column(table, s, n)); yn.push_back(n); }
  Eigen::VectorXd tcol;
  if (!spec.t.empty()) { std::string n; tcol = resolve_column(table, spec.t, n); }
  condition(spec.conditioning, table.source, tcol, xs, xn, ys);
  const Eigen::Index N = xs.front().size();
  std::vector<SplitRange> ranges = spec.splits;
  if (ranges.empty()) ranges.push_back({"train", "", ""});
  std::vector<std::pair<Eigen::Index, Eigen::Index>> taken;
  for (size_t ri = 0; ri < ranges.size(); ++ri) {
    const SplitRange& r = ranges[ri];
    const std::string where = table.source + ": split '" + r.name + "'";
    Eigen::Index b = parse_bound(r.begin, N, 0, where), e = parse_bound(r.end, N, N, where);
    if (e <= b) fail(where + ": empty row range [" + std::to_string(b) + ", " + std::to_string(e) + ")");
    // Overlapping splits would leak training rows into a test split.
    for (size_t k = 0; k < taken.size(); ++k)
      if (b < taken[k].second && taken[k].first < e)
        fail(where + ": rows [" + std::to_string(b) + ", " + std::to_string(e) + ") overlap split '" + ranges[k].name +
             "' rows [" + std::to_string(taken[k].first) + ", " + std::to_string(taken[k].second) + ")");
    taken.emplace_back(b, e);
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
  // What the signals went through, so that consumers can filter their model columns alike
  // (README, spml/1: `filter`, `derivatives`).
  if (spec.conditioning.lowpass_hz > 0)
    ds.provenance["filter"] = lowpass_record_text({spec.conditioning.filter_order, spec.conditioning.lowpass_hz});
  if (spec.conditioning.derive) ds.provenance["derivatives"] = "central-difference";
  validate(ds, table.source);
  return ds;
}

}  // namespace spml
