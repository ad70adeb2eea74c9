#include "spml/learners/compare.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
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

std::string compare_report(const std::vector<ResultRow>& results, const std::string& published_dir) {
  // Which paper table belongs to which of our groups.
  std::map<std::string, std::string> table_of;
  {
    const CsvText index = read_csv((fs::path(published_dir) / "tables.csv").string());
    if (index.header.size() < 4) throw DatasetError(index.source + ": expected columns scenario,split,output,table");
    for (const auto& r : index.rows) table_of[r[0] + "|" + r[1] + "|" + r[2]] = r[3];
  }
  std::vector<std::string> order;
  std::map<std::string, std::vector<const ResultRow*>> groups;
  for (const auto& r : results) {
    const std::string key = r.scenario + "|" + r.split + "|" + std::to_string(r.output);
    if (!groups.count(key)) order.push_back(key);
    groups[key].push_back(&r);
  }
  std::ostringstream out;
  std::map<std::string, TableScore> scores;   // by table file
  for (const auto& key : order) {
    const auto& rows = groups[key];
    const ResultRow& first = *rows.front();
    out << "\n== " << first.scenario << " / " << first.split << " / " << output_label(first);
    auto t = table_of.find(key);
    std::map<std::string, ResultRow> paper;
    std::vector<std::string> paper_order;
    if (t == table_of.end()) {
      out << "  (the paper has no table for this)\n";
    } else {
      out << "  (paper: " << t->second << ")\n";
      for (auto& p : read_published_table((fs::path(published_dir) / t->second).string())) {
        paper_order.push_back(p.algo);
        paper[p.algo] = p;
      }
    }
    out << std::left << std::setw(18) << "algo" << std::right << std::setw(16) << "RMSE ours" << std::setw(9) << "paper"
        << std::setw(9) << "delta" << std::setw(16) << "NLLH ours" << std::setw(9) << "paper" << std::setw(9)
        << "delta" << "\n";
    std::vector<double> ours_rmse, paper_rmse;
    std::vector<std::string> common;
    for (const ResultRow* r : rows) {
      auto p = paper.find(r->algo);
      const double pr = p != paper.end() ? p->second.rmse_mean : kNaN;
      const double pn = p != paper.end() ? p->second.nllh_mean : kNaN;
      out << std::left << std::setw(18) << r->algo << std::right << std::setw(16)
          << (num(r->rmse_mean) + "+-" + num(r->rmse_std)) << std::setw(9) << num(pr) << std::setw(9)
          << delta(r->rmse_mean, pr) << std::setw(16) << num(r->nllh_mean) << std::setw(9) << num(pn)
          << std::setw(9) << delta(r->nllh_mean, pn) << (r->warnings.empty() ? "" : "  !") << "\n";
      if (p != paper.end()) {
        ours_rmse.push_back(r->rmse_mean);
        paper_rmse.push_back(pr);
        common.push_back(r->algo);
      }
    }
    for (const auto& a : paper_order) {
      bool ran = false;
      for (const ResultRow* r : rows) ran |= r->algo == a;
      if (!ran) out << std::left << std::setw(18) << a << std::right << std::setw(16) << "(not run)" << std::setw(9)
                    << num(paper[a].rmse_mean) << "\n";
    }
    if (t != table_of.end()) scores[t->second] = score_table(rows, paper);
    if (common.size() >= 3) {
      auto best = [&](const std::vector<double>& v) {
        return common[static_cast<size_t>(std::min_element(v.begin(), v.end()) - v.begin())];
      };
      out << "rank agreement over " << common.size() << " learners (RMSE): Spearman rho " << num(spearman_rho(ours_rmse, paper_rmse))
          << ", Kendall tau " << num(kendall_tau(ours_rmse, paper_rmse)) << "; best: ours " << best(ours_rmse)
          << ", paper " << best(paper_rmse) << "\n";
    }
    bool any_warning = false;
    for (const ResultRow* r : rows) any_warning |= !r->warnings.empty();
    if (any_warning) {
      out << "! warnings:\n";
      for (const ResultRow* r : rows)
        if (!r->warnings.empty()) out << "  " << r->algo << ": " << r->warnings << "\n";
    }
  }
  out << scoreboard(table_of, scores);
  return out.str();
}

}  // namespace spml
