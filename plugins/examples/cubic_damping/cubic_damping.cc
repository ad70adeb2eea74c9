// An out-of-tree force plugin: cubic damping -c * qd^3 per joint (a viscous seal or a fluid
// damper whose drag grows with the square of the speed). Linear in c, so it exposes its
// regressor and `spml diagnose` can try it as a cause on every joint.
//
// Built against an installed (or exported) spml package, like learners/examples/ridge:
//   cmake -S . -B build -DCMAKE_PREFIX_PATH=<spml prefix>   (or -Dspml_DIR=<spml build>)
//   cmake --build build
//   spml plugins --plugin-path build/spml_force_cubic_damping.so
#include "spml/effect_base.h"

namespace example {

struct CubicDamping {
  static constexpr const char* kName = "cubic_damping";
  static constexpr const char* kDescription = "cubic damping -c*qd^3 per joint; linear in c";
  static constexpr spml_config_key kKeys[] = {
      {"c", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "cubic damping coefficient per joint"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr bool kLinear = true;

  explicit CubicDamping(const spml::effects::EffectConfig& config) : joints(config.joints) {
    theta = config.per_joint("c");
    for (auto& j : joints) names.push_back(j.name + ".c");
  }
  // R arrives zeroed (force_plugin.h): only this instance's joints are written.
  void regressor(const mjModel*, const mjtNum*, const mjtNum* qvel, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (int i = 0; i < np; ++i) {
      const mjtNum v = qvel[joints[i].dof];
      R[joints[i].dof * np + i] = -v * v * v;
    }
  }
  std::string config() const { return "c=" + spml::effects::exact_list(theta); }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const {
    spml::effects::compute_linear(*this, m, d, qfrc);
  }

  std::vector<spml::effects::Joint> joints;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace example
SPML_EXPORT_FORCE_PLUGIN(example::CubicDamping)
