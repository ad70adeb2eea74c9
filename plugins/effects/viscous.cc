// viscous: velocity-proportional friction -fv * qd per joint.
#include "spml/effect_base.h"

namespace spml::effects {

struct Viscous {
  static constexpr const char* kName = "viscous";
  static constexpr const char* kDescription = "viscous friction -fv*qd per joint; linear in fv";
  static constexpr spml_config_key kKeys[] = {
      {"fv", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "viscous coefficient per joint"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr bool kLinear = true;

  explicit Viscous(const EffectConfig& c) : joints(c.joints) {
    theta = c.per_joint("fv");
    for (auto& j : joints) names.push_back(j.name + ".fv");
  }
  void regressor(const mjModel*, const mjtNum*, const mjtNum* qvel, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (int i = 0; i < np; ++i) R[joints[i].dof * np + i] = -qvel[joints[i].dof];
  }
  std::string config() const { return "fv=" + exact_list(theta); }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::Viscous)
