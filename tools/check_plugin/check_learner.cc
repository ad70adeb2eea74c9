// The learner clauses, on small seeded synthetic data: 3 inputs, 2 outputs and a linear
// parametric model with 3 coefficients (prior and truth given when the flags ask for them),
// plus a residual the model cannot express and a little noise. Training inputs lie in
// [-2, 2]; the query is larger (200 rows) and reaches twice as far, [-4, 4], because a
// learner is asked to extrapolate (spml bench's extrapolation split) and a fault that shows
// only far out or only on a long query must not pass.
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "detail.h"
#include "spml/learner.h"
#include "spml/learners/learner.h"

namespace spml::check {
namespace {

constexpr int kInputs = 3, kOutputs = 2, kParams = 3, kTrainRows = 40, kQueryRows = 200;
constexpr double kTrainReach = 2, kQueryReach = 4;   // inputs uniform in [-reach, reach]
const double kTheta[kParams] = {1.5, -0.8, 0.6};
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Rows of x, y and the stacked regressor (output-major, spml/learner.h).
struct Data {
  int64_t rows = 0;
  int32_t inputs = kInputs;
  std::vector<double> x, y, phi;
  spml_learner_data view(bool with_y = true) const {
    return {rows, inputs, kOutputs, x.data(), with_y ? y.data() : nullptr, kParams, phi.data()};
  }
};

Data synthetic(int64_t rows, std::uint64_t seed, double reach) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-reach, reach);
  std::normal_distribution<double> noise(0, 0.05);
  Data d;
  d.rows = rows;
  d.x.resize(static_cast<size_t>(rows * kInputs));
  for (double& v : d.x) v = u(rng);
  d.phi.resize(static_cast<size_t>(kOutputs * rows * kParams));
  d.y.resize(static_cast<size_t>(rows * kOutputs));
  for (int o = 0; o < kOutputs; ++o)
    for (int64_t i = 0; i < rows; ++i) {
      const double* x = &d.x[static_cast<size_t>(i * kInputs)];
      double* phi = &d.phi[static_cast<size_t>((o * rows + i) * kParams)];
      phi[0] = x[0];
      phi[1] = std::sin(x[1]) * (o + 1);
      phi[2] = 1 + 0.5 * o * x[2];
      const double model = phi[0] * kTheta[0] + phi[1] * kTheta[1] + phi[2] * kTheta[2];
      d.y[static_cast<size_t>(i * kOutputs + o)] = model + 0.4 * std::cos(2 * x[2]) + noise(rng);
    }
  return d;
}

// A query as `like` but one input wider (the regressor unchanged).
Data wider(const Data& like) {
  Data d = like;
  d.inputs = like.inputs + 1;
  d.x.clear();
  for (int64_t i = 0; i < like.rows; ++i) {
    d.x.insert(d.x.end(), like.x.begin() + i * like.inputs, like.x.begin() + (i + 1) * like.inputs);
    d.x.push_back(0.5);
  }
  return d;
}

const double kPrior[kParams] = {0.9 * kTheta[0] + 0.05, 0.9 * kTheta[1] + 0.05, 0.9 * kTheta[2] + 0.05};

// "" when `after` holds the same bytes as `before`, else which array changed and where first.
std::string changed(const std::vector<double>& before, const double* after, const char* what) {
  for (size_t i = 0; i < before.size(); ++i)
    if (std::memcmp(&before[i], &after[i], sizeof(double)) != 0)
      return std::string(what) + "[" + std::to_string(i) + "] was " + num(before[i]) + ", is " + num(after[i]);
  return "";
}

// "" when the copy `used` still equals `given` byte for byte (x, y, phi), else what changed.
std::string data_changed(const Data& given, const Data& used) {
  std::string why = changed(given.x, used.x.data(), "x");
  if (why.empty()) why = changed(given.y, used.y.data(), "y");
  if (why.empty()) why = changed(given.phi, used.phi.data(), "phi");
  return why;
}

// One fit through the raw ABI, as the host makes it (defaults filled in from the key table),
// on a copy of the data and of the model's coefficients (a learner that writes into its
// inputs spoils only the copy; the inputs-untouched clause compares them).
// What a fit through fit_progress reported: every fraction, in order.
struct Reports {
  std::vector<double> fractions;
  static void hear(void* context, double fraction, const char*) { static_cast<Reports*>(context)->fractions.push_back(fraction); }
};

class Fit {
 public:
  // With `reports`, the fit goes through fit_progress (ABI revision 1) and records what it hears.
  Fit(const spml_learner& l, const Data& train, std::uint64_t seed, const std::vector<std::pair<std::string, std::string>>& given,
      Reports* reports = nullptr)
      : l_(l), data_(train), prior_(kPrior, kPrior + kParams), truth_(kTheta, kTheta + kParams) {
    const auto config = with_defaults(l.config_keys, given);
    std::vector<const char*> keys, values;
    for (const auto& [k, v] : config) {
      keys.push_back(k.c_str());
      values.push_back(v.c_str());
    }
    const spml_learner_config c{static_cast<int32_t>(keys.size()), keys.data(), values.data(), seed};
    static const char* const names[kParams] = {"theta0", "theta1", "theta2"};
    const spml_learner_model m{kParams, names, (l.flags & SPML_LEARNER_NEEDS_PRIOR) ? prior_.data() : nullptr,
                               (l.flags & SPML_LEARNER_NEEDS_TRUTH) ? truth_.data() : nullptr};
    const spml_learner_data d = data_.view();
    char error[1024] = "";
    state_ = reports ? l.fit_progress(&d, &m, &c, &Reports::hear, reports, error, sizeof error)
                     : l.fit(&d, &m, &c, error, sizeof error);
    error_ = error;
  }
  ~Fit() {
    if (state_) l_.destroy(state_);
  }
  Fit(const Fit&) = delete;
  Fit& operator=(const Fit&) = delete;
  void* state() const { return state_; }
  const std::string& error() const { return error_; }
  // What fit wrote into its inputs (compared with `given`, the data it was made from).
  std::string inputs_changed(const Data& given) const {
    std::string why = data_changed(given, data_);
    if (why.empty()) why = changed(std::vector<double>(kPrior, kPrior + kParams), prior_.data(), "model prior");
    if (why.empty()) why = changed(std::vector<double>(kTheta, kTheta + kParams), truth_.data(), "model truth");
    return why;
  }

 private:
  const spml_learner& l_;
  const Data data_;
  const std::vector<double> prior_, truth_;
  void* state_ = nullptr;
  std::string error_;
};

struct Prediction {
  int rc = 0;
  std::string error;
  std::vector<double> mean, var;   // pre-filled with NaN: what stays NaN was not written
};

// Predicts on a copy of `query`; `used` (when given) receives the copy as predict left it.
Prediction predict(const spml_learner& l, const Fit& fit, const Data& given, Data* used = nullptr) {
  Data copy = given;
  const Data& query = copy;
  Prediction p;
  p.mean.assign(static_cast<size_t>(query.rows * kOutputs), kNaN);
  const bool has_var = l.flags & SPML_LEARNER_VARIANCE;
  if (has_var) p.var.assign(p.mean.size(), kNaN);
  const spml_learner_data d = query.view(false);
  char error[1024] = "";
  p.rc = l.predict(fit.state(), &d, p.mean.data(), has_var ? p.var.data() : nullptr, error, sizeof error);
  p.error = error;
  if (used) *used = std::move(copy);
  return p;
}

// "" when a and b hold the same numbers bit for bit, else where they differ first and by how much.
std::string difference(const Prediction& a, const Prediction& b) {
  auto first = [](const std::vector<double>& x, const std::vector<double>& y, const char* what) -> std::string {
    double largest = 0;
    std::string at;
    for (size_t i = 0; i < x.size(); ++i)
      if (!(x[i] == y[i]) && !(std::isnan(x[i]) && std::isnan(y[i]))) {   // unwritten twice is outputs-written's
        if (at.empty()) at = "row " + std::to_string(i / kOutputs) + " output " + std::to_string(i % kOutputs);
        largest = std::max(largest, std::fabs(x[i] - y[i]));
      }
    return at.empty() ? "" : std::string(what) + " differ (first at " + at + ", largest difference " + num(largest) + ")";
  };
  std::string d = first(a.mean, b.mean, "means");
  if (d.empty()) d = first(a.var, b.var, "variances");
  return d;
}

Outcome outputs_written(const Prediction& p) {
  if (p.rc != 0) return fail("predict failed on a query of the training width: " + p.error);
  auto bad = [](const std::vector<double>& v, const char* what) -> std::string {
    size_t count = 0, first = 0;
    for (size_t i = v.size(); i-- > 0;)
      if (!std::isfinite(v[i])) ++count, first = i;
    if (!count) return "";
    return std::to_string(count) + " of " + std::to_string(v.size()) + " " + what + " unwritten or non-finite (pre-filled " +
           "with NaN; first at row " + std::to_string(first / kOutputs) + " output " + std::to_string(first % kOutputs) + ")";
  };
  std::string why = bad(p.mean, "means");
  if (why.empty()) why = bad(p.var, "variances");
  if (!why.empty()) return fail(why);
  return pass(std::to_string(p.mean.size()) + " means" + (p.var.empty() ? "" : " and " + std::to_string(p.var.size()) + " variances") +
              " written, finite (" + std::to_string(kQueryRows) + " rows in [-" + num(kQueryReach) + ", " + num(kQueryReach) +
              "], trained on [-" + num(kTrainReach) + ", " + num(kTrainReach) + "])");
}

// Over the variances written (an unwritten one is outputs-written's failure).
Outcome variance_positive(const spml_learner& l, const Prediction& p) {
  if (!(l.flags & SPML_LEARNER_VARIANCE)) return skip("not flagged VARIANCE");
  if (p.rc != 0) return fail("no variances to check: predict failed");
  size_t worst = p.var.size();
  for (size_t i = 0; i < p.var.size(); ++i)
    if (!std::isnan(p.var[i]) && (worst == p.var.size() || p.var[i] < p.var[worst])) worst = i;
  if (worst == p.var.size()) return fail("no variance written");
  if (p.var[worst] > 0) return pass("smallest variance " + num(p.var[worst]));
  return fail("variance " + num(p.var[worst]) + " at row " + std::to_string(worst / kOutputs) + " output " +
              std::to_string(worst % kOutputs) + " (must be > 0)");
}

Outcome coefficients(const spml_learner& l, const Fit& fit) {
  if (!l.coefficients) return skip("no coefficients callback");
  const int32_t n = l.coefficients(fit.state(), nullptr, 0);
  if (n == 0) return pass("none (0)");
  if (n != kParams) return fail("returned " + std::to_string(n) + " coefficients for a model of " + std::to_string(kParams));
  std::vector<double> theta(kParams, kNaN);
  const int32_t again = l.coefficients(fit.state(), theta.data(), kParams);
  for (int j = 0; j < kParams; ++j)
    if (!std::isfinite(theta[j])) return fail("coefficient " + std::to_string(j) + " is " + num(theta[j]) + " (unwritten or non-finite)");
  if (again != n) return fail("count changed between calls: " + std::to_string(n) + " then " + std::to_string(again));
  return pass(std::to_string(n) + " finite values (" + num(theta[0]) + ", " + num(theta[1]) + ", " + num(theta[2]) + ")");
}

// The inputs are const in the ABI: a learner that writes into x, y, phi or the model's
// coefficients (during fit or predict) corrupts the host's dataset for every later learner.
// On the first fit (made on copies), so that the clause costs no fit of its own.
Outcome inputs_untouched(const spml_learner& l, const Fit& fit, const Data& train, const Data& query) {
  if (std::string why = fit.inputs_changed(train); !why.empty()) return fail("fit wrote into its inputs: " + why);
  Data used;
  predict(l, fit, query, &used);
  if (std::string why = data_changed(query, used); !why.empty()) return fail("predict wrote into its query: " + why);
  return pass("x, y, phi, prior and truth byte for byte the same after fit and predict");
}

Outcome nan_refused(const spml_learner& l, const Data& train, std::uint64_t seed,
                    const std::vector<std::pair<std::string, std::string>>& given) {
  for (const char* where : {"X", "Y"}) {
    Data bad = train;
    (where[0] == 'X' ? bad.x : bad.y)[7] = kNaN;
    Fit fit(l, bad, seed, given);
    if (fit.state()) return fail("fit accepted a NaN in " + std::string(where) + " (row 3)");
    if (fit.error().empty()) return fail("fit refused a NaN in " + std::string(where) + " without a message");
  }
  return pass("refused with a message");
}

// Revision 1: a learner flagged PROGRESS reports fractions within [0, 1] that never go back,
// and fit_progress fits exactly as fit (the same predictions, bit for bit, for the same seed).
Outcome progress(const spml_learner& l, const Data& train, const Data& query, const Prediction& fitted, std::uint64_t seed,
                 const std::vector<std::pair<std::string, std::string>>& given) {
  if (!(l.flags & SPML_LEARNER_PROGRESS)) return skip("not flagged PROGRESS (ABI revision 1)");
  Reports heard;
  Fit fit(l, train, seed, given, &heard);
  if (!fit.state()) return fail("fit_progress failed where fit succeeded: " + (fit.error().empty() ? "no message" : fit.error()));
  const std::vector<double>& f = heard.fractions;
  if (f.empty()) return fail("flagged PROGRESS, but fit_progress reported nothing");
  for (size_t i = 0; i < f.size(); ++i) {
    if (!(f[i] >= 0 && f[i] <= 1))
      return fail("report " + std::to_string(i + 1) + " of " + std::to_string(f.size()) + ": fraction " + num(f[i]) +
                  " is outside [0, 1]");
    if (i > 0 && f[i] < f[i - 1])
      return fail("report " + std::to_string(i + 1) + " of " + std::to_string(f.size()) + ": the fraction went back from " +
                  num(f[i - 1]) + " to " + num(f[i]));
  }
  const std::string d = difference(fitted, predict(l, fit, query));
  if (!d.empty()) return fail("fit_progress and fit with seed " + std::to_string(seed) + " predict differently: " + d);
  return pass(std::to_string(f.size()) + " reports, " + num(f.front()) + " to " + num(f.back()) +
              ", never back; predictions identical to fit's");
}

void check_one(const spml_learner& l, Recorder& r) {
  const std::string name = l.name;
  if (std::string why = learner_problem(l); !why.empty()) return r.record(name, "callbacks", fail(why));
  r.record(name, "callbacks", pass());
  r.run(name, "key-table", [&] {
    const std::string why = key_table_problems(l.config_keys, false);
    return why.empty() ? pass() : fail(why);
  });
  const Data train = synthetic(kTrainRows, r.seed(), kTrainReach), query = synthetic(kQueryRows, r.seed() + 1, kQueryReach);
  std::unique_ptr<Fit> a;
  Prediction pa;
  std::vector<std::pair<std::string, std::string>> given;
  r.run(name, "fit", [&] {
    given = r.config_for(l.config_keys);
    a = std::make_unique<Fit>(l, train, r.seed(), given);
    return a->state() ? pass(std::to_string(kTrainRows) + " rows, " + std::to_string(kInputs) + " inputs, " +
                             std::to_string(kOutputs) + " outputs, " + std::to_string(kParams) + " model coefficients")
                      : fail("fit failed on the synthetic data: " + (a->error().empty() ? "no message" : a->error()));
  });
  if (!a || !a->state()) return;
  r.run(name, "outputs-written", [&] { return outputs_written(pa = predict(l, *a, query)); });
  r.run(name, "variance-positive", [&] { return variance_positive(l, pa); });
  r.run(name, "same-seed", [&] {
    Fit b(l, train, r.seed(), given);
    if (!b.state()) return fail("the second fit failed: " + b.error());
    const std::string d = difference(pa, predict(l, b, query));
    return d.empty() ? pass("two fits with seed " + std::to_string(r.seed()) + " predict identically") : fail(d);
  });
  r.run(name, "deterministic", [&] {
    if (!(l.flags & SPML_LEARNER_DETERMINISTIC)) return skip("not flagged DETERMINISTIC");
    Fit c(l, train, r.seed() + 17, given);
    if (!c.state()) return fail("the fit with another seed failed: " + c.error());
    const std::string d = difference(pa, predict(l, c, query));
    return d.empty() ? pass("fits with seeds " + std::to_string(r.seed()) + " and " + std::to_string(r.seed() + 17) +
                            " predict identically")
                     : fail("flagged DETERMINISTIC, but fits with seeds " + std::to_string(r.seed()) + " and " +
                            std::to_string(r.seed() + 17) + ": " + d);
  });
  r.run(name, "coefficients", [&] { return coefficients(l, *a); });
  r.run(name, "query-width", [&] {
    const Prediction p = predict(l, *a, wider(query));
    if (p.rc == 0) return fail("predict accepted a query of " + std::to_string(kInputs + 1) + " inputs after a fit on " + std::to_string(kInputs));
    return p.error.empty() ? fail("refused a query of another width without a message") : pass("refused: " + p.error);
  });
  r.run(name, "inputs-untouched", [&] { return inputs_untouched(l, *a, train, query); });
  r.run(name, "nan-refused", [&] { return nan_refused(l, train, r.seed(), given); });
  r.run(name, "progress", [&] { return progress(l, train, query, pa, r.seed(), given); });
}

}  // namespace

void check_learners(const std::string& file, Recorder& recorder) {
  const auto lib = load_library(file, learner_plugin_kind(), recorder);
  if (!lib) return;
  for (const void* e : lib->entries())
    if (recorder.wanted(static_cast<const spml_learner*>(e)->name)) check_one(*static_cast<const spml_learner*>(e), recorder);
}

}  // namespace spml::check
