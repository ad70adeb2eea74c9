#include "spml/learners/results.h"

#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "spml/csv.h"
#include "spml/dataset.h"
#include "spml/parse.h"

namespace spml {
namespace {

constexpr const char* kColumns[] = {"scenario", "split",    "output",  "output_index", "unit",    "algo",
                                    "rmsemean", "rmsestd",  "rmsemin", "rmsemax",      "nllhmean", "nllhstd",
                                    "nllhmin",  "nllhmax",  "fits",    "fitsec",       "warnings"};

// A text field of results.csv: one line (newlines become spaces), in double quotes when it
// holds a comma or a quote (RFC 4180: a quote inside is doubled), so that a data file or split
// called "a,b" stays one field for compare, plot and any CSV reader.
std::string field(std::string text) {
  for (char& c : text)
    if (c == '\n' || c == '\r') c = ' ';
  if (text.find_first_of(",\"") == std::string::npos && (text.empty() || (text.front() != ' ' && text.back() != ' ')))
    return text;
  std::string q = "\"";
  for (char c : text) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

double number(const std::string& text, const std::string& where, bool allow_missing) {
  if (text == "inf") return std::numeric_limits<double>::infinity();
  if (allow_missing && (text == "-" || text.empty())) return std::numeric_limits<double>::quiet_NaN();
  const auto v = parse_number(text);
  if (!v) throw DatasetError(where + ": '" + text + "' is not a number");
  return *v;
}

std::vector<ResultRow> parse_rows(const std::string& path, bool published) {
  const CsvText csv = read_csv(path);
  auto required = [&](std::initializer_list<const char*> names) {
    for (const char* n : names)
      if (int c = csv.column(n); c >= 0) return static_cast<size_t>(c);
    throw DatasetError(path + ": column '" + *names.begin() + "' is missing");
  };
  const size_t algo = required({"algo"});
  const size_t cols[8] = {required({"rmsemean"}), required({"rmsestd"}), required({"rmsemin", "rmseamin"}),
                          required({"rmsemax", "rmseamax"}), required({"nllhmean"}), required({"nllhstd"}),
                          required({"nllhmin", "nllhamin"}), required({"nllhmax", "nllhamax"})};
  size_t scenario = 0, split = 0, output = 0;
  if (!published) {
    scenario = required({"scenario"});
    split = required({"split"});
    output = required({"output"});
  }
  // Schema 2 names the output and gives its index in `output_index`; schema 1 has the index in `output`.
  const int index = csv.column("output_index"), unit = csv.column("unit");
  const int fits = csv.column("fits"), fitsec = csv.column("fitsec"), warnings = csv.column("warnings");
  std::vector<ResultRow> out;
  for (size_t i = 0; i < csv.rows.size(); ++i) {
    const auto& r = csv.rows[i];
    const std::string line = path + ": line " + std::to_string(csv.line[i]);
    ResultRow row;
    row.algo = canonical_algo(r[algo]);
    double* fields[8] = {&row.rmse_mean, &row.rmse_std, &row.rmse_min, &row.rmse_max,
                         &row.nllh_mean, &row.nllh_std, &row.nllh_min, &row.nllh_max};
    for (int k = 0; k < 8; ++k) *fields[k] = number(r[cols[k]], line + " column '" + csv.header[cols[k]] + "'", published);
    if (!published) {
      row.scenario = r[scenario];
      row.split = r[split];
      const size_t ic = index >= 0 ? static_cast<size_t>(index) : output;
      const auto o = parse_integer(r[ic], 0, 1 << 30);
      if (!o) throw DatasetError(line + " column '" + csv.header[ic] + "': '" + r[ic] + "' is not a whole number >= 0");
      row.output = static_cast<int>(*o);
      if (index >= 0) row.output_name = r[output];
      if (unit >= 0) row.unit = r[static_cast<size_t>(unit)];
      if (fits >= 0) row.fits = static_cast<int>(number(r[static_cast<size_t>(fits)], line + " column 'fits'", false));
      if (fitsec >= 0) row.fit_seconds = number(r[static_cast<size_t>(fitsec)], line + " column 'fitsec'", false);
      if (warnings >= 0) row.warnings = r[static_cast<size_t>(warnings)];
    }
    out.push_back(std::move(row));
  }
  return out;
}

}  // namespace

std::string results_header() {
  std::string h;
  for (const char* c : kColumns) h += (h.empty() ? "" : ",") + std::string(c);
  return h;
}

std::string results_line(const ResultRow& r) {
  std::string warnings = r.warnings;
  for (char& c : warnings)
    if (c == ',') c = ';';
  std::ostringstream s;
  s << field(r.scenario) << "," << field(r.split) << "," << field(r.output_name.empty() ? std::to_string(r.output) : r.output_name)
    << "," << r.output << "," << field(r.unit) << "," << field(r.algo) << "," << number_text(r.rmse_mean) << ","
    << number_text(r.rmse_std) << "," << number_text(r.rmse_min) << "," << number_text(r.rmse_max) << "," << number_text(r.nllh_mean) << ","
    << number_text(r.nllh_std) << "," << number_text(r.nllh_min) << "," << number_text(r.nllh_max) << "," << r.fits << ","
    << number_text(r.fit_seconds) << "," << field(warnings);
  return s.str();
}

std::vector<ResultRow> read_results(const std::string& path) { return parse_rows(path, false); }
std::vector<ResultRow> read_published_table(const std::string& path) { return parse_rows(path, true); }

std::string output_label(const ResultRow& row) {
  if (row.output_name.empty()) return "output " + std::to_string(row.output);
  return row.unit.empty() ? row.output_name : row.output_name + " [" + row.unit + "]";
}

std::string canonical_algo(const std::string& name) {
  if (name == "SPGP-from-zeroes") return "SPGP-from-zeros";
  return name;
}

}  // namespace spml
