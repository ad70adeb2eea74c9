// ripple: position-periodic torque sum_h a_h sin(h*gear*q + phi_h) per joint, the harmonic
// drive ripple model the paper borrows from Godler et al. (1999): harmonics h of the gear
// ratio. Written as s_h sin(h*gear*q) + c_h cos(h*gear*q) with s = a cos(phi), c = a sin(phi)
// it is linear in (s_h, c_h), which are the parameters exposed.
#include <algorithm>

#include "spml/effect_base.h"

namespace spml::effects {

struct Ripple {
  static constexpr const char* kName = "ripple";
  static constexpr const char* kDescription = "harmonic-drive ripple sum a*sin(h*gear*q+phase); linear in the sin/cos amplitudes";
  static constexpr spml_config_key kKeys[] = {
      {"gear", SPML_VALUE_NUMBER, 1e-12, HUGE_VAL, nullptr, "ripple periods per radian (gear ratio)"},
      {"harmonics", SPML_VALUE_NUMBERS, 1, 1000, nullptr, "harmonic orders, e.g. 1,2"},
      {"amplitudes", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "amplitude per harmonic (or per harmonic and joint)"},
      {"phases", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, "0", "phase per harmonic (or per harmonic and joint) [rad]"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr spml_shape_param kShape[] = {{"gear", SPML_SHAPE_ABSOLUTE, 1, 200, 0, 1}, {nullptr, 0, 0, 0, 0, 0}};
  static constexpr bool kLinear = true;

  // "8" for a whole order; "1p5" for 1.5 (exact digits, '.' separates the parts of a parameter
  // name): distinct orders give distinct names.
  static std::string harmonic_label(double h) {
    if (h == std::floor(h)) return std::to_string(static_cast<long long>(h));
    std::string t = exact_text(h);
    std::replace(t.begin(), t.end(), '.', 'p');
    return t;
  }

  explicit Ripple(const EffectConfig& c) : joints(c.joints), gear(c.number("gear")), harmonics(c.list("harmonics")) {
    require(gear > 0, "gear must be > 0");
    // One value per harmonic (shared by all joints), or one per harmonic and joint (joint-major).
    const size_t H = harmonics.size(), J = joints.size();
    auto per_joint_harmonic = [&](const std::string& key, double fallback) {
      std::vector<double> v = c.has(key) ? c.list(key) : std::vector<double>(H, fallback);
      if (v.size() == 1) v.assign(H, v[0]);
      require(v.size() == H || v.size() == H * J, "key '" + key + "': expected " + std::to_string(H) + " (one per harmonic) or " +
                                                   std::to_string(H * J) + " (per harmonic and joint) values, got " +
                                                   std::to_string(v.size()));
      if (v.size() == H) for (size_t j = 1; j < J; ++j) v.insert(v.end(), v.begin(), v.begin() + static_cast<long>(H));
      return v;
    };
    for (size_t h = 0; h < H; ++h)
      for (size_t k = 0; k < h; ++k)
        require(harmonics[k] != harmonics[h], "key 'harmonics': harmonic " + exact_text(harmonics[h]) + " given twice");
    auto amp = per_joint_harmonic("amplitudes", 0.0), phase = per_joint_harmonic("phases", 0.0);
    for (size_t j = 0; j < J; ++j)
      for (size_t h = 0; h < H; ++h) {
        std::string base = joints[j].name + ".h" + harmonic_label(harmonics[h]);
        theta.push_back(amp[j * H + h] * std::cos(phase[j * H + h]));
        names.push_back(base + ".sin");
        theta.push_back(amp[j * H + h] * std::sin(phase[j * H + h]));
        names.push_back(base + ".cos");
      }
  }
  // theta holds (a cos phi, a sin phi) pairs; written back as amplitudes and phases per joint.
  std::string config() const {
    std::vector<double> amp, phase;
    for (size_t i = 0; i + 1 < theta.size(); i += 2) {
      amp.push_back(std::hypot(theta[i], theta[i + 1]));
      phase.push_back(std::atan2(theta[i + 1], theta[i]));
    }
    return "gear=" + exact_text(gear) + " harmonics=" + exact_list(harmonics) + " amplitudes=" + exact_list(amp) +
           " phases=" + exact_list(phase);
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
