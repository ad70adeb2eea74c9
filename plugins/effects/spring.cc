// spring: a linear spring per joint, force -k*q + f0 (MuJoCo's stiffness k with springref f0/k).
#include "spml/effect_base.h"

namespace spml::effects {

struct Spring {
  static constexpr const char* kName = "spring";
  static constexpr const char* kDescription = "linear spring -k*q + f0 per joint (stiffness k, springref f0/k); linear in k, f0";
  static constexpr spml_config_key kKeys[] = {
      {"k", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "stiffness per joint"},
      {"f0", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "force at q = 0 per joint (k times the rest position)"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr bool kLinear = true;

  explicit Spring(const EffectConfig& c) : joints(c.joints) {
    const auto k = c.per_joint("k"), f0 = c.per_joint("f0");
    for (size_t i = 0; i < joints.size(); ++i) {
      theta.push_back(k[i]);
      theta.push_back(f0[i]);
      names.push_back(joints[i].name + ".k");
      names.push_back(joints[i].name + ".f0");
    }
  }
  // Per joint [k, f0]: the force is k*(-q) + f0*1.
  void regressor(const mjModel*, const mjtNum* qpos, const mjtNum*, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (size_t i = 0; i < joints.size(); ++i) {
      const int dof = joints[i].dof, k = static_cast<int>(2 * i);
      R[dof * np + k] = -qpos[joints[i].qpos];
      R[dof * np + k + 1] = 1.0;
    }
  }
  std::string config() const { return "k=" + exact_list(every(theta, 0, 2)) + " f0=" + exact_list(every(theta, 1, 2)); }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::Spring)
