// The LibTorch learner library (spml/learner.h): BNN and BaMbANN. The networks live in
// bayes_net.cc; this file maps the ABI's data and config onto them.
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "bayes_net.h"
#include "spml/learner_adapter.h"
#include "spml/parse.h"

namespace spml::torch_learners {
namespace {

using adapter::Config;
using adapter::View;

// "auto" or comma-separated whole numbers. The paper's widths: 64 units per layer for its
// single-output scenarios (Toy, VIA), 128 for the three-output arm (SimDyn).
std::vector<int> hidden_layers(const Config& c, Eigen::Index outputs) {
  auto it = c.values.find("hidden");
  if (it == c.values.end() || it->second == "auto") return std::vector<int>(3, outputs > 1 ? 128 : 64);
  std::vector<int> out;
  std::stringstream ss(it->second);
  std::string word;
  while (std::getline(ss, word, ',')) {
    const auto v = parse_integer(word, 1, 100000);
    if (!v) throw std::runtime_error("config 'hidden': '" + it->second + "' is not 'auto' or a list of layer widths (1..100000)");
    out.push_back(static_cast<int>(*v));
  }
  if (out.empty()) throw std::runtime_error("config 'hidden': no layer width given");
  return out;
}

BayesNetOptions options_from(const Config& c, Eigen::Index outputs, bool model_path) {
  BayesNetOptions o;
  o.hidden = hidden_layers(c, outputs);
  o.epochs = static_cast<int>(c.number("epochs", o.epochs));
  o.steps = static_cast<int>(c.number("steps", o.steps));
  o.batch = static_cast<int>(c.number("batch", o.batch));
  o.learning_rate = c.number("learning_rate", o.learning_rate);
  o.prior_scale = c.number("prior_scale", o.prior_scale);
  o.model_warmup = c.number("model_warmup", o.model_warmup);
  o.kl_weight = c.number("kl_weight", o.kl_weight);
  o.model_prior_scale = c.number("model_prior_scale", o.model_prior_scale);
  o.obs_var = c.number("obs_var", o.obs_var);
  o.noise_floor = c.number("noise_floor", o.noise_floor);
  o.samples = static_cast<int>(c.number("samples", o.samples));
  o.threads = static_cast<int>(c.number("threads", o.threads));
  o.seed = c.seed;
  o.model_path = model_path;
  return o;
}

template <bool kModelPath>
class BayesLearner : public adapter::Learner {
 public:
  void fit(const View& d, const spml_learner_model& model, const Config& config) override {
    Eigen::VectorXd prior;
    if (kModelPath) {
      adapter::require_model(d, model, "BaMbANN");
      // The paper starts from the dataset's prior coefficients, from zeros where it has none.
      prior = model.prior ? Eigen::Map<const Eigen::VectorXd>(model.prior, model.params).eval()
                          : Eigen::VectorXd::Zero(model.params);
    }
    const BayesNetOptions options = options_from(config, d.outputs, kModelPath);
    net_ = std::make_unique<BayesNet>(options);
    net_->fit(d.X, d.Y, d.phi, prior);
    // notes are warnings (spml compare marks them): only what a user should look at.
    const Eigen::VectorXd noise = net_->noise_var();
    for (Eigen::Index o = 0; o < noise.size(); ++o)
      if (options.obs_var <= 0 && noise[o] <= net_->noise_floor_var(o))
        notes += (notes.empty() ? "" : "; ") + std::string("output ") + std::to_string(o) +
                 ": calibrated noise at its floor (the network interpolates the training rows)";
    if (kModelPath && !model.prior) notes += (notes.empty() ? "" : "; ") + std::string("theta started from zeros (the dataset has no prior)");
  }
  void predict(const View& q, double* mean, double* var) const override {
    if (!net_) throw std::runtime_error("predict before fit");
    net_->predict(q.X, q.phi, mean, var);
  }
  Eigen::VectorXd coefficients() const override { return net_ ? net_->theta_mean() : Eigen::VectorXd(); }

 private:
  std::unique_ptr<BayesNet> net_;
};

#define SPML_TORCH_COMMON_KEYS                                                                    \
  {"hidden", SPML_VALUE_TEXT, 0, 0, "auto", "units per hidden layer, e.g. 64,64,64; auto: 64 each for one output, 128 for more"}, \
  {"epochs", SPML_VALUE_INTEGER, 0, 1e7, "0", "passes over the data; 0: as many as make `steps` optimiser steps"},    \
  {"steps", SPML_VALUE_INTEGER, 1, 1e9, "3000", "Adam steps when epochs = 0"},                                     \
  {"batch", SPML_VALUE_INTEGER, 1, 1e9, "64", "rows per Adam step"},                                              \
  {"learning_rate", SPML_VALUE_NUMBER, 1e-9, 10, "1e-2", "Adam step size"},                                         \
  {"kl_weight", SPML_VALUE_NUMBER, 0, 1, "1e-3", "beta: loss = NLL + beta KL / rows; 1 is the exact ELBO"},           \
  {"prior_scale", SPML_VALUE_NUMBER, 1e-9, 1e9, "1", "dense weights ~ N(0, prior_scale^2 / fan_in)"},     \
  {"obs_var", SPML_VALUE_NUMBER, 0, HUGE_VAL, "0", "fixed observation variance in target units^2; 0: learned"},     \
  {"noise_floor", SPML_VALUE_NUMBER, 0, 1, "1e-6", "learned noise: lower bound, fraction of the target variance"},  \
  {"samples", SPML_VALUE_INTEGER, 2, 1e6, "30", "weight draws per prediction"},                                   \
  {"threads", SPML_VALUE_INTEGER, 1, 1024, "1", "LibTorch threads (results depend on it: fixed for reproducibility)"}

constexpr spml_config_key kBnnKeys[] = {SPML_TORCH_COMMON_KEYS, {nullptr, 0, 0, 0, nullptr, nullptr}};
constexpr spml_config_key kBambannKeys[] = {
    SPML_TORCH_COMMON_KEYS,
    {"model_prior_scale", SPML_VALUE_NUMBER, 1e-9, 1e9, "10",
     "theta's g-prior: N(prior, s^2) per whitened direction, s in target RMS"},
    {"model_warmup", SPML_VALUE_NUMBER, 0, 1, "0", "fraction of the epochs that fit the model layer alone"},
    {nullptr, 0, 0, 0, nullptr, nullptr}};

const std::vector<spml_learner>& all() {
  static const std::vector<spml_learner> list{
      adapter::make_learner<BayesLearner<false>>(
          "BNN", "Bayesian neural network (Bayes by backprop), 3 ELU layers, no model",
          SPML_LEARNER_VARIANCE | SPML_LEARNER_NONPARAMETRIC, kBnnKeys),
      adapter::make_learner<BayesLearner<true>>(
          "BaMbANN", "BNN plus a Bayesian model layer phi(x).theta, trained jointly",
          SPML_LEARNER_VARIANCE | SPML_LEARNER_USES_MODEL, kBambannKeys)};
  return list;
}

}  // namespace
}  // namespace spml::torch_learners

extern "C" SPML_EXPORT int32_t spml_learner_abi_version(void) { return SPML_LEARNER_ABI_VERSION; }

extern "C" SPML_EXPORT const spml_learner* spml_learner_get(int32_t index) {
  return spml::adapter::learner_at(spml::torch_learners::all(), index);
}
