// `spml identify --estimator consistent`: the physically consistent fit of every body and joint
// term, printed beside the MJCF's values, and optionally written as a model file.
#pragma once

#include <string>

namespace spml::cli {

struct ConsistentArgs {
  std::string model, data, split = "train", write_model;
  bool json = false, offsets = false;
  double prior_weight = 1.0;
};

void identify_consistent_command(const ConsistentArgs& a);

}  // namespace spml::cli
