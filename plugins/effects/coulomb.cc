// coulomb: dry friction -fc * sign(qd) per joint (optionally tanh-smoothed over `smooth`).
#include "spml/effect_base.h"

namespace spml::effects {

struct Coulomb {
  static constexpr const char* kName = "coulomb";
  static constexpr const char* kDescription = "Coulomb friction -fc*sign(qd) per joint; linear in fc";
  static constexpr spml_config_key kKeys[] = {
      {"fc", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "Coulomb force per joint"},
      {"smooth", SPML_VALUE_NUMBER, 0, HUGE_VAL, "0", "tanh width in velocity units (0: exact sign)"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr bool kLinear = true;

  explicit Coulomb(const EffectConfig& c) : joints(c.joints), smooth(c.number("smooth", 0.0)) {
    require(smooth >= 0, "smooth must be >= 0");
    theta = c.per_joint("fc");
    for (auto& j : joints) names.push_back(j.name + ".fc");
  }
  void regressor(const mjModel* m, const mjtNum*, const mjtNum* qvel, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (int i = 0; i < np; ++i) R[joints[i].dof * np + i] = -smooth_sign(qvel[joints[i].dof], smooth);
    (void)m;
  }
  std::string config() const { return "fc=" + exact_list(theta) + " smooth=" + exact_text(smooth); }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  double smooth;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::Coulomb)
