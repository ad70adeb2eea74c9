#include "spml/envs/scenarios.h"
#include "spml/version.h"

#include <stdexcept>

namespace spml {

const std::vector<std::string>& scenario_names() {
  static const std::vector<std::string> names = {"toy", "via-inst", "via-ar", "simdyn-ll", "simdyn-gl",
                                                      "simdyn-ll-fresh", "simdyn-gl-fresh"};
  return names;
}

Dataset generate_scenario(const std::string& name, const GenerateOptions& options) {
  Dataset ds;
  if (name == "toy") ds = generate_toy(options);
  else if (name == "via-inst") ds = generate_via(false, options);
  else if (name == "via-ar") ds = generate_via(true, options);
  else if (name == "simdyn-ll") ds = generate_simdyn(false, options);
  else if (name == "simdyn-gl") ds = generate_simdyn(true, options);
  else if (name == "simdyn-ll-fresh") ds = generate_simdyn(false, options, true);
  else if (name == "simdyn-gl-fresh") ds = generate_simdyn(true, options, true);
  else {
    std::string list;
    for (const auto& n : scenario_names()) list += (list.empty() ? "" : ", ") + n;
    throw std::invalid_argument("unknown scenario '" + name + "' (known: " + list + ")");
  }
  ds.provenance["scenario"] = name;
  ds.provenance["seed"] = std::to_string(options.seed);
  ds.provenance["generator"] = "spml " SPML_VERSION;
  ds.provenance["reference"] = "Riedel & Stulp, Comparing Semi-Parametric Model Learning Algorithms for Dynamic Model Estimation in Robotics";
  return ds;
}

}  // namespace spml
