#include "spml/learners/compare.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "spml/csv.h"
#include "spml/dataset.h"
#include "spml/learners/learner.h"
#include "spml/parse.h"
#include "spml/plugin_loader.h"

namespace spml {
namespace {

namespace fs = std::filesystem;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::vector<double> ranks(const std::vector<double>& v) {
  std::vector<size_t> idx(v.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return v[a] < v[b]; });
  std::vector<double> r(v.size());
  for (size_t i = 0; i < idx.size();) {
    size_t j = i;
    while (j + 1 < idx.size() && v[idx[j + 1]] == v[idx[i]]) ++j;
    for (size_t k = i; k <= j; ++k) r[idx[k]] = 0.5 * static_cast<double>(i + j) + 1.0;   // ties share the mean rank
    i = j + 1;
  }
  return r;
}

std::string num(double v, int precision = 2) { return std::isnan(v) ? "-" : number_text(v, precision, true); }

std::string delta(double ours, double paper) {
  if (std::isnan(paper) || std::isinf(paper) || std::isinf(ours)) return "";
  std::ostringstream s;
  s << std::showpos << std::fixed << std::setprecision(2) << ours - paper;
  return s.str();
}

// One paper table against our rows of the same (scenario, split, output).
struct TableScore {
  std::string our_best, paper_best;
  double our_rmse = kNaN, paper_rmse = kNaN;
  int common = 0, within = 0;             // learners in both; of those, RMSE within +-15 % of the paper's
  double rho = kNaN;                      // Spearman over the common learners (>= 3)
};

// The paper's reference rows: the model with given (prior / true) coefficients, nothing
// learnt. Shown in the tables, but not candidates for "best" on either side.
bool reference_row(const std::string& algo) { return algo == "LLS-prior" || algo == "LLS-simulated"; }

TableScore score_table(const std::vector<const ResultRow*>& rows, const std::map<std::string, ResultRow>& paper) {
  TableScore s;
  for (const auto& [algo, p] : paper)
    if (!reference_row(algo) && std::isfinite(p.rmse_mean) && !(p.rmse_mean >= s.paper_rmse)) {
      s.paper_rmse = p.rmse_mean;
      s.paper_best = algo;
    }
  std::vector<double> ours, theirs;
  for (const ResultRow* r : rows) {
    if (!reference_row(r->algo) && std::isfinite(r->rmse_mean) && !(r->rmse_mean >= s.our_rmse)) {
      s.our_rmse = r->rmse_mean;
      s.our_best = r->algo;
    }
    auto p = paper.find(r->algo);
    if (p == paper.end() || !std::isfinite(p->second.rmse_mean)) continue;
    ++s.common;
    s.within += std::abs(r->rmse_mean - p->second.rmse_mean) <= 0.15 * p->second.rmse_mean;
    ours.push_back(r->rmse_mean);
    theirs.push_back(p->second.rmse_mean);
  }
  if (s.common >= 3) s.rho = spearman_rho(ours, theirs);
  return s;
}

// Every paper table in one block: our best learner against the paper's best, the rows that
// agree within 15 %, the rank agreement, and how many tables our best beats the paper's.
std::string scoreboard(const std::map<std::string, std::string>& table_of, const std::map<std::string, TableScore>& scores) {
  // "it-SVR-GP-SepKer 123.45 " and the trailing space keep columns apart for every paper name
  constexpr int kBestWidth = 26;
  std::ostringstream out;
  out << "\n== scoreboard: every paper table (RMSE; best = lowest mean over the repetitions)\n"
      << std::left << std::setw(30) << "table (scenario split output)" << std::setw(kBestWidth) << "ours best" << std::setw(kBestWidth) << "paper best"
      << std::right << std::setw(10) << "within15%" << std::setw(7) << "rho" << "  beats\n";
  int beats = 0, tables = 0, run = 0;
  std::vector<std::string> seen;
  for (const auto& [key, file] : table_of) {
    if (std::find(seen.begin(), seen.end(), file) != seen.end()) continue;
    seen.push_back(file);
    ++tables;
    std::string label = key;   // "scenario|split|output" -> "scenario split output"
    std::replace(label.begin(), label.end(), '|', ' ');
    auto it = scores.find(file);
    if (it == scores.end()) {
      out << std::left << std::setw(30) << label << "(not run)\n";
      continue;
    }
    const TableScore& s = it->second;
    ++run;
    const bool win = std::isfinite(s.our_rmse) && s.our_rmse < s.paper_rmse;
    beats += win;
    out << std::left << std::setw(30) << label << std::setw(kBestWidth) << (s.our_best + " " + num(s.our_rmse) + " ")
        << std::setw(kBestWidth) << (s.paper_best + " " + num(s.paper_rmse) + " ") << std::right << std::setw(10)
        << (std::to_string(s.within) + "/" + std::to_string(s.common)) << std::setw(7) << num(s.rho) << "  "
        << (win ? "yes" : "no") << "\n";
  }
  out << "our best beats the paper's best in " << beats << " of " << tables << " tables (" << run
      << " run; LLS-prior/LLS-simulated are reference rows, never 'best')\n";
  return out.str();
}

}  // namespace

std::string default_published_dir() { return (fs::path(spml_share_dir()) / "published").string(); }

double spearman_rho(const std::vector<double>& a, const std::vector<double>& b) {
  const std::vector<double> ra = ranks(a), rb = ranks(b);
  const double n = static_cast<double>(a.size());
  const double ma = (n + 1) / 2;
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    sab += (ra[i] - ma) * (rb[i] - ma);
    saa += (ra[i] - ma) * (ra[i] - ma);
    sbb += (rb[i] - ma) * (rb[i] - ma);
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : kNaN;
}

double kendall_tau(const std::vector<double>& a, const std::vector<double>& b) {
  double concordant = 0, discordant = 0, pairs = 0;
  for (size_t i = 0; i < a.size(); ++i)
    for (size_t j = i + 1; j < a.size(); ++j) {
      const double s = (a[i] - a[j]) * (b[i] - b[j]);
      if (s > 0) ++concordant;
      if (s < 0) ++discordant;
      ++pairs;
    }
  return pairs > 0 ? (concordant - discordant) / pairs : kNaN;
}

namespace {

// One (scenario, split, output) group of our rows with the paper's table for it: what both
// the printed report and --json show, worked out once.
struct Group {
  std::vector<const ResultRow*> rows;
  std::string table;                          // the paper's table file, "" when it has none
  std::map<std::string, ResultRow> paper;
  std::vector<std::string> paper_order, common;
  std::vector<double> ours_rmse, paper_rmse;  // over `common`
  double paper_value(const std::string& algo, bool rmse) const {
    auto p = paper.find(algo);
    return p == paper.end() ? kNaN : rmse ? p->second.rmse_mean : p->second.nllh_mean;
  }
  bool ran(const std::string& algo) const {
    for (const ResultRow* r : rows)
      if (r->algo == algo) return true;
    return false;
  }
  std::string best(const std::vector<double>& v) const {
    return common[static_cast<size_t>(std::min_element(v.begin(), v.end()) - v.begin())];
  }
};

struct Comparison {
  std::map<std::string, std::string> table_of;   // "scenario|split|output" -> table file
  std::vector<Group> groups;
  std::map<std::string, TableScore> scores;      // by table file
};

Comparison compare(const std::vector<ResultRow>& results, const std::string& published_dir) {
  Comparison c;
  const CsvText index = read_csv((fs::path(published_dir) / "tables.csv").string());
  if (index.header.size() < 4) throw DatasetError(index.source + ": expected columns scenario,split,output,table");
  for (const auto& r : index.rows) c.table_of[r[0] + "|" + r[1] + "|" + r[2]] = r[3];
  std::vector<std::string> order;
  std::map<std::string, std::vector<const ResultRow*>> by_key;
  for (const auto& r : results) {
    const std::string key = r.scenario + "|" + r.split + "|" + std::to_string(r.output);
    if (!by_key.count(key)) order.push_back(key);
    by_key[key].push_back(&r);
  }
  for (const auto& key : order) {
    Group g;
    g.rows = by_key[key];
    if (auto t = c.table_of.find(key); t != c.table_of.end()) {
      g.table = t->second;
      for (auto& p : read_published_table((fs::path(published_dir) / g.table).string())) {
        g.paper_order.push_back(p.algo);
        g.paper[p.algo] = p;
      }
      c.scores[g.table] = score_table(g.rows, g.paper);
    }
    for (const ResultRow* r : g.rows)
      if (g.paper.count(r->algo)) {
        g.ours_rmse.push_back(r->rmse_mean);
        g.paper_rmse.push_back(g.paper_value(r->algo, true));
        g.common.push_back(r->algo);
      }
    c.groups.push_back(std::move(g));
  }
  return c;
}

void print_group(std::ostream& out, const Group& g) {
  const ResultRow& first = *g.rows.front();
  out << "\n== " << first.scenario << " / " << first.split << " / " << output_label(first);
  out << (g.table.empty() ? "  (the paper has no table for this)\n" : "  (paper: " + g.table + ")\n");
  out << std::left << std::setw(18) << "algo" << std::right << std::setw(16) << "RMSE ours" << std::setw(9) << "paper"
      << std::setw(9) << "delta" << std::setw(16) << "NLLH ours" << std::setw(9) << "paper" << std::setw(9) << "delta" << "\n";
  for (const ResultRow* r : g.rows) {
    const double pr = g.paper_value(r->algo, true), pn = g.paper_value(r->algo, false);
    out << std::left << std::setw(18) << r->algo << std::right << std::setw(16) << (num(r->rmse_mean) + "+-" + num(r->rmse_std))
        << std::setw(9) << num(pr) << std::setw(9) << delta(r->rmse_mean, pr) << std::setw(16) << num(r->nllh_mean)
        << std::setw(9) << num(pn) << std::setw(9) << delta(r->nllh_mean, pn) << (r->warnings.empty() ? "" : "  !") << "\n";
  }
  for (const auto& a : g.paper_order)
    if (!g.ran(a))
      out << std::left << std::setw(18) << a << std::right << std::setw(16) << "(not run)" << std::setw(9) << num(g.paper_value(a, true)) << "\n";
  if (g.common.size() >= 3)
    out << "rank agreement over " << g.common.size() << " learners (RMSE): Spearman rho " << num(spearman_rho(g.ours_rmse, g.paper_rmse))
        << ", Kendall tau " << num(kendall_tau(g.ours_rmse, g.paper_rmse)) << "; best: ours " << g.best(g.ours_rmse)
        << ", paper " << g.best(g.paper_rmse) << "\n";
  bool any_warning = false;
  for (const ResultRow* r : g.rows) any_warning |= !r->warnings.empty();
  if (any_warning) {
    out << "! warnings:\n";
    for (const ResultRow* r : g.rows)
      if (!r->warnings.empty()) out << "  " << r->algo << ": " << r->warnings << "\n";
  }
}

// A number for JSON: null where it is not finite (NLLH without a variance, a value the paper omits).
nlohmann::json value(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

nlohmann::json group_json(const Group& g) {
  const ResultRow& first = *g.rows.front();
  nlohmann::json j{{"scenario", first.scenario}, {"split", first.split},
                   {"output", first.output_name.empty() ? nlohmann::json() : nlohmann::json(first.output_name)},
                   {"output_index", first.output}, {"unit", first.unit},
                   {"paper_table", g.table.empty() ? nlohmann::json() : nlohmann::json(g.table)}};
  for (const ResultRow* r : g.rows)
    j["learners"].push_back({{"algo", r->algo}, {"rmse_mean", value(r->rmse_mean)}, {"rmse_std", value(r->rmse_std)},
                             {"nllh_mean", value(r->nllh_mean)}, {"nllh_std", value(r->nllh_std)},
                             {"paper_rmse", value(g.paper_value(r->algo, true))}, {"paper_nllh", value(g.paper_value(r->algo, false))},
                             {"fits", r->fits}, {"fit_seconds", value(r->fit_seconds)}, {"warnings", r->warnings}});
  j["not_run"] = nlohmann::json::array();
  for (const auto& a : g.paper_order)
    if (!g.ran(a)) j["not_run"].push_back({{"algo", a}, {"paper_rmse", value(g.paper_value(a, true))}});
  if (g.common.size() >= 3)
    j["rank_agreement"] = {{"learners", g.common.size()}, {"spearman_rho", value(spearman_rho(g.ours_rmse, g.paper_rmse))},
                           {"kendall_tau", value(kendall_tau(g.ours_rmse, g.paper_rmse))},
                           {"best_ours", g.best(g.ours_rmse)}, {"best_paper", g.best(g.paper_rmse)}};
  return j;
}

}  // namespace

std::string compare_report(const std::vector<ResultRow>& results, const std::string& published_dir) {
  const Comparison c = compare(results, published_dir);
  std::ostringstream out;
  for (const Group& g : c.groups) print_group(out, g);
  out << scoreboard(c.table_of, c.scores);
  return out.str();
}

nlohmann::json compare_json(const std::vector<ResultRow>& results, const std::string& published_dir) {
  const Comparison c = compare(results, published_dir);
  nlohmann::json j{{"format", "spml-compare/1"}, {"groups", nlohmann::json::array()}, {"scoreboard", nlohmann::json::array()}};
  for (const Group& g : c.groups) j["groups"].push_back(group_json(g));
  int beats = 0;
  std::vector<std::string> seen;
  for (const auto& [key, file] : c.table_of) {
    if (std::find(seen.begin(), seen.end(), file) != seen.end()) continue;
    seen.push_back(file);
    nlohmann::json row{{"table", file}, {"key", key}};
    if (auto it = c.scores.find(file); it != c.scores.end()) {
      const TableScore& s = it->second;
      const bool win = std::isfinite(s.our_rmse) && s.our_rmse < s.paper_rmse;
      beats += win;
      row.update({{"ours_best", s.our_best}, {"ours_rmse", value(s.our_rmse)}, {"paper_best", s.paper_best},
                  {"paper_rmse", value(s.paper_rmse)}, {"within_15_percent", s.within}, {"common", s.common},
                  {"spearman_rho", value(s.rho)}, {"beats", win}});
    } else {
      row["run"] = false;
    }
    j["scoreboard"].push_back(row);
  }
  j["tables"] = seen.size();
  j["beats"] = beats;
  return j;
}

}  // namespace spml
