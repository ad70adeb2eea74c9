// BNN and BaMbANN configuration: the key tables (the only place the defaults are written) and
// their translation into BayesNetOptions.
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "bayes_net.h"
#include "spml/parse.h"

namespace spml::torch_learners {
namespace {

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

// "auto" or comma-separated whole numbers. The paper's widths: 64 units per layer for its
// single-output scenarios (Toy, VIA), 128 for the three-output arm (SimDyn).
std::vector<int> hidden_layers(const std::string& text, Eigen::Index outputs) {
  if (text == "auto") return std::vector<int>(3, outputs > 1 ? 128 : 64);
  std::vector<int> out;
  std::stringstream ss(text);
  std::string word;
  while (std::getline(ss, word, ',')) {
    const auto v = parse_integer(word, 1, 100000);
    if (!v) throw std::runtime_error("config 'hidden': '" + text + "' is not 'auto' or a list of layer widths (1..100000)");
    out.push_back(static_cast<int>(*v));
  }
  if (out.empty()) throw std::runtime_error("config 'hidden': no layer width given");
  return out;
}

}  // namespace

const spml_config_key* bayes_net_keys(bool model_path) { return model_path ? kBambannKeys : kBnnKeys; }

BayesNetOptions bayes_net_options(const std::map<std::string, std::string>& values, Eigen::Index outputs,
                                  bool model_path, std::uint64_t seed) {
  auto text = [&](const char* key) -> std::string {
    if (auto it = values.find(key); it != values.end()) return it->second;
    for (const spml_config_key* k = bayes_net_keys(model_path); k->name; ++k)
      if (std::string(k->name) == key) return k->default_value;
    throw std::logic_error(std::string("no config key '") + key + "'");
  };
  auto number = [&](const char* key) {
    const std::string t = text(key);
    const auto v = parse_number(t);
    if (!v) throw std::runtime_error(std::string("config '") + key + "': '" + t + "' is not a number");
    return *v;
  };
  BayesNetOptions o;
  o.hidden = hidden_layers(text("hidden"), outputs);
  o.epochs = static_cast<int>(number("epochs"));
  o.steps = static_cast<int>(number("steps"));
  o.batch = static_cast<int>(number("batch"));
  o.learning_rate = number("learning_rate");
  o.prior_scale = number("prior_scale");
  o.kl_weight = number("kl_weight");
  o.obs_var = number("obs_var");
  o.noise_floor = number("noise_floor");
  o.samples = static_cast<int>(number("samples"));
  o.threads = static_cast<int>(number("threads"));
  if (model_path) {
    o.model_warmup = number("model_warmup");
    o.model_prior_scale = number("model_prior_scale");
  }
  o.seed = seed;
  o.model_path = model_path;
  return o;
}

}  // namespace spml::torch_learners
