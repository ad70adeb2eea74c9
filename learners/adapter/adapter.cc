// Config parsing and model checks shared by the learner libraries (learner_adapter.h).
#include <stdexcept>

#include "spml/learner_adapter.h"
#include "spml/parse.h"

namespace spml::adapter {

Config::Config(const spml_learner_config* c) {
  if (!c) return;
  seed = c->seed;
  for (int32_t i = 0; i < c->count; ++i) values[c->keys[i]] = c->values[i];
}

double Config::number(const std::string& key, double fallback) const {
  auto it = values.find(key);
  if (it == values.end()) return fallback;
  const auto v = parse_number(it->second);
  if (!v) throw std::runtime_error("config '" + key + "': '" + it->second + "' is not a number");
  return *v;
}

void require_model(const View& data, const spml_learner_model& model, const char* learner) {
  if (data.phi.cols() == 0)
    throw std::runtime_error(std::string(learner) + " needs the dataset's parametric model, and there is none");
  if (model.params != data.phi.cols())
    throw std::runtime_error(std::string(learner) + ": model lists " + std::to_string(model.params) +
                             " parameters, the regressor has " + std::to_string(data.phi.cols()) + " columns");
}

}  // namespace spml::adapter
