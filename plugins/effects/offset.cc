// offset: a constant generalized force per joint (sensor bias, cable or spring preload).
#include "spml/effect_base.h"

namespace spml::effects {

struct Offset {
  static constexpr const char* kName = "offset";
  static constexpr const char* kDescription = "constant force/torque c per joint; linear in c";
  static constexpr spml_config_key kKeys[] = {
      {"c", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "constant force per joint"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr bool kLinear = true;

  explicit Offset(const EffectConfig& c) : joints(c.joints) {
    theta = c.per_joint("c");
    for (auto& j : joints) names.push_back(j.name + ".c");
  }
  void regressor(const mjModel*, const mjtNum*, const mjtNum*, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (int i = 0; i < np; ++i) R[joints[i].dof * np + i] = 1.0;
  }
  std::string config() const { return "c=" + exact_list(theta); }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::Offset)
