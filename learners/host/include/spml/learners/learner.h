// The host side of learner plugins: loading libraries (spml/learner.h ABI), the C++
// Learner interface the evaluator uses, and sequential/iterative compositions "A-B" and
// "it-A-B" built from any two learners.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "spml/learner.h"
#include "spml/plugin_loader.h"
#include "spml/row_matrix.h"

namespace spml {

// Any problem running a learner; the message names the learner. (Loading problems are
// PluginError, shared with the force plugins.)
class LearnerError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Hears how far a fit has come: the fraction done in [0, 1], never going back, and the
// stage's text (ABI revision 1, spml_learner_progress). Called on the fitting thread.
using ProgressFn = std::function<void(double fraction, const char* stage)>;

struct LearnerConfig {
  std::vector<std::pair<std::string, std::string>> values;   // key=value as given by the user
  std::uint64_t seed = 1;
  // When set, learners that can (flag SPML_LEARNER_PROGRESS; compositions always) report
  // their progress here during fit(). It changes nothing in the fit.
  ProgressFn progress;
};

struct LearnerModel {
  std::vector<std::string> names;
  Eigen::VectorXd prior, truth;   // empty when unknown
};

// Inputs of fit/predict. phi: (outputs*rows) x params, output-major; null without a model.
struct LearnerData {
  const RowMatrix* X = nullptr;
  const RowMatrix* Y = nullptr;   // null in predict
  const RowMatrix* phi = nullptr;
  int outputs = 0;
};

struct LearnerPrediction {
  RowMatrix mean;   // rows x outputs
  RowMatrix var;    // rows x outputs, empty when the learner has no variance
};

class Learner {
 public:
  virtual ~Learner() = default;
  virtual std::string name() const = 0;
  virtual std::uint32_t flags() const = 0;
  virtual void fit(const LearnerData& train, const LearnerModel& model, const LearnerConfig& config) = 0;
  virtual LearnerPrediction predict(const LearnerData& query) const = 0;
  virtual std::string notes() const = 0;   // warnings of the last fit, "" when none
  virtual Eigen::VectorXd coefficients() const = 0;
  bool has_variance() const { return flags() & SPML_LEARNER_VARIANCE; }
  bool uses_model() const { return flags() & SPML_LEARNER_USES_MODEL; }
  bool reports_progress() const { return flags() & SPML_LEARNER_PROGRESS; }
};

// How learner libraries are recognised (symbol prefix, ABI version, search folders).
const PluginKind& learner_plugin_kind();
// "" for a table entry the host can use, else what is wrong with it (a required callback missing).
std::string learner_problem(const spml_learner& learner);

// All learners found on the search path (spml/plugin_loader.h), plus their compositions.
class LearnerRegistry {
 public:
  LearnerRegistry();
  // The shipped learners, then the folders in $SPML_LEARNER_PATH (':'-separated).
  void add_default_path();
  // A folder (every *.so in it; one that is not a learner library is skipped with a
  // warning) or one library file (which must load). Throws PluginError naming the file.
  void add(const std::string& folder_or_file);
  const std::vector<std::string>& warnings() const { return catalog_.warnings(); }

  const std::vector<std::string>& plugin_names() const { return catalog_.names(); }   // in load order
  const spml_learner* plugin(const std::string& name) const;
  std::string plugin_file(const std::string& name) const;
  // "all" (every plugin, and A-B, it-A-B for each parametric A and non-parametric B) or a
  // comma-separated list; every name is checked.
  std::vector<std::string> expand(const std::string& list) const;
  std::unique_ptr<Learner> create(const std::string& name) const;
  // The library files the named learner's code comes from (compositions: both parts').
  std::vector<std::string> library_files(const std::string& name) const;
  // Config keys the named learner accepts (compositions: both parts, plus "iterations").
  std::set<std::string> config_keys(const std::string& name) const;
  // "" if `value` suits key `key` of learner `name` (type and bounds from the learner's key
  // table), else the problem. The key must be one config_keys(name) lists.
  std::string check_config(const std::string& name, const std::string& key, const std::string& value) const;

 private:
  bool split_composition(const std::string& name, std::string* a, std::string* b, bool* iterative) const;
  PluginCatalog catalog_;
};

}  // namespace spml
