// spml diagnose: the stages in the order the data flows (diagnosis.h lists the files).
#include "spml/diagnose.h"

#include <cmath>
#include <filesystem>
#include <sstream>

#include "diagnosis.h"
#include "report.h"
#include "spml/matrix_file.h"

namespace spml {
namespace diagnose_detail {

std::string fmt(double v, int precision) {
  std::ostringstream s;
  s.precision(precision);
  s << v;
  return s.str();
}

std::string integer_text(double v) { return std::to_string(static_cast<long long>(std::llround(v))); }

DiagnoseResult Diagnosis::run(const std::string& out_dir) {
  auto t0 = Clock::now();
  load();
  find_candidates();
  result_.timings.load = since(t0);
  select();
  t0 = Clock::now();
  decide_parameters();
  result_.timings.refits += since(t0);
  build_report(out_dir);
  auto& T = result_.timings;
  result_.report["timings_s"] = {{"load", T.load}, {"search", T.search}, {"refits", T.refits}, {"rollouts", T.rollouts}, {"outputs", T.outputs}};
  result_.summary = report_summary(result_.report);
  if (!out_dir.empty()) {
    namespace fs = std::filesystem;
    write_text_atomic((fs::path(out_dir) / "report.md").string(), report_markdown(result_.report));
    write_text_atomic((fs::path(out_dir) / "report.json").string(), result_.report.dump(2) + "\n");
  }
  return result_;
}

}  // namespace diagnose_detail

DiagnoseResult diagnose(const DiagnoseOptions& options, const std::string& out_dir) {
  diagnose_detail::Diagnosis d(options);
  return d.run(out_dir);
}

}  // namespace spml
