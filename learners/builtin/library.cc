// Entry points of the built-in learner library (spml/learner.h, ABI v1).
#include <cstdlib>
#include <stdexcept>
#include <vector>

#include "learners.h"
#include "spml/parse.h"

namespace spml::builtin {

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

namespace {
const std::vector<spml_learner>& all() {
  static const std::vector<spml_learner> list = [] {
    std::vector<spml_learner> v{lls_learner(), svr_learner(), lls_prior_learner(), lls_simulated_learner()};
    add_gaussian_process_learners(v);
    return v;
  }();
  return list;
}
}  // namespace

}  // namespace spml::builtin

extern "C" SPML_EXPORT int32_t spml_learner_abi_version(void) { return SPML_LEARNER_ABI_VERSION; }

extern "C" SPML_EXPORT const spml_learner* spml_learner_get(int32_t index) {
  const auto& list = spml::builtin::all();
  return index >= 0 && static_cast<size_t>(index) < list.size() ? &list[static_cast<size_t>(index)] : nullptr;
}
