// friction_band: extra dry friction -level * sign(qd) acting only while the joint position
// lies in [lower, upper] - a local defect such as a damaged bearing race or a tight spot in a
// gear (the paper's SimDyn-Ll mismatch). Linear in `level` for a fixed interval.
#include "spml/effect_base.h"

namespace spml::effects {

struct FrictionBand {
  static constexpr const char* kName = "friction_band";
  static constexpr const char* kDescription = "dry friction of size level inside lower <= q <= upper; linear in level";
  static constexpr spml_config_key kKeys[] = {
      {"lower", SPML_VALUE_NUMBER, -HUGE_VAL, HUGE_VAL, nullptr, "lower edge of the band (joint position)"},
      {"upper", SPML_VALUE_NUMBER, -HUGE_VAL, HUGE_VAL, nullptr, "upper edge of the band (joint position)"},
      {"level", SPML_VALUE_NUMBERS, -HUGE_VAL, HUGE_VAL, nullptr, "friction level inside the band, per joint"},
      {"smooth", SPML_VALUE_NUMBER, 0, HUGE_VAL, "0", "tanh width in velocity units (0: exact sign)"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr spml_shape_param kShape[] = {
      {"lower", SPML_SHAPE_POSITION, 0.0, 1.0, 0, 0}, {"upper", SPML_SHAPE_POSITION, 0.0, 1.0, 0, 0}, {nullptr, 0, 0, 0, 0, 0}};
  static constexpr bool kLinear = true;

  explicit FrictionBand(const EffectConfig& c)
      : joints(c.joints), lower(c.number("lower")), upper(c.number("upper")), smooth(c.number("smooth", 0.0)) {
    require(lower < upper, "lower (" + std::to_string(lower) + ") must be below upper (" + std::to_string(upper) + ")");
    require(smooth >= 0, "smooth must be >= 0");
    auto level = c.per_joint("level");
    for (size_t i = 0; i < joints.size(); ++i) {
      require(level[i] >= 0, "level must be >= 0");
      theta.push_back(level[i]);
      names.push_back(joints[i].name + ".level");
    }
  }
  bool inside(double q) const { return q >= lower && q <= upper; }
  void regressor(const mjModel*, const mjtNum* qpos, const mjtNum* qvel, mjtNum* R) const {
    const int np = static_cast<int>(theta.size());
    for (size_t i = 0; i < joints.size(); ++i)
      if (inside(qpos[joints[i].qpos])) R[joints[i].dof * np + i] = -smooth_sign(qvel[joints[i].dof], smooth);
  }
  std::string config() const {
    return "lower=" + exact_text(lower) + " upper=" + exact_text(upper) + " level=" + exact_list(theta) + " smooth=" + exact_text(smooth);
  }
  void compute(const mjModel* m, const mjData* d, mjtNum* qfrc) const { compute_linear(*this, m, d, qfrc); }

  std::vector<Joint> joints;
  double lower, upper, smooth;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::FrictionBand)
