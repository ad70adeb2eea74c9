// spml diagnose: the stages in the order the data flows (diagnosis.h lists the files).
#include "spml/diagnose.h"

#include <cmath>
#include <filesystem>
#include <sstream>
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>
#include <stdexcept>

#include "diagnosis.h"
#include "parallel.h"
#include "report.h"
#include "spml/dataset.h"   // utf8_problem
#include "spml/matrix_file.h"
#include "spml/output_guard.h"

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
  std::string json;
  try {
    json = result_.report.dump(2) + "\n";
  } catch (const nlohmann::json::type_error& e) {
    throw std::runtime_error("report.json: a path, joint, body or split name holds bytes that are not UTF-8 (" + std::string(e.what()) +
                             "); nothing was written");
  }
  if (!out_dir.empty()) {
    namespace fs = std::filesystem;
    write_text_atomic((fs::path(out_dir) / "report.md").string(), report_markdown(result_.report));
    write_text_atomic((fs::path(out_dir) / "report.json").string(), json);
  }
  return result_;
}

namespace {

namespace fs = std::filesystem;
// In the order they are moved into place: report.json last, so that a reader who sees it sees
// the rest of the same run.
const char* const kOutputs[] = {"extended.xml", "series.csv", "unexplained.csv", "rollouts.csv", "report.md", "report.json"};
// The figures tools/plots/diagnose_plots.py draws into plots/.
const char* const kPlots[] = {"residuals.png", "states.png", "rollouts.png", "rollouts_trajectories.png", "unexplained.png"};

// The same file-identity check as generate, import and bench (spml/output_guard.h).
void refuse_inputs_among_outputs(const DiagnoseOptions& o, const fs::path& out) {
  std::vector<std::string> inputs = {o.model, o.data};
  inputs.insert(inputs.end(), o.more_data.begin(), o.more_data.end());
  inputs.insert(inputs.end(), o.cross.begin(), o.cross.end());
  if (const std::string p = input_among_outputs(inputs, out.string(), {std::begin(kOutputs), std::end(kOutputs)}, {"plots"}); !p.empty())
    throw std::runtime_error(p);
}

// The staged folder is removed on every way out; its files are moved into out_dir together.
// A folder out_dir the run itself created goes too when the run leaves it empty (a failure).
struct Staging {
  fs::path dir, created;
  ~Staging() {
    std::error_code ec;
    if (!dir.empty()) fs::remove_all(dir, ec);
    if (!created.empty() && fs::is_empty(created, ec)) fs::remove(created, ec);
  }
};

void publish(const fs::path& staged, const fs::path& out) {
  // One run's files at a time: a lock file in the folder, held while the files move.
  const int fd = ::open((out / ".spml-diagnose.lock").c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644);
  if (fd >= 0) ::flock(fd, LOCK_EX);
  std::error_code ec;
  // A run without plots must not show the last run's; files of the user's own stay.
  for (const char* name : kPlots) fs::remove(out / "plots" / name, ec);
  if (fs::exists(staged / "plots")) {
    fs::create_directories(out / "plots");
    for (const auto& f : fs::directory_iterator(staged / "plots")) fs::rename(f.path(), out / "plots" / f.path().filename());
  }
  fs::remove(out / "plots", ec);   // only when it is left empty
  // An output this run did not write (rollouts.csv without rollouts) must not stay from the last.
  for (const char* name : kOutputs)
    if (fs::exists(staged / name)) fs::rename(staged / name, out / name);
    else fs::remove(out / name, ec);
  if (fd >= 0) {
    ::flock(fd, LOCK_UN);
    ::close(fd);
  }
}

}  // namespace

}  // namespace diagnose_detail

void DiagnoseOptions::check() const {
  auto in = [](const char* name, double v, double lo, double hi) {
    if (!std::isfinite(v) || v < lo || v > hi)
      throw std::invalid_argument(std::string("diagnose option ") + name + " = " + diagnose_detail::fmt(v) + ": must be a finite number in [" +
                                  diagnose_detail::fmt(lo) + ", " + diagnose_detail::fmt(hi) + "]");
  };
  if (model.empty()) throw std::invalid_argument("diagnose option model: no MJCF file given");
  if (data.empty()) throw std::invalid_argument("diagnose option data: no dataset given");
  if (fit_split.empty()) throw std::invalid_argument("diagnose option fit_split: empty");
  in("holdout", holdout, 0.05, 0.9);
  in("bic_threshold", bic_threshold, 0, 1e9);
  in("min_gain", min_gain, 0, 1);
  in("max_causes", max_causes, 1, 1000);
  in("threads", threads, 0, 256);
  in("still_speed", still_speed, 0, 1e9);
  in("rollout_seconds", rollout_seconds, 1e-3, 10);
  in("rollouts", rollouts, 0, 10000);
  in("min_ripple_periods", min_ripple_periods, 0, 1e6);
  in("ripple_gear", ripple_gear, 0, 1e9);
  in("prior_weight", prior_weight, 1e-6, 1e6);
  if (estimator != "ls" && estimator != "iv")
    throw std::invalid_argument("diagnose option estimator: '" + estimator + "' is neither 'iv' nor 'ls'");
  // report.json names every input, and JSON holds only UTF-8: refuse here, naming the option,
  // before anything is read or written.
  auto utf8 = [](const char* name, const std::string& path) {
    if (const std::string why = utf8_problem(path); !why.empty())
      throw std::invalid_argument(std::string("diagnose option ") + name + ": the path is not UTF-8, which report.json cannot hold (" +
                                  why + "); rename it");
  };
  utf8("model", model);
  utf8("data", data);
  for (const auto& p : more_data) utf8("data", p);
  for (const auto& p : cross) utf8("cross", p);
  utf8("fit_split", fit_split);
}

DiagnoseResult diagnose(const DiagnoseOptions& options, const std::string& out_dir,
                        const std::function<void(const std::string&)>& before_publish) {
  using namespace diagnose_detail;
  namespace fs = std::filesystem;
  options.check();
  const ThreadCap cap(static_cast<unsigned>(options.threads));
  Diagnosis d(options);
  if (out_dir.empty()) return d.run("");
  const fs::path out(out_dir);
  if (const std::string why = utf8_problem(out_dir); !why.empty())
    throw std::invalid_argument("diagnose: the output folder's path is not UTF-8, which report.json cannot hold (" + why + ")");
  refuse_inputs_among_outputs(options, out);
  Staging staged{out / (".spml-diagnose-" + std::to_string(::getpid())), !fs::exists(out) ? out : fs::path()};
  fs::create_directories(out);
  fs::remove_all(staged.dir);
  fs::create_directories(staged.dir);
  DiagnoseResult r = d.run(staged.dir.string());
  if (before_publish) before_publish(staged.dir.string());
  if (!fs::exists(staged.dir / "plots"))
    write_text_atomic((staged.dir / "report.md").string(), diagnose_detail::report_markdown(r.report, false));
  publish(staged.dir, out);
  return r;
}

}  // namespace spml
