// ripple: position-periodic torque sum_h a_h sin(h*gear*q + phi_h) per joint, the harmonic
// drive ripple model the paper borrows from Godler et al. (1999): harmonics h of the gear
// ratio. Written as s_h sin(h*gear*q) + c_h cos(h*gear*q) with s = a cos(phi), c = a sin(phi)
// it is linear in (s_h, c_h), which are the parameters exposed.
#include "effect_base.h"

namespace spml::effects {

struct Ripple {
  static constexpr const char* kName = "ripple";
  static constexpr const char* kDescription = "harmonic-drive ripple sum a*sin(h*gear*q+phase); linear in the sin/cos amplitudes";
  static constexpr spml_config_key kKeys[] = {
      {"gear", SPML_VALUE_NUMBER, 1e-12, HUGE_VAL, nullptr, "ripple periods per radian (gear ratio)"},
      {"harmonics", SPML_VALUE_NUMBERS, 1, 1000, nullptr, "harmonic orders, e.g. 1,2"},
      {"amplitudes", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "amplitude per harmonic"},
      {"phases", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, "0", "phase per harmonic [rad]"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr spml_shape_param kShape[] = {{"gear", SPML_SHAPE_ABSOLUTE, 1, 200, 0, 1}, {nullptr, 0, 0, 0, 0, 0}};
  static constexpr bool kLinear = true;

  explicit Ripple(const EffectConfig& c) : joints(c.joints), gear(c.number("gear")), harmonics(c.list("harmonics")) {
    require(gear > 0, "gear must be > 0");
    auto amp = c.list("amplitudes", harmonics.size());
    auto phase = c.has("phases") ? c.list("phases", harmonics.size()) : std::vector<double>(harmonics.size(), 0.0);
    for (auto& j : joints)
      for (size_t h = 0; h < harmonics.size(); ++h) {
        std::string base = j.name + ".h" + std::to_string(static_cast<long>(harmonics[h]));
        theta.push_back(amp[h] * std::cos(phase[h]));
        names.push_back(base + ".sin");
        theta.push_back(amp[h] * std::sin(phase[h]));
        names.push_back(base + ".cos");
      }
  }
  void regressor(const mjModel*, const mjtNum* qpos, const mjtNum*, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    int k = 0;
    for (auto& j : joints)
      for (double h : harmonics) {
        double arg = h * gear * qpos[j.qpos];
        R[j.dof * np + k++] = std::sin(arg);
        R[j.dof * np + k++] = std::cos(arg);
      }
  }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  double gear;
  std::vector<double> harmonics;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::Ripple)
