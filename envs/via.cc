// VIA joint (paper Sec. "Variable Impedance Actuator"): a position-controlled motor drives a
// link through a spring K and damper D in parallel; the link has stick-slip friction. The
// target is the link-side torque tau = K (theta - q) + D (theta_dot - q_dot) + friction,
// i.e. what a link-side torque sensor reads; the parametric model knows only {K, D}.
#include <random>

#include "signals.h"
#include "spml/envs/mujoco_model.h"
#include "spml/envs/scenarios.h"
#include "spml/envs/parametric_model.h"
#include "spml/force_effects.h"

namespace spml {
namespace {

constexpr double kDuration = 40.0;        // s; the chirp sweeps 0 -> 3 Hz over it
constexpr double kFadeOut = 4.0;          // s of cosine amplitude taper at the end
constexpr double kAmplitude = 0.3;        // rad, motor reference
constexpr double kMotorKp = 2000.0, kMotorKd = 20.0;
constexpr double kRecordRate = 1000.0;    // Hz, telemetry
constexpr int kResample = 10;             // 1 kHz -> 100 Hz
constexpr double kTrainFraction = 0.64;
constexpr int kHistory = 4;               // VIA-AR: four past samples, 10 ms apart
constexpr double kEncoderNoise = 1e-5;    // rad, uniform +-
constexpr double kTorqueNoise = 0.2;      // Nm, Gaussian std of the torque sensor

}  // namespace

Dataset generate_via(bool autoregressive, const GenerateOptions& options) {
  const std::string path = mjcf_path("via_joint.xml");
  ModelPtr m = load_mjcf(path);
  DataPtr d = make_data(m.get());
  ForceEffects effects(m.get(), path);
  effects.attach();
  const int motor = m->jnt_dofadr[mj_name2id(m.get(), mjOBJ_JOINT, "motor")];
  const int link = m->jnt_dofadr[mj_name2id(m.get(), mjOBJ_JOINT, "link")];
  const int tendon = mj_name2id(m.get(), mjOBJ_TENDON, "elastic");
  if (motor < 0 || link < 0 || tendon < 0) throw std::runtime_error(path + ": needs joints 'motor', 'link' and tendon 'elastic'");
  const double K = m->tendon_stiffness[tendon], D = m->tendon_damping[tendon];

  const double h = m->opt.timestep;
  const int sub = static_cast<int>(std::lround(1.0 / (kRecordRate * h)));
  const int records = static_cast<int>(kDuration * kRecordRate) + 2 * signals::kEdge;
  signals::Chirp chirp{0.0, 3.0, kDuration};
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> enc(-kEncoderNoise, kEncoderNoise);
  std::normal_distribution<double> torque_noise(0.0, kTorqueNoise);

  Eigen::MatrixXd defl(records, 1), tau(records, 1);
  std::vector<mjtNum> friction(m->nv);
  for (int r = 0; r < records; ++r) {
    for (int s = 0; s < sub; ++s) {
      double t = (r * sub + s) * h;
      double env = t > kDuration - kFadeOut ? 0.5 * (1 + std::cos(M_PI * (t - kDuration + kFadeOut) / kFadeOut)) : 1.0;
      if (t > kDuration) env = 0.0;
      double ref = kAmplitude * env * std::sin(chirp.phase(t));
      double ref_d = kAmplitude * env * 2 * M_PI * chirp.freq(t) * std::cos(chirp.phase(t));
      d->qfrc_applied[motor] = kMotorKp * (ref - d->qpos[motor]) + kMotorKd * (ref_d - d->qvel[motor]);
      if (s == 0) {
        // Sample the sensors at the start of each 1 ms period.
        std::fill(friction.begin(), friction.end(), 0.0);
        effects.compute(d.get(), friction.data());
        double delta = d->qpos[motor] - d->qpos[link], rate = d->qvel[motor] - d->qvel[link];
        tau(r, 0) = K * delta + D * rate + friction[link] + torque_noise(rng);
        defl(r, 0) = delta + enc(rng) - enc(rng);
      }
      step(m.get(), d.get(), effects);
    }
    if (options.progress && r % 10000 == 0) options.progress(autoregressive ? "via-ar" : "via-inst", double(r) / records);
  }
  effects.detach();

  const Eigen::MatrixXd rate = central_difference(defl.col(0), 1.0 / kRecordRate);
  // Drop the undifferentiable edges, then average blocks of 10 (1 kHz -> 100 Hz).
  const int e = signals::kEdge, kept = records - 2 * e;
  Eigen::MatrixXd raw(kept, 3);
  raw << defl.middleRows(e, kept), rate.middleRows(e, kept), tau.middleRows(e, kept);
  Eigen::MatrixXd slow = signals::block_average(raw, kResample);
  const Eigen::Index n = slow.rows() - kHistory;   // rows with a full history
  const int lags = autoregressive ? kHistory + 1 : 1;

  Split all;
  all.x_columns = {"deflection", "deflection_rate"};
  for (int l = 1; l < lags; ++l) {
    all.x_columns.push_back("deflection@-" + std::to_string(10 * l) + "ms");
    all.x_columns.push_back("deflection_rate@-" + std::to_string(10 * l) + "ms");
  }
  all.y_columns = {"tau:link"};
  all.X.resize(n, 2 * lags);
  all.Y.resize(n, 1);
  all.t.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    Eigen::Index k = i + kHistory;
    for (int l = 0; l < lags; ++l) {
      all.X(i, 2 * l) = slow(k - l, 0);
      all.X(i, 2 * l + 1) = slow(k - l, 1);
    }
    all.Y(i, 0) = slow(k, 2);
    all.t[i] = (k * kResample + 0.5 * (kResample - 1) + e) / kRecordRate;   // block centre
  }
  const Eigen::Index cut = static_cast<Eigen::Index>(std::lround(kTrainFraction * n));
  Dataset ds;
  ds.splits = {all.slice(0, cut, "train"), all.slice(cut, n, "test")};
  ds.model.name = "via";
  ds.model.param_names = {"K", "D"};
  ds.model.prior = Eigen::Vector2d(300.0, 20.0);   // the paper's starting guess
  ds.model.truth = Eigen::Vector2d(K, D);
  ds.model.mjcf_path = "mjcf/via_joint.xml";
  ds.provenance["scenario"] = autoregressive ? "via-ar" : "via-inst";
  ds.provenance["model_features"] = "tau = K*deflection + D*deflection_rate (current sample only)";
  ds.provenance["excitation"] = "motor PD (kp=2000, kd=20) on a 0.3 rad chirp 0->3 Hz over 40 s, 4 s fade-out";
  ds.provenance["sampling"] = "1 kHz telemetry, 10-sample block average to 100 Hz, split at 64 %";
  return ds;
}

namespace {
// The paper's VIA model tau = K * deflection + D * deflection_rate.
class ViaModel : public RowwiseModel {
 public:
  explicit ViaModel(const Split& s)
      : d_(require_column(s, "deflection", "via")), r_(require_column(s, "deflection_rate", "via")) {}
  std::string name() const override { return "via"; }
  Eigen::MatrixXd features(const Eigen::Ref<const Eigen::RowVectorXd>& x) const override {
    Eigen::MatrixXd phi(1, 2);
    phi << x[d_], x[r_];
    return phi;
  }
 private:
  int d_, r_;
};
const bool kViaRegistered = register_parametric_model("via", [](const Dataset& ds, const Split& s) {
  if (s.Y.cols() != 1) require_outputs(s, {"tau:link"}, "via");
  auto m = std::make_unique<ViaModel>(s);
  take_coefficients(*m, ds, 2, 1);
  return std::unique_ptr<ParametricModel>(std::move(m));
});
}  // namespace

}  // namespace spml
