// stick_slip: LuGre dry friction (Canudas de Wit et al., 1995), a bristle model with one
// internal state z per joint. It sticks for real: below the break-away force fs the joint
// only deflects the bristles (about F/sigma0) and comes to rest; above it, it slips with the
// Stribeck curve g(v) = fc + (fs - fc) exp(-(v/vs)^2) plus viscous sigma2*v.
//   dz/dt = v - sigma0 |v| z / g(v),   F = sigma0 z + sigma1 dz/dt + sigma2 v,   force = -F.
// Not linear in its parameters, so it has no regressor columns.
#include "spml/effect_base.h"

namespace spml::effects {

struct StickSlip {
  static constexpr const char* kName = "stick_slip";
  static constexpr const char* kDescription = "LuGre stick-slip friction with break-away force fs (stateful, nonlinear)";
  static constexpr spml_config_key kKeys[] = {
      {"fc", SPML_VALUE_NUMBERS, 0, HUGE_VAL, nullptr, "Coulomb level"},
      {"fs", SPML_VALUE_NUMBERS, 0, HUGE_VAL, nullptr, "break-away force"},
      {"vs", SPML_VALUE_NUMBERS, 0, HUGE_VAL, nullptr, "Stribeck velocity"},
      {"sigma0", SPML_VALUE_NUMBERS, 0, HUGE_VAL, nullptr, "bristle stiffness"},
      {"sigma1", SPML_VALUE_NUMBERS, 0, HUGE_VAL, nullptr, "bristle damping"},
      {"sigma2", SPML_VALUE_NUMBERS, 0, HUGE_VAL, nullptr, "viscous coefficient"},
      {nullptr, 0, 0, 0, nullptr, nullptr}};
  static constexpr bool kStateful = true;
  // Searched when diagnose fits it by simulation: the Stribeck speed as a fraction of the top
  // speed, the bristle stiffness and damping absolute (fc, fs, sigma2 are levels it scales).
  // sigma1 up to 1e4: LuGre's textbook bristles are sigma0 1e5, sigma1 sqrt(1e5) = 316
  // (Canudas de Wit et al. 1995), which a range ending at 1e2 left to `coulomb` on a slide.
  static constexpr spml_shape_param kShape[] = {{"vs", SPML_SHAPE_SPEED, 0.005, 0.5, 1, 0},
                                                {"sigma0", SPML_SHAPE_ABSOLUTE, 10, 1e6, 1, 0},
                                                {"sigma1", SPML_SHAPE_ABSOLUTE, 1e-3, 1e4, 1, 0},
                                                {nullptr, 0, 0, 0, 0, 0}};

  explicit StickSlip(const EffectConfig& c) : joints(c.joints), z(c.joints.size(), 0.0) {
    const char* keys[] = {"fc", "fs", "vs", "sigma0", "sigma1", "sigma2"};
    std::vector<std::vector<double>> v;
    for (const char* k : keys) v.push_back(c.per_joint(k));
    for (size_t i = 0; i < joints.size(); ++i) {
      require(v[0][i] > 0 && v[1][i] >= v[0][i], "need 0 < fc <= fs");
      require(v[2][i] > 0 && v[3][i] > 0 && v[4][i] >= 0 && v[5][i] >= 0, "need vs, sigma0 > 0 and sigma1, sigma2 >= 0");
      for (size_t k = 0; k < 6; ++k) {
        theta.push_back(v[k][i]);
        names.push_back(joints[i].name + "." + keys[k]);
      }
    }
  }
  const double* p(size_t i) const { return &theta[6 * i]; }   // fc fs vs sigma0 sigma1 sigma2
  double g(size_t i, double v) const {
    const double* q = p(i);
    // Far beyond vs the hump is exactly 0 in double precision (exp(-746) underflows to 0):
    // no exp there, the same force (diagnose integrates this along whole logs thousands of times).
    const double a = (v / q[2]) * (v / q[2]);
    return a > 746 ? q[0] : q[0] + (q[1] - q[0]) * std::exp(-a);
  }
  std::string config() const {
    static const char* keys[] = {"fc", "fs", "vs", "sigma0", "sigma1", "sigma2"};
    std::string out;
    for (size_t k = 0; k < 6; ++k) out += std::string(k ? " " : "") + keys[k] + "=" + exact_list(every(theta, k, 6));
    return out;
  }
  void compute(const mjModel*, const mjData* d, mjtNum* qfrc) const {
    for (size_t i = 0; i < joints.size(); ++i) {
      const double* q = p(i);
      double v = d->qvel[joints[i].dof];
      double zdot = v - q[3] * std::fabs(v) * z[i] / g(i, v);
      qfrc[joints[i].dof] -= q[3] * z[i] + q[4] * zdot + q[5] * v;
    }
  }
  // Exact update of the bristle ODE with v held over the step: unconditionally stable even
  // for the stiff sigma0 that a real stick phase needs.
  void advance(const mjModel*, const mjData* d, mjtNum dt) {
    for (size_t i = 0; i < joints.size(); ++i) {
      double v = d->qvel[joints[i].dof];
      if (v == 0) continue;
      double gi = g(i, v), rate = p(i)[3] * std::fabs(v) / gi, zss = v / rate;
      z[i] = zss + (z[i] - zss) * std::exp(-rate * dt);
    }
  }
  void reset() { std::fill(z.begin(), z.end(), 0.0); }

  std::vector<Joint> joints;
  std::vector<double> z;
  std::vector<std::string> names;
  std::vector<double> theta;
};

}  // namespace spml::effects
SPML_EXPORT_FORCE_PLUGIN(spml::effects::StickSlip)
