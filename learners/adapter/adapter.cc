// Config parsing and model checks shared by the learner libraries (learner_adapter.h).
#include <cmath>
#include <stdexcept>

#include "spml/learner_adapter.h"
#include "spml/parse.h"

namespace spml::adapter {

Config::Config(const spml_learner_config* c) {
  if (!c) return;
  seed = c->seed;
  for (int32_t i = 0; i < c->count; ++i) values[c->keys[i]] = c->values[i];
}

double Config::number(const std::string& key) const {
  if (values.find(key) == values.end())
    throw std::runtime_error("config '" + key + "' is missing (the host fills every default in from the learner's key table)");
  return number(key, 0.0);
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

namespace spml::adapter {

void require_finite_training_data(const View& train) {
  auto first_bad = [](const ConstRowMap& a, const char* what) {
    for (Eigen::Index i = 0; i < a.rows(); ++i)
      for (Eigen::Index j = 0; j < a.cols(); ++j)
        if (!std::isfinite(a(i, j)))
          throw std::runtime_error(std::string("training ") + what + " holds a non-finite value (row " + std::to_string(i) +
                                   ", column " + std::to_string(j) + "): refused");
  };
  first_bad(train.X, "X");
  first_bad(train.Y, "Y");
  first_bad(train.phi, "regressor");
}

void require_query_like_fit(const View& query, Eigen::Index inputs, Eigen::Index outputs) {
  if (query.X.cols() != inputs || query.outputs != outputs)
    throw std::runtime_error("query has " + std::to_string(query.X.cols()) + " inputs and " + std::to_string(query.outputs) +
                             " outputs, the fit had " + std::to_string(inputs) + " and " + std::to_string(outputs));
}

}  // namespace spml::adapter
