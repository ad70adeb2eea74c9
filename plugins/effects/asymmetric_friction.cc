// asymmetric_friction: Coulomb and viscous friction with their own levels for each direction
// of motion, as a worn ball screw or a preloaded gear shows (e.g. the EMPS benchmark's
// extended model, Janot et al. 2019). Per joint:
//   qd > 0:  -fc_pos - fv_pos * qd        qd < 0:  +fc_neg - fv_neg * qd        qd = 0: 0
// Linear in (fc_pos, fc_neg, fv_pos, fv_neg), which are the parameters exposed.
#include "spml/effect_base.h"

namespace spml::effects {

struct AsymmetricFriction {
  static constexpr const char* kName = "asymmetric_friction";
  static constexpr const char* kDescription =
      "direction-dependent Coulomb and viscous friction (fc_pos, fc_neg, fv_pos, fv_neg); linear";
  static constexpr spml_config_key kKeys[] = {
      {"fc_pos", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "Coulomb level moving forward, per joint"},
      {"fc_neg", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "Coulomb level moving backward, per joint"},
      {"fv_pos", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, "0", "viscous coefficient moving forward, per joint"},
      {"fv_neg", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, "0", "viscous coefficient moving backward, per joint"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr bool kLinear = true;

  explicit AsymmetricFriction(const EffectConfig& c) : joints(c.joints) {
    const char* keys[] = {"fc_pos", "fc_neg", "fv_pos", "fv_neg"};
    std::vector<std::vector<double>> v;
    for (const char* k : keys) v.push_back(c.per_joint(k));
    for (size_t i = 0; i < joints.size(); ++i)
      for (size_t k = 0; k < 4; ++k) {
        theta.push_back(v[k][i]);
        names.push_back(joints[i].name + "." + keys[k]);
      }
  }
  void regressor(const mjModel*, const mjtNum*, const mjtNum* qvel, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (size_t i = 0; i < joints.size(); ++i) {
      const double v = qvel[joints[i].dof];
      mjtNum* row = R + joints[i].dof * np + 4 * static_cast<int>(i);
      if (v > 0) row[0] = -1.0, row[2] = -v;
      if (v < 0) row[1] = 1.0, row[3] = -v;
    }
  }
  std::string config() const {
    return "fc_pos=" + exact_list(every(theta, 0, 4)) + " fc_neg=" + exact_list(every(theta, 1, 4)) +
           " fv_pos=" + exact_list(every(theta, 2, 4)) + " fv_neg=" + exact_list(every(theta, 3, 4));
  }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::AsymmetricFriction)
