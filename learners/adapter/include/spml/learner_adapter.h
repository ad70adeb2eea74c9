// The C++ side of spml's learner libraries (built-in, torch): each learner is a class with
// fit/predict on Eigen views; make_learner<T>() wraps it in the C ABI of spml/learner.h,
// turning exceptions into error messages so nothing unwinds across the boundary.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "spml/learner.h"
#include "spml/row_matrix.h"

namespace spml::adapter {

using ConstRowMap = Eigen::Map<const RowMatrix>;

// The ABI's data as Eigen views (phi has 0 columns when the host gave none).
struct View {
  ConstRowMap X, Y, phi;
  Eigen::Index outputs;
  explicit View(const spml_learner_data& d)
      : X(d.x, d.rows, d.inputs),
        Y(d.y, d.y ? d.rows : 0, d.outputs),
        phi(d.phi, d.phi ? d.rows * d.outputs : 0, d.phi ? d.params : 0),
        outputs(d.outputs) {}
};

struct Config {
  std::map<std::string, std::string> values;
  std::uint64_t seed = 0;
  explicit Config(const spml_learner_config* c);
  // A key with a default in the learner's table: the host has filled it in (spml/plugin_loader.h,
  // with_defaults), so a missing one is an error, naming the key. Defaults live in the table only.
  double number(const std::string& key) const;
  // A key whose default is worked out from the data (NULL in the table): `fallback` when not given.
  double number(const std::string& key, double fallback) const;   // throws naming the key
};

// Where a fit's progress goes (ABI revision 1): the host's callback, or nowhere. Keeps the
// promise the ABI makes for the learner - fractions within [0, 1] that never go back - so a
// learner can report its best estimate (a phase that ends early, a guess that was too low)
// without checking that itself.
class Progress {
 public:
  Progress() = default;
  Progress(spml_learner_progress callback, void* context) : callback_(callback), context_(context) {}
  void operator()(double fraction, const char* stage = "") {
    if (!callback_ || !(fraction == fraction)) return;   // NaN: nothing to say
    last_ = std::max(last_, std::min(1.0, std::max(0.0, fraction)));
    callback_(context_, last_, stage ? stage : "");
  }
  bool active() const { return callback_ != nullptr; }
  double last() const { return last_; }

 private:
  spml_learner_progress callback_ = nullptr;
  void* context_ = nullptr;
  double last_ = 0;
};

// Maps a part of a fit onto [from, to] of the whole: part(f) reports from + f (to - from). A
// learner made of stages (outputs fitted one after the other, a subset fit then a full one)
// hands one to each stage.
inline std::function<void(double)> progress_part(Progress& whole, double from, double to, const char* stage) {
  if (!whole.active()) return {};
  return [&whole, from, to, stage](double f) { whole(from + std::min(1.0, std::max(0.0, f)) * (to - from), stage); };
}

class Learner {
 public:
  virtual ~Learner() = default;
  virtual void fit(const View& train, const spml_learner_model& model, const Config& config) = 0;
  // mean, var: rows x outputs row-major buffers; var may be null.
  virtual void predict(const View& query, double* mean, double* var) const = 0;
  virtual Eigen::VectorXd coefficients() const { return {}; }
  std::string notes;
  Eigen::Index fitted_inputs = 0, fitted_outputs = 0;   // set by the adapter: what predict must match
  // During fit(): reports to the host when it asked for progress (fit_progress), else nothing.
  // A learner flagged SPML_LEARNER_PROGRESS calls it; the adapter reports 1 when fit returns.
  Progress progress;
};

// Throws unless the host passed a regressor with the model's parameter count.
void require_model(const View& data, const spml_learner_model& model, const char* learner);
// The checks every learner needs, once (spml check-plugin's contract): fit data holding no NaN
// or Inf, and a query as wide as the fit's data. Throw with the message the host shows.
void require_finite_training_data(const View& train);
void require_query_like_fit(const View& query, Eigen::Index inputs, Eigen::Index outputs);

template <class T>
struct Adapter {
  static void* fit(const spml_learner_data* train, const spml_learner_model* model, const spml_learner_config* config,
                   char* error, size_t error_size) {
    return fit_progress(train, model, config, nullptr, nullptr, error, error_size);
  }
  // fit with progress (ABI revision 1); the same fit, only observed.
  static void* fit_progress(const spml_learner_data* train, const spml_learner_model* model,
                            const spml_learner_config* config, spml_learner_progress callback, void* context, char* error,
                            size_t error_size) {
    try {
      const View data(*train);
      require_finite_training_data(data);
      auto learner = std::make_unique<T>();
      learner->progress = Progress(callback, context);
      learner->progress(0.0, "start");
      learner->fit(data, *model, Config(config));
      learner->progress(1.0, "done");
      learner->progress = Progress();   // the host's callback is valid during this call only
      learner->fitted_inputs = data.X.cols();
      learner->fitted_outputs = data.outputs;
      return learner.release();
    } catch (const std::exception& e) {
      std::snprintf(error, error_size, "%s", e.what());
      return nullptr;
    }
  }
  static int predict(void* state, const spml_learner_data* query, double* mean, double* var, char* error,
                     size_t error_size) {
    try {
      const T& learner = *static_cast<const T*>(state);
      const View q(*query);
      require_query_like_fit(q, learner.fitted_inputs, learner.fitted_outputs);
      learner.predict(q, mean, var);
      return 0;
    } catch (const std::exception& e) {
      std::snprintf(error, error_size, "%s", e.what());
      return 1;
    }
  }
  static const char* notes(void* state) { return static_cast<T*>(state)->notes.c_str(); }
  static int32_t coefficients(void* state, double* theta, int32_t capacity) {
    Eigen::VectorXd c = static_cast<T*>(state)->coefficients();
    for (int32_t i = 0; i < capacity && i < c.size(); ++i) theta[i] = c[i];
    return static_cast<int32_t>(c.size());
  }
  static void destroy(void* state) { delete static_cast<T*>(state); }
};

// The entry of learner T. fit_progress is always filled in; the host uses it when `flags` has
// SPML_LEARNER_PROGRESS, which a learner sets when its fit calls `progress` along the way.
template <class T>
spml_learner make_learner(const char* name, const char* summary, uint32_t flags, const spml_config_key* keys) {
  return spml_learner{SPML_LEARNER_ABI_VERSION, name, summary, flags, keys,
                      &Adapter<T>::fit, &Adapter<T>::predict, &Adapter<T>::notes,
                      &Adapter<T>::coefficients, &Adapter<T>::destroy, &Adapter<T>::fit_progress};
}

}  // namespace spml::adapter
