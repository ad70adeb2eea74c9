// spml bench: selection, data preparation, unit keys, fitting and aggregation, each a step.
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>

#include "spml/json_utf8.h"
#include "spml/output_guard.h"
#include "spml/envs/parametric_model.h"
#include "spml/learners/evaluate.h"
#include "spml/learners/results.h"
#include "spml/matrix_file.h"
#include "spml/parse.h"

namespace spml {
namespace {

namespace fs = std::filesystem;

// ---- 64-bit FNV-1a over everything a unit depends on ----
class Hasher {
 public:
  void bytes(const void* p, size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) h_ = (h_ ^ b[i]) * 1099511628211ull;
  }
  void text(const std::string& s) {
    const uint64_t n = s.size();
    bytes(&n, sizeof n);
    bytes(s.data(), s.size());
  }
  template <class M>
  void matrix(const M& m) {
    const int64_t dims[2] = {m.rows(), m.cols()};
    bytes(dims, sizeof dims);
    if (m.size()) bytes(m.data(), static_cast<size_t>(m.size()) * sizeof(double));
  }
  std::string hex() const {
    std::ostringstream s;
    s << std::hex << std::setw(16) << std::setfill('0') << h_;
    return s.str();
  }

 private:
  uint64_t h_ = 1469598103934665603ull;
};

constexpr const char* kManifestFormat = "spml-bench/3";
constexpr const char* kPredictionsFormat = "spml-predictions/2";   // 2: root attributes `outputs`, `units`, `inputs`, `input_units`

std::string clock_text(double seconds) {
  const long s = std::lround(seconds);
  std::ostringstream out;
  if (s >= 3600) out << s / 3600 << " h " << (s % 3600) / 60 << " min";
  else if (s >= 60) out << s / 60 << " min " << s % 60 << " s";
  else out << s << " s";
  return out.str();
}

// "elapsed, ETA" after each fitted unit. A GP fit can take 10^4 times an LLS fit, so one mean
// over all units misleads (it said 9 s for 47 s): each learner's units still to fit count at
// the mean time of its own units (fitted in this run, or reused with the time stamped in
// them); learners not timed yet as the slowest timed one (a GP after LLS and SVR), and the line says how many
// that are, so the ETA is read as the rough figure it is.
class Progress {
 public:
  explicit Progress(std::map<std::string, int> units) : start_(std::chrono::steady_clock::now()) {
    for (const auto& [name, n] : units) learners_[name].left = n;
  }
  void skip(const std::string& name, double seconds) { record(name, seconds); }
  std::string done(const std::string& name, double seconds) {
    record(name, seconds);
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    double eta = 0, slowest = 0;
    int untimed = 0, left = 0;
    for (const auto& [n, l] : learners_)
      if (l.fits > 0) slowest = std::max(slowest, l.seconds / l.fits);
    for (const auto& [n, l] : learners_) {
      left += l.left;
      eta += l.left * (l.fits > 0 ? l.seconds / l.fits : slowest);
      untimed += l.left > 0 && l.fits == 0;
    }
    if (left <= 0) return "  (" + clock_text(elapsed) + " elapsed)";
    return "  (" + clock_text(elapsed) + " elapsed, ETA " + (untimed ? "~" : "") + clock_text(eta) +
           (untimed ? ": " + std::to_string(untimed) + " learner(s) not timed yet, counted as the slowest so far" : "") + ")";
  }
  // The mean time of this learner's units so far; 0 when none is timed.
  double expected(const std::string& name) const {
    auto it = learners_.find(name);
    return it == learners_.end() || it->second.fits == 0 ? 0.0 : it->second.seconds / it->second.fits;
  }
  // The run's ETA while a unit of `name` is fitting, foreseen from its progress to take `unit`
  // seconds in all, `left` of them still to come: its learner's later units count at their
  // mean so far or, before the first has finished, at `unit`; the other learners as done().
  // Sets *guessed when some learner is not timed yet (counted as the slowest so far).
  double eta_during(const std::string& name, double unit, double left, bool* guessed) const {
    double slowest = unit, eta = left;
    for (const auto& [n, l] : learners_)
      if (l.fits > 0) slowest = std::max(slowest, l.seconds / l.fits);
    *guessed = false;
    for (const auto& [n, l] : learners_) {
      if (n == name) {
        eta += (l.left - 1) * (l.fits > 0 ? l.seconds / l.fits : unit);
        continue;
      }
      eta += l.left * (l.fits > 0 ? l.seconds / l.fits : slowest);
      *guessed |= l.left > 0 && l.fits == 0;
    }
    return eta;
  }

 private:
  struct Learner {
    int left = 0, fits = 0;
    double seconds = 0;
  };
  void record(const std::string& name, double seconds) {
    Learner& l = learners_[name];
    --l.left;
    if (std::isfinite(seconds) && seconds >= 0) {
      l.seconds += seconds;
      ++l.fits;
    }
  }
  std::map<std::string, Learner> learners_;
  std::chrono::steady_clock::time_point start_;
};

// The stage fit_unit reports once the fit has returned, while it predicts.
constexpr const char* kPredicting = "predicting the test splits";

// What a fit reports while it runs (LearnerConfig::progress), for the heartbeat's thread.
class FitProgress {
 public:
  void set(double fraction, const char* stage) {
    std::lock_guard<std::mutex> lock(mutex_);
    fraction_ = fraction;
    stage_ = stage ? stage : "";
  }
  // false until the fit has reported.
  bool get(double* fraction, std::string* stage) const {
    std::lock_guard<std::mutex> lock(mutex_);
    *fraction = fraction_;
    *stage = stage_;
    return fraction_ >= 0;
  }

 private:
  mutable std::mutex mutex_;
  double fraction_ = -1;
  std::string stage_;
};

// A line every `every` seconds while one unit is being fitted, so a long fit (a GP on
// thousands of rows) is not silent; stops when it goes out of scope. When the learner reports
// its progress, the line gives the fraction, the fit's ETA from elapsed / fraction and the
// run's ETA with this fit foreseen so (`run` is read only: the main thread waits in the fit).
class Heartbeat {
 public:
  Heartbeat(double every, std::string tag, std::string name, const Progress& run, const FitProgress& fit,
            std::function<void(const std::string&)> log)
      : thread_([=, &run, &fit] {
          if (!(every > 0) || !log) return;
          const double expected = run.expected(name);
          const auto start = std::chrono::steady_clock::now();
          std::unique_lock<std::mutex> lock(mutex_);
          while (!cv_.wait_for(lock, std::chrono::duration<double>(every), [this] { return stop_; })) {
            const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
            double f = 0;
            std::string stage;
            const bool reported = fit.get(&f, &stage);
            if (reported && stage == kPredicting) {
              bool guessed = false;
              const double eta = run.eta_during(name, t, 0.0, &guessed);
              log(tag + ": fitted, " + stage + ", " + clock_text(t) + " elapsed; run ETA " + (guessed ? "~" : "") + clock_text(eta));
            } else if (reported && f >= 0.005) {   // below, t / f would blow up the first moments' noise
              const double total = t / f, left = std::max(0.0, total - t);
              bool guessed = false;
              const double eta = run.eta_during(name, total, left, &guessed);
              std::ostringstream pct;
              pct << std::fixed << std::setprecision(f < 0.1 ? 1 : 0) << 100 * f << " %";
              log(tag + ": " + pct.str() + (stage.empty() ? "" : " (" + stage + ")") + ", " + clock_text(t) +
                  " elapsed, ETA " + clock_text(left) + " for this fit; run ETA " + (guessed ? "~" : "") + clock_text(eta));
            } else {
              log(tag + ": still fitting, " + clock_text(t) +
                  (expected > 0 ? " (its earlier units took " + clock_text(expected) + " each)" : ""));
            }
          }
        }) {}
  ~Heartbeat() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;
};

// One split as the learners see it, its columns in the train split's order.
struct Part {
  std::string name;
  std::vector<Eigen::Index> rows;
  RowMatrix X, Y, phi;
  bool has_phi = false;
  LearnerData data(bool with_y) const {
    LearnerData d;
    d.X = &X;
    d.Y = with_y ? &Y : nullptr;
    d.phi = has_phi ? &phi : nullptr;
    d.outputs = static_cast<int>(Y.cols());
    return d;
  }
};

// Column j of the result is the column of `have` named want[j]; refuses missing or extra names.
std::vector<int> match_columns(const std::vector<std::string>& want, const std::vector<std::string>& have,
                               const std::string& where) {
  std::vector<int> idx;
  std::string missing, extra;
  for (const auto& w : want) {
    const auto it = std::find(have.begin(), have.end(), w);
    if (it == have.end()) missing += (missing.empty() ? "" : ", ") + w;
    idx.push_back(static_cast<int>(it - have.begin()));
  }
  for (const auto& h : have)
    if (std::find(want.begin(), want.end(), h) == want.end()) extra += (extra.empty() ? "" : ", ") + h;
  if (!missing.empty() || !extra.empty())
    throw DatasetError(where + ": columns differ from the train split's (matched by name)" +
                       (missing.empty() ? "" : "; missing: " + missing) + (extra.empty() ? "" : "; not in train: " + extra));
  return idx;
}

// Values whose squares leave the range of doubles (beyond ~1e154 they overflow to inf, below
// ~1e-154 they underflow to 0) break every learner's sums of squares: refused, naming the
// column, instead of an RMSE of inf or 0.
void check_scale(const RowMatrix& m, const std::vector<std::string>& columns, const std::string& where) {
  for (Eigen::Index c = 0; c < m.cols(); ++c) {
    const double top = m.col(c).cwiseAbs().maxCoeff();
    if (top > 1e150 || (top > 0 && top < 1e-150)) {
      std::ostringstream msg;
      msg << where << ": column '" << columns[static_cast<size_t>(c)] << "' reaches at most |" << top
          << "|: outside [1e-150, 1e150], where squared sums overflow or underflow; rescale it (other units)";
      throw DatasetError(msg.str());
    }
  }
}

Part make_part(const Split& s, const Split& train, Eigen::Index max, const ParametricModel* model, const std::string& file) {
  const std::string where = file + ": split '" + s.name + "'";
  check_scale(s.X, s.x_columns, where + ": X");
  check_scale(s.Y, s.y_columns, where + ": Y");
  const std::vector<int> xc = match_columns(train.x_columns, s.x_columns, where + ": X");
  const std::vector<int> yc = match_columns(train.y_columns, s.y_columns, where + ": Y");
  Part p;
  p.name = s.name;
  p.rows = strided_rows(s.rows(), max);
  p.X.resize(static_cast<Eigen::Index>(p.rows.size()), static_cast<Eigen::Index>(xc.size()));
  p.Y.resize(p.X.rows(), static_cast<Eigen::Index>(yc.size()));
  for (Eigen::Index i = 0; i < p.X.rows(); ++i) {
    for (size_t j = 0; j < xc.size(); ++j) p.X(i, static_cast<Eigen::Index>(j)) = s.X(p.rows[static_cast<size_t>(i)], xc[j]);
    for (size_t j = 0; j < yc.size(); ++j) p.Y(i, static_cast<Eigen::Index>(j)) = s.Y(p.rows[static_cast<size_t>(i)], yc[j]);
  }
  if (model) {
    p.phi = model->stacked(p.X);
    p.has_phi = true;
  }
  return p;
}

std::string scenario_name(const Dataset& ds, const std::string& file) {
  auto it = ds.provenance.find("scenario");
  return it != ds.provenance.end() ? it->second : fs::path(file).stem().string();
}

struct Selected {
  std::string name;
  std::uint32_t flags;
};

// Which learners can run here; "all" quietly leaves out (and names) what the data cannot support.
std::vector<Selected> select_learners(const LearnerRegistry& registry, const BenchOptions& o, const ParametricModel* model,
                                      const std::string& model_problem, bool all_requested, BenchReport& report) {
  std::vector<Selected> out;
  for (const auto& name : o.learners) {
    const std::uint32_t f = registry.create(name)->flags();
    std::string why;
    if ((f & SPML_LEARNER_USES_MODEL) && !model) why = "needs a parametric model: " + model_problem;
    else if ((f & SPML_LEARNER_NEEDS_TRUTH) && model->truth.size() == 0) why = "the dataset has no true coefficients";
    else if ((f & SPML_LEARNER_NEEDS_PRIOR) && model->prior.size() == 0) why = "the dataset has no prior coefficients";
    if (why.empty()) out.push_back({name, f});
    else if (all_requested) report.skipped.push_back(name + ": " + why);
    else throw LearnerError("learner '" + name + "' cannot run on " + o.data + ": " + why);
  }
  return out;
}

}  // namespace

// "GP.max_evals" -> {"GP", "max_evals"}; an unscoped key -> {"", key}.
std::pair<std::string, std::string> scoped_key(const std::string& key) {
  const auto dot = key.find('.');
  if (dot == std::string::npos) return {"", key};
  return {key.substr(0, dot), key.substr(dot + 1)};
}

LearnerConfig config_for(const LearnerConfig& config, const std::string& learner) {
  LearnerConfig out;
  out.seed = config.seed;
  for (const auto& [k, v] : config.values)
    if (scoped_key(k).first.empty()) out.values.emplace_back(k, v);
  for (const auto& [k, v] : config.values) {
    const auto [scope, key] = scoped_key(k);
    if (scope != learner) continue;
    auto it = std::find_if(out.values.begin(), out.values.end(), [&](const auto& kv) { return kv.first == key; });
    if (it != out.values.end()) it->second = v;   // the learner's own value wins over the shared one
    else out.values.emplace_back(key, v);
  }
  return out;
}

// Every --set key must be understood by a selected learner (a scoped one by the learner it
// names), and its value must suit every learner that takes it.
void check_config(const LearnerRegistry& registry, const std::vector<std::string>& learners, const LearnerConfig& config) {
  std::string names;
  for (const auto& l : learners) names += (names.empty() ? "" : ", ") + l;
  for (const auto& [k, v] : config.values) {
    const auto [scope, key] = scoped_key(k);
    if (!scope.empty() && std::find(learners.begin(), learners.end(), scope) == learners.end())
      throw LearnerError("--set " + k + "=" + v + ": '" + scope + "' is not a learner of this run (" + names + ")");
    bool used = false;
    for (const auto& l : learners) {
      if ((!scope.empty() && l != scope) || !registry.config_keys(l).count(key)) continue;
      used = true;
      if (std::string why = registry.check_config(l, key, v); !why.empty())
        throw LearnerError("--set " + k + "=" + v + ": " + l + ": " + why);
    }
    if (!used)
      throw LearnerError("--set " + k + ": " + (scope.empty() ? "no selected learner accepts" : scope + " does not accept") +
                         " the key '" + key + "'");
  }
}

namespace {

// The key of one unit: the data (every part, its columns, the regressor, the coefficients)
// hashed once, plus what is particular to the unit.
std::string data_key(const std::vector<Part>& parts, const Split& train, const LearnerModel& lm) {
  Hasher h;
  for (const auto& c : train.x_columns) h.text(c);
  for (const auto& c : train.y_columns) h.text(c);
  for (const Part& p : parts) {
    h.text(p.name);
    h.matrix(p.X);
    h.matrix(p.Y);
    if (p.has_phi) h.matrix(p.phi);
  }
  for (const auto& n : lm.names) h.text(n);
  h.matrix(lm.prior);
  h.matrix(lm.truth);
  return h.hex();
}

// The bytes of a learner library, hashed once per file and run: a rebuilt learner (new code,
// same name) invalidates its units instead of silently reusing old numbers.
std::string library_hash(const std::string& file) {
  static std::map<std::string, std::string> cache;
  auto it = cache.find(file);
  if (it != cache.end()) return it->second;
  Hasher h;
  std::ifstream in(file, std::ios::binary);
  std::vector<char> buf(1 << 16);
  while (in.read(buf.data(), static_cast<std::streamsize>(buf.size())) || in.gcount() > 0)
    h.bytes(buf.data(), static_cast<size_t>(in.gcount()));
  return cache[file] = h.hex();
}

std::string unit_key(const std::string& data_key, const LearnerRegistry& registry, const std::string& learner,
                     const LearnerConfig& config, std::uint64_t seed) {
  Hasher h;
  h.text(data_key);
  h.text(learner);
  for (const auto& f : registry.library_files(learner)) h.text(library_hash(f));
  h.bytes(&seed, sizeof seed);
  const auto keys = registry.config_keys(learner);
  for (const auto& [k, v] : config.values)
    if (keys.count(k)) {
      h.text(k);
      h.text(v);
    }
  return h.hex();
}

std::string unit_path(const std::string& out, const std::string& algo, int rep) {
  return (fs::path(out) / "units" / algo / ("rep" + std::to_string(rep) + ".h5")).string();
}

// Temporary files of writers that no longer run (an interrupted bench): name.tmp-<pid>.
void remove_stale_temporaries(const std::string& out, const std::function<void(const std::string&)>& log) {
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(out, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const auto pos = name.rfind(".tmp-");
    if (pos == std::string::npos || !it->is_regular_file()) continue;
    const auto pid = parse_integer(name.substr(pos + 5), 1, 1LL << 31);
    if (!pid) continue;
    if (::kill(static_cast<pid_t>(*pid), 0) == 0 || errno != ESRCH) continue;   // its writer still runs
    std::error_code rm;
    fs::remove(it->path(), rm);
    if (log) log("removed " + it->path().string() + " (left by an interrupted run)");
  }
}

// Every text bench.json would hold must be UTF-8 (JSON cannot hold anything else): checked
// before anything is written, naming the value (a path with a Latin-1 byte, a --set value).
void check_utf8_fields(const nlohmann::json& j, const std::string& out) {
  if (const JsonUtf8Problem p = json_utf8_problem(j); !p.why.empty())
    throw LearnerError(p.text + ": " + (p.field.empty() ? "" : "bench.json field '" + p.field + "': ") + p.why + "; " + out +
                       "/bench.json is JSON, which holds only UTF-8 text");
}

// bench.json describes the run whose results.csv and predictions.h5 lie beside it. A run with
// other settings first removes the old results (they stay until the new ones are written
// only when bench.json is unchanged), so an interrupted run never leaves a bench.json that
// disagrees with results.csv.
void write_manifest(const std::string& out, const std::string& text) {
  const fs::path file = fs::path(out) / "bench.json";
  std::ifstream in(file, std::ios::binary);
  const std::string before((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (before == text) return;
  for (const char* old : {"results.csv", "predictions.h5"}) {
    std::error_code ec;
    fs::remove(fs::path(out) / old, ec);
    if (ec) throw LearnerError((fs::path(out) / old).string() + ": cannot remove the previous run's results: " + ec.message());
  }
  write_text_atomic(file.string(), text);
}

// Copies the file unless an identical path already holds it; atomic (temp file + rename).
void copy_unit(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  if (fs::exists(to) && fs::equivalent(from, to, ec)) return;
  fs::create_directories(to.parent_path());
  const fs::path tmp = to.string() + ".tmp-" + std::to_string(::getpid());
  fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
  fs::rename(tmp, to);
}

// A finished unit, or nothing when the file is missing, unreadable or made for another key.
std::optional<MatrixFile> read_unit(const std::string& path, const std::string& key, std::string* why) {
  if (!fs::exists(path)) return std::nullopt;
  try {
    MatrixFile u = read_matrix_file(path);
    if (u.attributes.count("key") && u.attributes.at("key") == key && u.attributes.count("fit_seconds")) return u;
    *why = "made with other data or settings";
  } catch (const std::exception&) {
    *why = "unreadable (interrupted write?)";
  }
  return std::nullopt;
}

// Fit plus prediction time stamped in a unit (NaN when it holds none).
double unit_seconds(const MatrixFile& u) {
  double t = 0;
  for (const char* k : {"fit_seconds", "predict_seconds"}) {
    auto it = u.attributes.find(k);
    t += it == u.attributes.end() ? std::numeric_limits<double>::quiet_NaN() : parse_number(it->second).value_or(NAN);
  }
  return t;
}

// Fits, predicts every test part, writes the unit atomically and returns it.
MatrixFile fit_unit(Learner& learner, const std::vector<Part>& parts, const LearnerModel& lm, const LearnerConfig& config,
                    const std::string& key, const std::string& path, std::string* summary) {
  const auto t0 = std::chrono::steady_clock::now();
  learner.fit(parts.front().data(true), lm, config);
  const auto t1 = std::chrono::steady_clock::now();
  if (config.progress) config.progress(1.0, kPredicting);   // the heartbeat says the fit is over
  MatrixFile unit;
  std::ostringstream line;
  for (size_t pi = 1; pi < parts.size(); ++pi) {
    LearnerPrediction pred = learner.predict(parts[pi].data(false));
    if (!pred.mean.allFinite()) throw LearnerError(learner.name() + ": non-finite predictive mean on " + parts[pi].name);
    if (pred.var.size() && !(pred.var.allFinite() && (pred.var.array() > 0).all()))
      throw LearnerError(learner.name() + ": predictive variance not positive and finite on " + parts[pi].name);
    unit.matrices[parts[pi].name + "/mean"] = pred.mean;
    if (pred.var.size()) unit.matrices[parts[pi].name + "/var"] = pred.var;
    const Scores sc = score(parts[pi].Y, pred);
    line << " " << parts[pi].name << " RMSE";
    for (double r : sc.rmse) line << " " << number_text(r);
  }
  const auto t2 = std::chrono::steady_clock::now();
  const Eigen::VectorXd coef = learner.coefficients();
  if (coef.size()) unit.matrices["coefficients"] = RowMatrix(coef.transpose());
  unit.attributes["key"] = key;
  unit.attributes["learner"] = learner.name();
  unit.attributes["notes"] = learner.notes();
  unit.attributes["fit_seconds"] = number_text(std::chrono::duration<double>(t1 - t0).count());
  unit.attributes["predict_seconds"] = number_text(std::chrono::duration<double>(t2 - t1).count());
  fs::create_directories(fs::path(path).parent_path());
  write_matrix_file(path, unit);
  *summary = unit.attributes["fit_seconds"] + " s;" + line.str();
  return unit;
}

// results.csv rows and predictions of one learner from its units (all repetitions present).
void aggregate(const std::string& scenario, const std::string& name, bool deterministic, int reps,
               const std::vector<MatrixFile>& units, const std::vector<Part>& parts, const std::vector<std::string>& outputs,
               const std::vector<std::string>& slide_joints, std::vector<ResultRow>& rows, MatrixFile& predictions) {
  double fitsec = 0;
  std::string warnings;
  for (const auto& u : units) {
    fitsec += parse_number(u.attributes.at("fit_seconds")).value_or(0.0);
    const std::string& n = u.attributes.count("notes") ? u.attributes.at("notes") : std::string();
    if (!n.empty() && warnings.find(n) == std::string::npos) warnings += (warnings.empty() ? "" : " | ") + n;
  }
  fitsec /= static_cast<double>(units.size());
  for (size_t pi = 1; pi < parts.size(); ++pi) {
    const Part& part = parts[pi];
    std::vector<std::vector<double>> rmse(static_cast<size_t>(part.Y.cols())), nllh(rmse.size());
    for (int r = 0; r < reps; ++r) {
      const MatrixFile& u = units[deterministic ? 0 : static_cast<size_t>(r)];
      LearnerPrediction p;
      p.mean = u.matrices.at(part.name + "/mean");
      if (u.matrices.count(part.name + "/var")) p.var = u.matrices.at(part.name + "/var");
      const Scores sc = score(part.Y, p);
      for (size_t k = 0; k < rmse.size(); ++k) {
        rmse[k].push_back(sc.rmse[k]);
        nllh[k].push_back(sc.nllh[k]);
      }
      if (!deterministic || r == 0) {
        const std::string key = part.name + "/" + name + "/rep" + std::to_string(r);
        predictions.matrices[key + "/mean"] = p.mean;
        if (p.var.size()) predictions.matrices[key + "/std"] = p.var.cwiseSqrt();
      }
    }
    for (size_t k = 0; k < rmse.size(); ++k) {
      const Summary a = summarize(rmse[k]), b = summarize(nllh[k]);
      rows.push_back({scenario, part.name, name, static_cast<int>(k), a.mean, a.std, a.min, a.max, b.mean, b.std, b.min,
                      b.max, static_cast<int>(units.size()), fitsec, warnings, outputs[k], column_unit(outputs[k], slide_joints)});
    }
  }
}

}  // namespace

void BenchOptions::check() const {
  if (data.empty()) throw LearnerError("--data: no dataset given");
  if (out.empty()) throw LearnerError("--out: no output folder given");
  if (reps < 1 || reps > 1000) throw LearnerError("--reps " + std::to_string(reps) + ": must be 1 ... 1000");
  if (shards < 1 || shard < 1 || shard > shards)
    throw LearnerError("--shard " + std::to_string(shard) + "/" + std::to_string(shards) + ": expected K/N with 1 <= K <= N");
  if (train_max < 0) throw LearnerError("--train-max " + std::to_string(train_max) + ": must be a whole number >= 1 or all (0)");
  if (test_max < 0) throw LearnerError("--test-max " + std::to_string(test_max) + ": must be a whole number >= 1 or all (0)");
  for (const auto& [k, v] : config.values)
    if (k.empty() || k.back() == '.' || k.front() == '.') throw LearnerError("--set " + k + "=" + v + ": expected key=value or LEARNER.key=value");
  if (!(heartbeat_seconds >= 0 && std::isfinite(heartbeat_seconds)))
    throw LearnerError("heartbeat_seconds " + number_text(heartbeat_seconds) + ": must be a finite number >= 0");
  std::vector<std::string> inputs = {data, model};
  inputs.insert(inputs.end(), other_inputs.begin(), other_inputs.end());
  // What a run writes into out (temporaries aside): refused as inputs, also before they exist.
  if (std::string p = input_among_outputs(inputs, out, {"bench.json", "results.csv", "predictions.h5"}, {"units"}); !p.empty())
    throw LearnerError(p);
}

BenchReport run_bench(const LearnerRegistry& registry, const BenchOptions& o, bool all_requested) {
  auto log = [&](const std::string& s) {
    if (o.log) o.log(s);
  };
  o.check();
  const Dataset ds = read_dataset(o.data);
  const Split& train_split = ds.get("train");
  std::unique_ptr<ParametricModel> model;
  std::string model_problem;
  try {
    model = make_parametric_model(ds, train_split, o.model);
  } catch (const DatasetError& e) {
    if (!o.model.empty()) throw;   // a model asked for explicitly must work
    model_problem = e.what();
  }

  BenchReport report;
  const std::vector<Selected> learners = select_learners(registry, o, model.get(), model_problem, all_requested, report);
  {
    std::vector<std::string> names;
    for (const auto& l : learners) names.push_back(l.name);
    check_config(registry, names, o.config);
  }

  std::vector<Part> parts{make_part(train_split, train_split, o.train_max, model.get(), o.data)};
  for (const Split& s : ds.splits)
    if (s.name != "train" && s.name.rfind("test", 0) == 0)
      parts.push_back(make_part(s, train_split, o.test_max, model.get(), o.data));
  if (parts.size() < 2) throw LearnerError(o.data + ": no test split (a group named test*)");

  LearnerModel lm;
  if (model) {
    lm.names = model->param_names;
    lm.prior = model->prior;
    lm.truth = model->truth;
  }
  const std::string dkey = data_key(parts, train_split, lm);

  // Provenance for people, and what `spml merge` needs to redo the run's aggregation;
  // reuse is decided per unit by its key.
  nlohmann::json config = nlohmann::json::array();
  for (const auto& [k, v] : o.config.values) config.push_back({k, v});   // in order: unit keys hash it so
  nlohmann::json names = nlohmann::json::array();
  for (const auto& l : learners) names.push_back(l.name);
  nlohmann::json manifest{{"format", kManifestFormat},
                          {"data", fs::absolute(o.data).string()},
                          {"data_key", dkey},
                          {"model", model ? model->name() : std::string()},
                          {"model_file", o.model.empty() ? std::string() : fs::absolute(o.model).string()},
                          {"learners", names},
                          {"seed", o.seed},
                          {"reps", o.reps},
                          {"train_max", o.train_max},
                          {"test_max", o.test_max},
                          {"config", config},
                          {"shard", std::to_string(o.shard) + "/" + std::to_string(o.shards)}};
  check_utf8_fields(manifest, o.out);
  if (!utf8_problem(o.out).empty())
    throw LearnerError(o.out + ": --out: " + utf8_problem(o.out) + "; bench.json is JSON, which holds only UTF-8");
  fs::create_directories(o.out);
  remove_stale_temporaries(o.out, o.log);
  write_manifest(o.out, manifest.dump(2) + "\n");

  const std::string scenario = scenario_name(ds, o.data);
  std::ostringstream head;
  head << scenario << ": train " << parts[0].rows.size() << " of " << train_split.rows() << " rows";
  for (size_t i = 1; i < parts.size(); ++i) head << ", " << parts[i].name << " " << parts[i].rows.size() << " rows";
  log(head.str());

  std::vector<ResultRow> rows;
  MatrixFile predictions;
  predictions.attributes["format"] = kPredictionsFormat;
  predictions.attributes["data"] = fs::absolute(o.data).string();
  predictions.attributes["scenario"] = scenario;
  // The outputs by name and unit, in the column order of every y, mean and std (format 2).
  // Units follow the model's joint types; without a model every joint counts as a hinge.
  const std::vector<std::string> slide_joints = model ? model->slide_joints : std::vector<std::string>();
  auto listed = [&](const std::vector<std::string>& columns, bool units) {
    std::string text;
    for (size_t i = 0; i < columns.size(); ++i) text += (i ? "," : "") + (units ? column_unit(columns[i], slide_joints) : columns[i]);
    return text;
  };
  predictions.attributes["outputs"] = listed(train_split.y_columns, false);
  predictions.attributes["units"] = listed(train_split.y_columns, true);
  predictions.attributes["inputs"] = listed(train_split.x_columns, false);
  predictions.attributes["input_units"] = listed(train_split.x_columns, true);
  for (size_t pi = 1; pi < parts.size(); ++pi) {
    predictions.matrices[parts[pi].name + "/y"] = parts[pi].Y;
    RowMatrix idx(static_cast<Eigen::Index>(parts[pi].rows.size()), 1);
    for (size_t i = 0; i < parts[pi].rows.size(); ++i) idx(static_cast<Eigen::Index>(i), 0) = static_cast<double>(parts[pi].rows[i]);
    predictions.matrices[parts[pi].name + "/rows"] = idx;
  }

  // Units in run order; unit u belongs to shard u % shards + 1.
  int total_units = 0, mine = 0;
  std::map<std::string, int> plan;   // units of each learner in this shard
  for (const auto& l : learners)
    for (int rep = 0; rep < ((l.flags & SPML_LEARNER_DETERMINISTIC) ? 1 : o.reps); ++rep)
      if (total_units++ % o.shards == o.shard - 1) {
        ++mine;
        ++plan[l.name];
      }
  if (o.shards > 1) log("shard " + std::to_string(o.shard) + "/" + std::to_string(o.shards) + ": " + std::to_string(mine) +
                        " of " + std::to_string(total_units) + " units");
  Progress progress(plan);
  int unit_number = -1;
  for (size_t li = 0; li < learners.size(); ++li) {
    const std::string& name = learners[li].name;
    const bool deterministic = learners[li].flags & SPML_LEARNER_DETERMINISTIC;
    auto learner = registry.create(name);
    const int fits = deterministic ? 1 : o.reps;
    std::vector<MatrixFile> units;
    for (int rep = 0; rep < fits; ++rep) {
      const bool in_shard = ++unit_number % o.shards == o.shard - 1;
      LearnerConfig config = config_for(o.config, name);
      config.seed = o.seed + static_cast<std::uint64_t>(rep);
      const std::string path = unit_path(o.out, name, rep);
      const std::string key = unit_key(dkey, registry, name, config, config.seed);
      std::ostringstream tag;
      tag << "[" << li + 1 << "/" << learners.size() << "] " << name << " rep " << rep + 1 << "/" << fits;
      std::string why;
      // merge: a unit comes from the folder of the shard that fitted it, never from a stale
      // copy another shard's folder may hold, so the result does not depend on argument order.
      const std::string source =
          o.unit_sources.empty() ? path : unit_path(o.unit_sources[static_cast<size_t>(unit_number) % o.unit_sources.size()], name, rep);
      if (auto u = read_unit(source, key, &why)) {
        if (source != path) copy_unit(source, path);
        ++report.units_cached;
        if (in_shard) {
          progress.skip(name, unit_seconds(*u));
          log(tag.str() + ": done earlier");
        }
        units.push_back(std::move(*u));
        continue;
      }
      if (o.reuse_only)
        throw LearnerError("unit " + name + " rep " + std::to_string(rep + 1) + " (" + source + ") " +
                           (why.empty() ? "is missing" : why) + ": was its shard run to the end?");
      if (!in_shard) {
        ++report.units_elsewhere;
        continue;
      }
      log(tag.str() + (why.empty() ? "" : ": earlier unit " + why + "; refitting") + ": fitting on " +
          std::to_string(parts[0].rows.size()) + " rows ...");
      try {
        std::string summary;
        {
          FitProgress fit_progress;
          if (o.log && o.heartbeat_seconds > 0)
            config.progress = [&fit_progress](double f, const char* stage) { fit_progress.set(f, stage); };
          const Heartbeat beat(o.heartbeat_seconds, tag.str(), name, progress, fit_progress, o.log);
          units.push_back(fit_unit(*learner, parts, lm, config, key, path, &summary));
          config.progress = nullptr;   // it points at fit_progress, which ends here
        }
        ++report.units_run;
        log(tag.str() + ": " + summary + (learner->notes().empty() ? "" : "  [" + learner->notes() + "]") +
            progress.done(name, unit_seconds(units.back())));
      } catch (const std::exception& e) {
        report.failed.push_back(name + ": " + e.what());
        log(tag.str() + ": FAILED: " + e.what());
        unit_number += fits - rep - 1;   // keeps the numbering of later learners' units
        break;
      }
    }
    if (static_cast<int>(units.size()) == fits)
      aggregate(scenario, name, deterministic, o.reps, units, parts, train_split.y_columns, slide_joints, rows, predictions);
  }

  // predictions.h5 first: when it cannot be written (a full disk), no results.csv claims the run.
  std::string csv = results_header() + "\n";
  for (const auto& r : rows) csv += results_line(r) + "\n";
  write_matrix_file((fs::path(o.out) / "predictions.h5").string(), predictions);
  write_text_atomic((fs::path(o.out) / "results.csv").string(), csv);
  return report;
}

namespace {

nlohmann::json read_manifest(const std::string& dir) {
  const std::string path = (fs::path(dir) / "bench.json").string();
  if (!fs::exists(path)) throw LearnerError(dir + ": no bench.json (not an spml bench output folder)");
  nlohmann::json m;
  try {
    std::ifstream in(path);
    m = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw LearnerError(path + ": not valid JSON: " + e.what());
  }
  if (m.value("format", std::string()) != kManifestFormat)
    throw LearnerError(path + ": format '" + m.value("format", std::string("?")) + "', merge needs '" + kManifestFormat +
                       "' (rerun the shard with this spml)");
  return m;
}

// "K/N" -> {K, N}; throws naming the folder.
std::pair<int, int> shard_of(const nlohmann::json& m, const std::string& dir) {
  const std::string s = m.value("shard", std::string());
  const auto slash = s.find('/');
  const auto k = slash == std::string::npos ? std::nullopt : parse_integer(s.substr(0, slash), 1, 1 << 20);
  const auto n = slash == std::string::npos ? std::nullopt : parse_integer(s.substr(slash + 1), 1, 1 << 20);
  if (!k || !n || *k > *n) throw LearnerError(dir + "/bench.json: shard '" + s + "' is not K/N");
  return {static_cast<int>(*k), static_cast<int>(*n)};
}

}  // namespace

BenchReport merge_bench(const LearnerRegistry& registry, const std::vector<std::string>& shard_dirs, const std::string& out,
                        const std::function<void(const std::string&)>& log) {
  if (shard_dirs.empty()) throw LearnerError("merge: no shard folders given");
  for (const auto& dir : shard_dirs) {
    std::error_code ec;
    if (fs::exists(out) && fs::equivalent(dir, out, ec))
      throw LearnerError("merge: --out " + out + " is the shard folder " + dir +
                         " (merging into it would overwrite that shard's results); merge into a new folder");
  }
  const nlohmann::json first = read_manifest(shard_dirs.front());
  const int shards = shard_of(first, shard_dirs.front()).second;
  std::vector<std::string> owner(static_cast<size_t>(shards));
  for (const auto& dir : shard_dirs) {
    const nlohmann::json m = read_manifest(dir);
    for (const char* field : {"data_key", "data", "model_file", "learners", "seed", "reps", "train_max", "test_max", "config"})
      if (m.value(field, nlohmann::json()) != first.value(field, nlohmann::json()))
        throw LearnerError("merge: " + dir + "/bench.json: '" + field + "' differs from " + shard_dirs.front() +
                           "'s (" + m.value(field, nlohmann::json()).dump() + " vs " +
                           first.value(field, nlohmann::json()).dump() + "): not shards of one run");
    const auto [k, n] = shard_of(m, dir);
    if (n != shards) throw LearnerError("merge: " + dir + " is shard " + std::to_string(k) + "/" + std::to_string(n) +
                                        ", " + shard_dirs.front() + " one of " + std::to_string(shards));
    if (!owner[static_cast<size_t>(k - 1)].empty())
      throw LearnerError("merge: " + dir + " and " + owner[static_cast<size_t>(k - 1)] + " are both shard " +
                         std::to_string(k) + "/" + std::to_string(n));
    owner[static_cast<size_t>(k - 1)] = dir;
  }
  std::string missing;
  for (int k = 0; k < shards; ++k)
    if (owner[static_cast<size_t>(k)].empty()) missing += (missing.empty() ? "" : ", ") + std::to_string(k + 1) + "/" + std::to_string(shards);
  if (!missing.empty()) throw LearnerError("merge: shard(s) " + missing + " not given");

  BenchOptions o;
  o.unit_sources = owner;
  o.data = first.at("data").get<std::string>();
  o.model = first.at("model_file").get<std::string>();
  o.learners = first.at("learners").get<std::vector<std::string>>();
  o.seed = first.at("seed").get<std::uint64_t>();
  o.reps = first.at("reps").get<int>();
  o.train_max = first.at("train_max").get<Eigen::Index>();
  o.test_max = first.at("test_max").get<Eigen::Index>();
  for (const auto& kv : first.at("config")) o.config.values.emplace_back(kv.at(0).get<std::string>(), kv.at(1).get<std::string>());
  o.out = out;
  o.log = log;
  o.reuse_only = true;
  return run_bench(registry, o);
}

}  // namespace spml
