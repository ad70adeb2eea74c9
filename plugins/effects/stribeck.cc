// stribeck: -(fc + (fs - fc) exp(-(qd/vs)^2)) sign(qd) per joint. With the Stribeck
// velocity vs fixed (a structural constant), the force is linear in (fc, fs).
#include "effect_base.h"

namespace spml::effects {

struct Stribeck {
  static constexpr const char* kName = "stribeck";
  static constexpr const char* kDescription = "Stribeck friction, static fs decaying to Coulomb fc over vs; linear in fc, fs";
  static constexpr const char* kKeys[] = {"fc", "fs", "vs", "smooth", nullptr};
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
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  std::vector<double> vs;
  double smooth;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::Stribeck)
