// The host side of learner plugins: loading libraries (spml/learner.h ABI), the C++
// Learner interface the evaluator uses, and sequential/iterative compositions "A-B" and
// "it-A-B" built from any two learners.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "spml/learner.h"

namespace spml {

using LearnerMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Any problem loading or running a learner; the message names the file or the learner.
class LearnerError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct LearnerConfig {
  std::vector<std::pair<std::string, std::string>> values;   // key=value as given by the user
  std::uint64_t seed = 1;
};

struct LearnerModel {
  std::vector<std::string> names;
  Eigen::VectorXd prior, truth;   // empty when unknown
};

// Inputs of fit/predict. phi: (outputs*rows) x params, output-major; null without a model.
struct LearnerData {
  const LearnerMatrix* X = nullptr;
  const LearnerMatrix* Y = nullptr;   // null in predict
  const LearnerMatrix* phi = nullptr;
  int outputs = 0;
};

struct LearnerPrediction {
  LearnerMatrix mean;   // rows x outputs
  LearnerMatrix var;    // rows x outputs, empty when the learner has no variance
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
};

class LearnerLibrary;

// All learners found on a search path, plus their compositions.
class LearnerRegistry {
 public:
  LearnerRegistry();
  ~LearnerRegistry();
  // The build's learner folder, then the folders in $SPML_LEARNER_PATH (':'-separated).
  static std::vector<std::string> default_search_path();
  // A folder (every *.so in it is loaded) or one library file. Throws LearnerError naming
  // the file for a library that is not a learner, has another ABI version or clashes.
  void add(const std::string& folder_or_file);
  void add_default_path();

  std::vector<std::string> plugin_names() const;   // in load order
  const spml_learner* plugin(const std::string& name) const;
  std::string plugin_file(const std::string& name) const;
  // "all" (every plugin, and A-B, it-A-B for each parametric A and non-parametric B) or a
  // comma-separated list; every name is checked.
  std::vector<std::string> expand(const std::string& list) const;
  std::unique_ptr<Learner> create(const std::string& name) const;
  // Config keys the named learner accepts (compositions: both parts, plus "iterations").
  std::set<std::string> config_keys(const std::string& name) const;

 private:
  bool parse_composition(const std::string& name, std::string* a, std::string* b, bool* iterative) const;
  std::vector<std::shared_ptr<LearnerLibrary>> libraries_;
  std::map<std::string, std::pair<const spml_learner*, std::shared_ptr<LearnerLibrary>>> plugins_;
  std::vector<std::string> order_;
};

// Iterations of it-A-B when the config does not say (the paper: "a fixed number of times").
inline constexpr int kDefaultIterations = 3;

}  // namespace spml
