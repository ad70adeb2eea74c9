#include "spml/import.h"

#include "spml/csv.h"
#include "spml/matrix_file.h"
#include "spml/parse.h"
#include "spml/signal.h"

#include <matio.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
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
  std::string have, other;
  for (const auto& n : table.names) have += (have.empty() ? "" : ", ") + n;
  for (const auto& n : table.left_out) other += (other.empty() ? "" : ", ") + n;
  fail(table.source + ": no column '" + rhs + "' (available: " + have + ")" +
       (other.empty() ? "" : "; vectors of another length, not columns: " + other));
}

// The cells of one CSV line (RFC 4180 quoting: a cell in double quotes may hold the
// delimiter, and "" inside it is one quote); unquoted cells are trimmed of surrounding blanks.
std::vector<std::string> csv_cells(const std::string& line, char delim, const std::string& where) {
  const char* blanks = delim == '\t' ? " " : " \t";
  auto blank = [&](char c) { return c == ' ' || (c == '\t' && delim != '\t'); };
  std::vector<std::string> cells;
  size_t i = 0;
  while (true) {
    while (i < line.size() && blank(line[i])) ++i;
    std::string cell;
    if (i < line.size() && line[i] == '"') {
      for (++i;; ++i) {
        if (i >= line.size()) fail(where + ": a quoted cell is not closed (missing '\"')");
        if (line[i] == '"' && i + 1 < line.size() && line[i + 1] == '"') cell += line[i++];
        else if (line[i] == '"') break;
        else cell += line[i];
      }
      ++i;
      while (i < line.size() && blank(line[i])) ++i;
      if (i < line.size() && line[i] != delim) fail(where + ": text after the closing quote of cell " + std::to_string(cells.size() + 1));
    } else {
      const size_t end = line.find(delim, i);
      cell = line.substr(i, end == std::string::npos ? std::string::npos : end - i);
      const auto e = cell.find_last_not_of(blanks);
      cell = e == std::string::npos ? "" : cell.substr(0, e + 1);
      i = end == std::string::npos ? line.size() : end;
    }
    cells.push_back(std::move(cell));
    if (i >= line.size()) return cells;
    ++i;   // the delimiter
  }
}

}  // namespace

int CsvText::column(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return static_cast<int>(i);
  return -1;
}

CsvText read_csv(const std::string& path, const CsvDialect& dialect) {
  if (dialect.delimiter == '"' || dialect.delimiter == ' ' || dialect.delimiter == '\n' || dialect.delimiter == '\r' ||
      dialect.delimiter == '\0')
    fail(path + ": the delimiter cannot be a quote, a space, a newline or NUL");
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path + ": cannot open");
  std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (content.rfind("\x89HDF\r\n\x1a\n", 0) == 0)
    fail(path + ": is an HDF5 file, not CSV text (import reads CSV or .mat; spml/1 files need no import)");
  if (content.find('\0') != std::string::npos) fail(path + ": is a binary file, not CSV text");
  if (content.rfind("\xEF\xBB\xBF", 0) == 0) content.erase(0, 3);   // a UTF-8 byte order mark is not part of the first name
  CsvText t;
  t.source = path;
  std::istringstream lines(content);
  std::string line;
  size_t lineno = 0;
  while (std::getline(lines, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos) continue;
    if (!dialect.comment.empty() && line.compare(first, dialect.comment.size(), dialect.comment) == 0) continue;
    const std::string where = path + ":" + std::to_string(lineno);
    auto cells = csv_cells(line, dialect.delimiter, where);
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

Table read_csv_table(const std::string& path, const CsvDialect& dialect) {
  const CsvText csv = read_csv(path, dialect);
  Table t;
  t.source = path;
  t.names = csv.header;
  std::vector<Eigen::VectorXd> cols(csv.header.size(), Eigen::VectorXd(static_cast<Eigen::Index>(csv.rows.size())));
  for (size_t r = 0; r < csv.rows.size(); ++r)
    for (size_t c = 0; c < csv.header.size(); ++c) {
      const auto v = parse_number(csv.rows[r][c]);
      if (!v)
        fail(path + ":" + std::to_string(csv.line[r]) + ": column '" + csv.header[c] + "': '" + csv.rows[r][c] +
             "' is not a finite number" +
             (dialect.delimiter != ',' && csv.rows[r][c].find(',') != std::string::npos
                  ? " (decimal commas are not read: export with decimal points)" : ""));
      cols[c][static_cast<Eigen::Index>(r)] = *v;
    }
  t.columns = std::move(cols);
  t.lines = csv.line;
  return t;
}

namespace {

// Element i of a numeric matio variable as a double (every real class MATLAB writes).
template <class T>
double element(const matvar_t* var, size_t i) {
  return static_cast<double>(static_cast<const T*>(var->data)[i]);
}

bool mat_value(const matvar_t* var, size_t i, double& v) {
  switch (var->data_type) {
    case MAT_T_DOUBLE: v = element<double>(var, i); return true;
    case MAT_T_SINGLE: v = element<float>(var, i); return true;
    case MAT_T_INT8: v = element<int8_t>(var, i); return true;
    case MAT_T_UINT8: v = element<uint8_t>(var, i); return true;
    case MAT_T_INT16: v = element<int16_t>(var, i); return true;
    case MAT_T_UINT16: v = element<uint16_t>(var, i); return true;
    case MAT_T_INT32: v = element<int32_t>(var, i); return true;
    case MAT_T_UINT32: v = element<uint32_t>(var, i); return true;
    case MAT_T_INT64: v = element<int64_t>(var, i); return true;
    case MAT_T_UINT64: v = element<uint64_t>(var, i); return true;
    default: return false;
  }
}

// The real numeric vectors and scalars of a .mat file, by name, in file order.
std::vector<std::pair<std::string, Eigen::VectorXd>> mat_vectors(mat_t* mat, const std::string& path) {
  std::vector<std::pair<std::string, Eigen::VectorXd>> vectors;
  matvar_t* var;
  while ((var = Mat_VarReadNext(mat)) != nullptr) {
    const bool numeric = var->class_type == MAT_C_DOUBLE || var->class_type == MAT_C_SINGLE ||
                         (var->class_type >= MAT_C_INT8 && var->class_type <= MAT_C_UINT64);
    if (numeric && var->rank == 2 && !var->isComplex && var->data && (var->dims[0] == 1 || var->dims[1] == 1)) {
      const size_t n = var->dims[0] * var->dims[1];
      Eigen::VectorXd v(static_cast<Eigen::Index>(n));
      for (size_t i = 0; i < n; ++i)
        if (!mat_value(var, i, v[static_cast<Eigen::Index>(i)])) {
          const std::string name = var->name ? var->name : "?", type = std::to_string(static_cast<int>(var->data_type));
          Mat_VarFree(var);
          fail(path + ": variable '" + name + "': numeric data type " + type + " is not supported");
        }
      vectors.emplace_back(var->name ? var->name : "", v);
    }
    Mat_VarFree(var);
  }
  return vectors;
}

// matio reads a truncated v5 file without complaint (the last variables then hold whatever
// was there). Its top-level elements are walked here instead: a 128-byte header, then per
// variable an 8-byte tag (type, byte count) and the data, padded to 8 bytes unless compressed.
void check_mat5_complete(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<unsigned char> b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (b.size() < 128) fail(path + ": truncated .mat file (" + std::to_string(b.size()) + " bytes, shorter than its header)");
  const bool swapped = b[126] == 'M' && b[127] == 'I';   // written on a machine of the other byte order
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    for (int k = 0; k < 4; ++k) v |= static_cast<uint32_t>(b[at + static_cast<size_t>(swapped ? 3 - k : k)]) << (8 * k);
    return v;
  };
  constexpr uint32_t kCompressed = 15;
  for (size_t at = 128, index = 1; at < b.size(); ++index) {
    if (b.size() - at < 8) fail(path + ": truncated .mat file (variable " + std::to_string(index) + " has no complete tag)");
    const uint32_t type = u32(at), bytes = u32(at + 4);
    size_t next = at + 8 + bytes;
    if (type != kCompressed) next += (8 - bytes % 8) % 8;
    if (next > b.size() + (type != kCompressed ? 7 : 0))
      fail(path + ": truncated .mat file (variable " + std::to_string(index) + " needs " + std::to_string(next) +
           " bytes, the file has " + std::to_string(b.size()) + ")");
    at = next;
  }
}

}  // namespace

Table read_mat_table(const std::string& path) {
  quiet_hdf5();   // matio reads v7.3 files through HDF5, which would print its error stack
  mat_t* mat = Mat_Open(path.c_str(), MAT_ACC_RDONLY);
  if (!mat) fail(path + ": not a readable MATLAB .mat file");
  if (Mat_GetVersion(mat) == MAT_FT_MAT5) {
    try {
      check_mat5_complete(path);
    } catch (...) {
      Mat_Close(mat);
      throw;
    }
  }
  Table t;
  t.source = path;
  std::vector<std::pair<std::string, Eigen::VectorXd>> vectors;
  try {
    vectors = mat_vectors(mat, path);
  } catch (...) {
    Mat_Close(mat);
    throw;
  }
  Mat_Close(mat);
  for (auto& [n, v] : vectors)
    if (v.size() == 1) t.scalars[n] = v[0];
  // Columns are the vectors of the most common length (the records; on a tie the longer
  // ones); the other vectors are left out and named when a column is not found.
  std::map<Eigen::Index, int> count;
  for (auto& [n, v] : vectors) if (v.size() > 1) count[v.size()]++;
  Eigen::Index len = 0;
  int best = 0;
  for (auto& [l, c] : count) if (c >= best) { best = c; len = l; }
  for (auto& [n, v] : vectors) {
    if (v.size() == len) { t.names.push_back(n); t.columns.push_back(v); }
    else if (v.size() > 1) t.left_out.push_back(n + " (" + std::to_string(v.size()) + " samples)");
  }
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

namespace {

// The numbers of one text log, read line by line: every non-blank line must hold the same
// count as the first (a sample per line, a value per line, or whole samples per line), so a
// short row followed by a long one cannot shift values between columns.
std::vector<double> read_log_values(const std::string& file, size_t k, const std::string& names) {
  std::ifstream in(file, std::ios::binary);
  if (!in) fail(file + ": cannot open");
  std::vector<double> values;
  std::string line, word;
  size_t lineno = 0, width = 0, first_line = 0;
  while (std::getline(in, line)) {
    ++lineno;
    std::istringstream words(line);
    size_t count = 0;
    while (words >> word) {
      const auto v = parse_number(word);
      if (!v) fail(file + ":" + std::to_string(lineno) + ": '" + word + "' is not a finite number");
      values.push_back(*v);
      ++count;
    }
    if (count == 0) continue;
    if (width == 0) {
      width = count;
      first_line = lineno;
      if (width % k != 0 && k % width != 0)
        fail(file + ":" + std::to_string(lineno) + ": " + std::to_string(width) + " values on a line, but a sample has " +
             std::to_string(k) + " (" + names + "): neither whole samples nor whole parts of one");
    } else if (count != width) {
      fail(file + ":" + std::to_string(lineno) + ": " + std::to_string(count) + " values, but line " +
           std::to_string(first_line) + " and those after it hold " + std::to_string(width) + " (a ragged log; " +
           "a sample has " + std::to_string(k) + ": " + names + ")");
    }
  }
  return values;
}

}  // namespace

Table read_text_logs(const std::vector<std::string>& specs) {
  Table t;
  for (const auto& spec : specs) {
    const auto eq = spec.find('=');
    if (eq == std::string::npos || eq == 0) fail("--text '" + spec + "': expected FILE=NAMES");
    const std::string file = spec.substr(0, eq);
    const std::vector<std::string> names = expand_names(spec.substr(eq + 1));
    for (const auto& n : names)
      if (n.empty()) fail("--text '" + spec + "': " + file + ": empty column name (expected FILE=NAME,NAME,...)");
    if (names.empty()) fail("--text '" + spec + "': " + file + ": no column names after '=' (expected FILE=NAME,NAME,...)");
    const size_t k = names.size();
    const std::vector<double> values = read_log_values(file, k, join_list(names));
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

// The floor is nudged: 1 / median step reads 999.99... at 1 kHz.
int suggested_decimation(double rate_hz, double lowpass_hz) {
  return static_cast<int>(std::floor(rate_hz / std::max(200.0, 10 * lowpass_hz) + 1e-6));
}

namespace {

// The uniform grid with step dt over t's span. A time stamp far off the others (one stray
// t = 1e5 in a 10 s log) would make millions of interpolated rows: refused beyond twice the
// rows measured, naming the largest gap.
Eigen::VectorXd uniform_grid(const Eigen::VectorXd& t, double dt, const std::string& source) {
  const double span = (t[t.size() - 1] - t[0]) / dt;
  if (!(span + 1 <= 2.0 * static_cast<double>(t.size()))) {
    Eigen::Index gap = 1;
    for (Eigen::Index i = 2; i < t.size(); ++i)
      if (t[i] - t[i - 1] > t[gap] - t[gap - 1]) gap = i;
    std::ostringstream msg;
    msg << source << ": time stamps: interpolating onto the median step " << dt << " s would make " << span + 1
        << " rows from " << t.size() << " (the largest gap: row " << gap << ", t = " << t[gap - 1] << " -> " << t[gap]
        << " s); is a time stamp wrong?";
    fail(msg.str());
  }
  const auto n = static_cast<Eigen::Index>(std::floor(span)) + 1;
  return Eigen::VectorXd::LinSpaced(n, t[0], t[0] + dt * static_cast<double>(n - 1));
}

// The decimation's low-pass: kAntiAliasShare of the Nyquist frequency after keeping every K-th.
double anti_alias_cutoff(const Conditioning& c, double dt) { return kAntiAliasShare * 0.5 / (dt * c.decimate); }

// The least cut-off (to 1 %) of an order-`order` low-pass at `rate` whose start-up transient
// settles within `samples`: doubled from `from` until it does, then bisected in the logarithm.
// (Scaling `from` by the settling ratio fails where the settling is capped: a review's 1e-3 Hz
// pass named 0.14 Hz, whose transient is longer than its 30 000-row log.)
double cutoff_settling_within(int order, double from, double rate, Eigen::Index samples) {
  auto settles = [&](double f) { return settling_samples(butterworth_lowpass(order, f, rate)) <= samples; };
  const double top = 0.45 * rate;
  double lo = from, hi = from;
  while (hi < top && !settles(hi)) lo = hi, hi = std::min(2 * hi, top);
  if (hi >= top && !settles(hi)) return top;
  while (hi > 1.01 * lo) {
    const double mid = std::sqrt(lo * hi);
    (settles(mid) ? hi : lo) = mid;
  }
  return hi;
}

// A transient's size as a percentage for a message (a 1e-12 Hz pass overflowed the rounding).
std::string percent_text(double share) {
  return share < 100 ? std::to_string(std::lround(100 * share)) : std::string("more than 10000");
}

// The start-up transient a low-pass pass leaves in the rows kept (`drop` cut at each end),
// relative to their RMS: the pass against the same pass reflected over its whole settling
// (no transient), on what the dataset will hold - a position's second difference where
// `second_difference` (--derive amplifies it most).
double start_up_transient(const std::vector<Eigen::Matrix<double, 5, 1>>& sos, const Eigen::VectorXd& raw, const Eigen::VectorXd& filtered,
                          Eigen::Index settle, Eigen::Index drop, bool second_difference, double dt) {
  Eigen::VectorXd a = filtered, b = filtfilt(sos, raw, settle);
  if (second_difference)
    for (auto* v : {&a, &b}) *v = central_difference(central_difference(*v, dt), dt);
  const Eigen::Index len = raw.size() - 2 * drop;
  const double rms = std::sqrt(b.segment(drop, len).squaredNorm() / static_cast<double>(len));
  return (a - b).segment(drop, len).cwiseAbs().maxCoeff() / std::max(rms, 1e-300);
}

// Steps 1-6 of Conditioning on the chosen columns (in place), with the time column. Returns
// the anti-alias cut-off applied (0: none); `steps` gets the quantization step of each position
// it differentiates, where the raw log has one (spml/1 `position_steps`).
double condition(const Conditioning& c, const std::string& source, Eigen::VectorXd& t, std::vector<Eigen::VectorXd>& xs,
               std::vector<std::string>& xn, std::vector<Eigen::VectorXd>& ys, std::map<std::string, double>& steps,
               double& kept_transient) {
  if (!c.any()) return 0;
  if (c.derive)
    for (size_t k = 0; k < xs.size(); ++k)
      if (xn[k].rfind("q:", 0) == 0)
        if (const auto step = quantization_step(xs[k])) steps[xn[k]] = *step;
  if (t.size() < 3) fail(source + ": filtering, differentiation, edge dropping and decimation need the time column (--t)");
  for (Eigen::Index i = 1; i < t.size(); ++i)
    if (!(t[i] > t[i - 1])) fail(source + ": time stamps must increase; row " + std::to_string(i) + " does not");
  const double dt = median_step(t);
  Eigen::Index settle = 0;   // samples the low-pass's start-up transient reaches into the log
  double transient = 0;      // ... and its largest size in the rows kept, relative to the column's RMS
  std::string transient_column;
  if (uneven_steps(t)) {
    const Eigen::VectorXd grid = uniform_grid(t, dt, source);
    for (auto* cols : {&xs, &ys})
      for (auto& col : *cols) col = interpolate(t, col, grid);
    t = grid;
  }
  if (c.lowpass_hz > 0) {
    if (!(c.lowpass_hz < 0.5 / dt)) {
      std::ostringstream msg;
      msg << source << ": --lowpass " << c.lowpass_hz << " Hz: the cut-off must lie below half the sampling rate, "
          << 0.5 / dt << " Hz (the time column's median step is " << dt << " s)";
      fail(msg.str());
    }
    const auto sos = butterworth_lowpass(c.filter_order, c.lowpass_hz, 1.0 / dt);
    settle = settling_samples(sos);
    for (auto* cols : {&xs, &ys})
      for (size_t k = 0; k < cols->size(); ++k) {
        Eigen::VectorXd& col = (*cols)[k];
        Eigen::VectorXd filtered = filtfilt(sos, col);
        if (settle > c.drop_edges && 2 * c.drop_edges + 2 < col.size()) {
          const bool position = cols == &xs && c.derive && xn[k].rfind("q:", 0) == 0;
          const double off = start_up_transient(sos, col, filtered, settle, c.drop_edges, position, dt);
          if (off > transient)
            transient = off, transient_column = position ? "the second difference of " + xn[k] : cols == &xs ? xn[k] : "target " + std::to_string(k + 1);
        }
        col = std::move(filtered);
      }
  }
  // (derive_like_import, signal.h, restates this chain - low-pass, differences, anti-alias,
  // decimation - for one column, for diagnose's encoders' floor: keep the two in step.)
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
  double anti_alias_hz = 0;
  if (c.decimate > 1 && c.anti_alias) {
    anti_alias_hz = anti_alias_cutoff(c, dt);
    const auto sos = butterworth_lowpass(kAntiAliasOrder, anti_alias_hz, 1.0 / dt);
    for (auto* cols : {&xs, &ys})
      for (auto& col : *cols) col = filtfilt(sos, col);
  }
  const Eigen::Index n = t.size(), drop = c.drop_edges;
  if (2 * drop >= n) fail(source + ": --drop-edges " + std::to_string(drop) + " leaves no rows of " + std::to_string(n));
  // Fewer than 3 rows hold no time step to difference or interpolate (a review's --decimate
  // 40000 wrote a one-row dataset).
  if (const Eigen::Index kept = (n - 2 * drop + c.decimate - 1) / c.decimate; c.decimate > 1 && kept < 3)
    fail(source + ": --decimate " + std::to_string(c.decimate) + " keeps " + std::to_string(kept) + " row" + (kept == 1 ? "" : "s") + " of the " +
         std::to_string(n - 2 * drop) + (drop > 0 ? " left after --drop-edges" : " rows") + "; at most " + std::to_string((n - 2 * drop - 1) / 2) + " keeps 3");
  // Where a log ends while the robot moves, the low-pass starts with a transient that its
  // derivatives amplify: with 50 samples dropped after a 20 Hz pass at 1 kHz (307 to settle),
  // a review's log kept a 2.5 N m error in its last 0.1 s, and diagnose missed a 3 ms delay.
  // Said when it exceeds 1 % of a kept column's RMS (a log that starts and ends at rest has none).
  // Where the transient reaches past the log's middle no drop helps (a review's --lowpass 1e-3
  // was told to drop more samples than the log had): the cut-off that settles within a quarter
  // of the log is said instead (the settling scales with the cut-off's period).
  if (transient > 0.01) {
    kept_transient = transient;
    std::cerr << "spml: warning: " << source << ": ";
    if (2 * settle >= n)
      std::cerr << "--lowpass " << c.lowpass_hz << " Hz: its start-up transient (up to " << percent_text(transient) << " % of the RMS of "
                << transient_column << ") reaches " << settle << " samples (" << static_cast<double>(settle) * dt
                << " s) into each end of a log of " << n << " rows, so no drop leaves a row free of it; a cut-off of "
                << cutoff_settling_within(c.filter_order, c.lowpass_hz, 1 / dt, n / 4) << " Hz or more settles within a quarter of the log\n";
    else
      std::cerr << "--drop-edges " << drop << " keeps part of the low-pass's start-up transient (up to " << percent_text(transient)
                << " % of the RMS of " << transient_column << " in the rows kept), which reaches " << settle << " samples ("
                << static_cast<double>(settle) * dt << " s) into each end of the log: drop at least " << settle << "\n";
  }
  // A band far below the sampling rate keeps all it holds at a fraction of the rows, and
  // diagnose's fits by simulation integrate every row thousands of times (a review's 31 s
  // LuGre log with 3 joints kept at 1 kHz: 54 s, decimated to 200 Hz 12 s, the same causes).
  if (c.lowpass_hz > 0 && c.decimate == 1) {
    const double rate = 1.0 / dt;
    const int k = suggested_decimation(rate, c.lowpass_hz);
    if (k >= 2)
      std::cerr << "spml: note: " << source << ": the " << c.lowpass_hz << " Hz band is sampled at " << rate << " Hz; --decimate " << k
                << " keeps it (" << rate / k << " Hz) and makes diagnose's fits by simulation about " << k << " times cheaper\n";
  }
  auto keep = [&](Eigen::VectorXd& v) {
    Eigen::VectorXd out((n - 2 * drop + c.decimate - 1) / c.decimate);
    for (Eigen::Index i = 0; i < out.size(); ++i) out[i] = v[drop + i * c.decimate];
    v = out;
  };
  keep(t);
  for (auto* cols : {&xs, &ys})
    for (auto& col : *cols) keep(col);
  return anti_alias_hz;
}

// The source column of a spec ("name=source*factor" -> "source").
std::string source_of(const std::string& spec) {
  std::string rhs = spec.substr(spec.find('=') == std::string::npos ? 0 : spec.find('=') + 1);
  return rhs.substr(0, rhs.find('*'));
}

// A column that is both an input and a target would hand the learners the answer.
void check_no_target_leak(const Table& table, const ImportSpec& spec) {
  for (const auto& y : spec.y)
    for (const auto& x : spec.x)
      if (source_of(x) == source_of(y))
        fail(table.source + ": column '" + source_of(y) + "' is both an input (--x " + x + ") and a target (--y " + y +
             "): the target would leak into the inputs");
}

}  // namespace

Dataset table_to_dataset(const Table& table, const ImportSpec& spec) {
  if (spec.x.empty() || spec.y.empty()) fail(table.source + ": choose at least one X and one Y column");
  Dataset ds;
  std::vector<Eigen::VectorXd> xs, ys;
  std::vector<std::string> xn, yn;
  for (const auto& s : spec.x) { std::string n; xs.push_back(resolve_column(table, s, n)); xn.push_back(n); }
  for (const auto& s : spec.y) { std::string n; ys.push_back(resolve_column(table, s, n)); yn.push_back(n); }
  check_no_target_leak(table, spec);
  Eigen::VectorXd tcol;
  if (!spec.t.empty()) {
    std::string n;
    tcol = resolve_column(table, spec.t, n);
    // Where a row is in the file: its line for a CSV, else its place among the data rows.
    auto place = [&](Eigen::Index i) {
      const auto r = static_cast<size_t>(i);
      return r < table.lines.size() ? "line " + std::to_string(table.lines[r]) : "data row " + std::to_string(i + 1);
    };
    for (Eigen::Index i = 1; i < tcol.size(); ++i) {
      std::ostringstream msg;
      msg << table.source << ": column '" << spec.t << "': ";
      if (tcol[i] < tcol[i - 1])
        msg << "rows are not in time order (" << place(i) << ": t = " << tcol[i] << " after t = " << tcol[i - 1]
            << "); sort the rows by time before importing";
      else if (tcol[i] == tcol[i - 1] && spec.conditioning.any())   // filters and differences need a step
        msg << "time stamps must increase; " << place(i) << " repeats t = " << tcol[i] << " of " << place(i - 1)
            << " (remove the duplicate row)";
      else
        continue;
      fail(msg.str());
    }
  }
  std::map<std::string, double> steps;
  double kept_transient = 0;
  const size_t given_columns = xn.size();   // condition() appends the states it derives
  const double anti_alias_hz = condition(spec.conditioning, table.source, tcol, xs, xn, ys, steps, kept_transient);
  const Eigen::Index N = xs.front().size();
  std::vector<SplitRange> ranges = spec.splits;
  if (ranges.empty()) ranges.push_back({"train", "", ""});
  std::vector<std::pair<Eigen::Index, Eigen::Index>> taken;
  for (size_t ri = 0; ri < ranges.size(); ++ri) {
    const SplitRange& r = ranges[ri];
    const std::string where = table.source + ": split '" + r.name + "'";
    Eigen::Index b = parse_bound(r.begin, N, 0, where), e = parse_bound(r.end, N, N, where);
    if (e <= b) fail(where + ": empty row range [" + std::to_string(b) + ", " + std::to_string(e) + ")");
    // The decimation's bound per split (a review's --decimate 14999 over a 64/36 split wrote a
    // one-row test split): fewer than 3 rows hold no time step.
    if (spec.conditioning.decimate > 1 && e - b < 3)
      fail(where + ": --decimate " + std::to_string(spec.conditioning.decimate) + " leaves it " + std::to_string(e - b) + " row" +
           (e - b == 1 ? "" : "s") + " (of " + std::to_string(N) + " kept); a split needs 3");
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
  if (spec.conditioning.derive) {
    ds.provenance["derivatives"] = "central-difference";
    // Which states the differences made (the others were given, and only filtered): what
    // diagnose needs to replay the chain on a known motion (its chain bias).
    std::string derived;
    for (size_t k = given_columns; k < xn.size(); ++k) derived += (derived.empty() ? "" : " ") + xn[k];
    ds.provenance["derived_columns"] = derived;
  }
  if (!steps.empty()) ds.provenance["position_steps"] = position_steps_text(steps);
  // The low-pass's start-up transient the rows kept at the log's ends still hold (the warning
  // above), as a share of the RMS of the column it is largest in.
  if (kept_transient > 0) ds.provenance["start_up_transient"] = std::to_string(kept_transient);
  if (spec.conditioning.decimate > 1) {
    DecimationRecord d{spec.conditioning.decimate, std::nullopt};
    if (anti_alias_hz > 0) d.anti_alias = LowpassRecord{kAntiAliasOrder, anti_alias_hz};
    ds.provenance["decimation"] = decimation_record_text(d);
  }
  validate(ds, table.source);
  return ds;
}

}  // namespace spml
