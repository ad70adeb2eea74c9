// stribeck: -(fc + (fs - fc) exp(-(qd/vs)^2)) sign(qd) per joint. With the Stribeck
// velocity vs fixed (a structural constant), the force is linear in (fc, fs).
#include "spml/effect_base.h"

namespace spml::effects {

struct Stribeck {
  static constexpr const char* kName = "stribeck";
  static constexpr const char* kDescription = "Stribeck friction, static fs decaying to Coulomb fc over vs; linear in fc, fs";
  static constexpr spml_config_key kKeys[] = {
      {"fc", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "Coulomb level per joint"},
      {"fs", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "static (break-away) level per joint"},
      {"vs", SPML_VALUE_NUMBERS, 1e-12, HUGE_VAL, nullptr, "Stribeck velocity per joint"},
      {"smooth", SPML_VALUE_NUMBER, 0, HUGE_VAL, "0", "tanh width in velocity units (0: exact sign)"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr spml_shape_param kShape[] = {{"vs", SPML_SHAPE_SPEED, 0.005, 0.5, 1, 0}, {nullptr, 0, 0, 0, 0, 0}};
  static constexpr bool kLinear = true;

  explicit Stribeck(const EffectConfig& c) : joints(c.joints), vs(c.per_joint("vs")), smooth(c.number("smooth", 0.0)) {
    auto fc = c.per_joint("fc"), fs = c.per_joint("fs");
    for (size_t i = 0; i < joints.size(); ++i) {
      require(vs[i] > 0, "vs must be > 0");
      theta.push_back(fc[i]);
      theta.push_back(fs[i]);
      names.push_back(joints[i].name + ".fc");
      names.push_back(joints[i].name + ".fs");
    }
    require(smooth >= 0, "smooth must be >= 0");
  }
  void regressor(const mjModel*, const mjtNum*, const mjtNum* qvel, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (size_t i = 0; i < joints.size(); ++i) {
      double v = qvel[joints[i].dof], s = smooth_sign(v, smooth), e = std::exp(-(v / vs[i]) * (v / vs[i]));
      R[joints[i].dof * np + 2 * i] = -s * (1.0 - e);
      R[joints[i].dof * np + 2 * i + 1] = -s * e;
    }
  }
  std::string config() const {
    return "fc=" + exact_list(every(theta, 0, 2)) + " fs=" + exact_list(every(theta, 1, 2)) + " vs=" + exact_list(vs) +
           " smooth=" + exact_text(smooth);
  }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  std::vector<double> vs;
  double smooth;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::Stribeck)
