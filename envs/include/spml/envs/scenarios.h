// The paper's scenarios, regenerated headlessly into spml/1 datasets.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "spml/dataset.h"

namespace spml {

struct GenerateOptions {
  std::uint64_t seed = 1;
  int test_stride = 1;   // SimDyn: keep every n-th 1 kHz test sample (1 = the paper's 1 kHz)
  std::function<void(const std::string& stage, double fraction)> progress;   // may be empty
};

// toy, via-inst, via-ar, simdyn-ll, simdyn-gl (the paper), simdyn-ll-fresh, simdyn-gl-fresh
const std::vector<std::string>& scenario_names();
Dataset generate_scenario(const std::string& name, const GenerateOptions& options);

Dataset generate_toy(const GenerateOptions& options);
Dataset generate_via(bool autoregressive, const GenerateOptions& options);
// fresh_interp: test_interp follows new phases (a new path through the training region)
// instead of retracing the training path as in the paper.
Dataset generate_simdyn(bool global_mismatch, const GenerateOptions& options, bool fresh_interp = false);

// Toy basis phi(x) = (sin 2x, x, 1, 0.09 x^2) and the scenario's true theta.
Eigen::Vector4d toy_features(double x);
double toy_deviation(double x);

}  // namespace spml
