// SimDyn (paper Sec. "Simulated Robot Dynamics"): the planar 3R arm under computed-torque
// control with the prior model, following two sums of sines around a joint-0 offset of 0
// (train + interpolation test) or 0.3 rad (extrapolation test). The mismatch comes from the
// force plugins declared in mjcf/planar_arm3_{ll,gl}.xml.
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

#include "plugin_text.h"
#include "signals.h"
#include "spml/envs/mujoco_model.h"
#include "spml/envs/planar_arm3.h"
#include "spml/envs/scenarios.h"
#include "spml/force_effects.h"

namespace spml {
namespace {

constexpr double kKp = 3947.8, kKd = 125.7;            // paper's gains
constexpr double kAmp[3] = {0.4, 0.2, 0.3};
constexpr double kF1[3] = {0.28, 0.52, 0.26}, kF2[3] = {1.1, 2.3, 2.2};
constexpr double kDuration = 100.0;                     // s per roll-out
constexpr double kNoise = 1e-6;                         // position noise, uniform +-[rad]
constexpr int kTrainStride = 10;                        // 1 kHz -> 100 Hz

// Every frequency is a multiple of 0.02 Hz, so the reference repeats every 50 s: the
// paper's interpolation test (the second 50 s) retraces the training trajectory. The
// "-fresh" scenarios shift the phases instead, for a new path through the same region.
constexpr double kFreshPhase1[3] = {1.3, 2.1, 0.7}, kFreshPhase2[3] = {0.4, 2.9, 1.8};   // rad

struct Reference {
  double offset0;
  bool fresh = false;
  void at(double t, double* q, double* qd, double* qdd) const {
    for (int i = 0; i < 3; ++i) {
      const double w1 = 2 * M_PI * kF1[i], w2 = 2 * M_PI * kF2[i], a = kAmp[i];
      const double p1 = fresh ? kFreshPhase1[i] : 0.0, p2 = fresh ? kFreshPhase2[i] : 0.0;
      q[i] = a * std::sin(w1 * t + p1) + a / 3 * std::sin(w2 * t + p2) + (i == 0 ? offset0 : 0.0);
      qd[i] = a * w1 * std::cos(w1 * t + p1) + a / 3 * w2 * std::cos(w2 * t + p2);
      qdd[i] = -a * w1 * w1 * std::sin(w1 * t + p1) - a / 3 * w2 * w2 * std::sin(w2 * t + p2);
    }
  }
};

struct Rollout {
  Eigen::MatrixXd q, qd, qdd, tau;   // measured q, differentiated qd/qdd, commanded tau
  Eigen::VectorXd t;
};

Rollout simulate(const mjModel* sim, ForceEffects& effects, const mjModel* prior, Reference ref,
                 std::mt19937_64& rng, const GenerateOptions& options, const std::string& stage) {
  const double h = sim->opt.timestep;
  const int steps = static_cast<int>(std::lround(kDuration / h));
  const int n = steps + 2 * signals::kEdge;   // extra samples each side for the differences
  DataPtr d = make_data(sim), dc = make_data(prior);
  double qr[3], qdr[3], qddr[3];
  // Start on the reference so the controller has no transient to catch up.
  ref.at(-signals::kEdge * h, qr, qdr, qddr);
  for (int i = 0; i < 3; ++i) { d->qpos[i] = qr[i]; d->qvel[i] = qdr[i]; }
  effects.reset();
  std::uniform_real_distribution<double> noise(-kNoise, kNoise);
  Eigen::MatrixXd qm(n, 3), tau(n, 3);
  Eigen::VectorXd t(n);
  for (int k = 0; k < n; ++k) {
    double time = (k - signals::kEdge) * h;
    ref.at(time, qr, qdr, qddr);
    // Computed-torque control with the prior model (mj_inverse on the prior MJCF), on the
    // simulator's state; the sensor noise only enters the recorded data.
    for (int i = 0; i < 3; ++i) {
      dc->qpos[i] = d->qpos[i];
      dc->qvel[i] = d->qvel[i];
      dc->qacc[i] = qddr[i] + kKp * (qr[i] - d->qpos[i]) + kKd * (qdr[i] - d->qvel[i]);
    }
    mj_inverse(prior, dc.get());
    for (int i = 0; i < 3; ++i) {
      tau(k, i) = dc->qfrc_inverse[i];
      qm(k, i) = d->qpos[i] + noise(rng);
      d->qfrc_applied[i] = tau(k, i);
    }
    t[k] = time;
    step(sim, d.get(), effects);
    if (options.progress && k % 20000 == 0) options.progress(stage, static_cast<double>(k) / n);
  }
  Rollout r;
  Eigen::MatrixXd qd(qm.rows(), qm.cols()), qdd(qm.rows(), qm.cols());
  for (Eigen::Index j = 0; j < qm.cols(); ++j) {
    qd.col(j) = central_difference(qm.col(j), h);
    qdd.col(j) = central_difference(qd.col(j), h);
  }
  // Drop the edge samples that have no full difference stencil.
  const int e = signals::kEdge;
  r.q = qm.middleRows(e, steps);
  r.qd = qd.middleRows(e, steps);
  r.qdd = qdd.middleRows(e, steps);
  r.tau = tau.middleRows(e, steps);
  r.t = t.segment(e, steps);
  return r;
}

Split make_split(const std::string& name, const Rollout& r, Eigen::Index begin, Eigen::Index end, int stride,
                 const std::vector<std::string>& joints) {
  Split s;
  s.name = name;
  for (const char* kind : {"q:", "qd:", "qdd:"})
    for (const auto& j : joints) s.x_columns.push_back(kind + j);
  for (const auto& j : joints) s.y_columns.push_back("tau:" + j);
  const Eigen::Index n = (end - begin + stride - 1) / stride;
  s.X.resize(n, 9);
  s.Y.resize(n, 3);
  s.t.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    Eigen::Index k = begin + i * stride;
    s.X.row(i) << r.q.row(k), r.qd.row(k), r.qdd.row(k);
    s.Y.row(i) = r.tau.row(k);
    s.t[i] = r.t[k];
  }
  return s;
}

// The dataset's columns are q:/qd:/qdd:/tau:<joint>: every joint of the arm needs a name and
// one degree of freedom (mj_id2name gives NULL for an unnamed joint).
std::string named_joint(const mjModel* m, int j, const std::string& file) {
  static const char* const kTypes[] = {"free", "ball", "slide", "hinge"};
  const int type = m->jnt_type[j];
  const std::string kind = type >= 0 && type < 4 ? kTypes[type] : "type " + std::to_string(type);
  const char* name = mj_id2name(m, mjOBJ_JOINT, j);
  if (type != mjJNT_HINGE && type != mjJNT_SLIDE)
    throw std::runtime_error(file + ": joint " + std::to_string(j) + (name ? " '" + std::string(name) + "'" : "") + " (" +
                             kind + ") is not a hinge or slide joint; the SimDyn arm needs one per link");
  if (!name || !*name)
    throw std::runtime_error(file + ": joint " + std::to_string(j) + " (" + kind +
                             ") has no name; the dataset's columns are named after the joints");
  return name;
}

}  // namespace

Dataset generate_simdyn(bool global_mismatch, const GenerateOptions& options, bool fresh_interp) {
  const std::string file = global_mismatch ? "planar_arm3_gl.xml" : "planar_arm3_ll.xml";
  const std::string path = mjcf_path(file);
  ModelPtr sim = load_mjcf(path);
  ModelPtr truth = load_mjcf(mjcf_path("planar_arm3.xml"));
  ModelPtr prior = load_mjcf(mjcf_path("planar_arm3_prior.xml"));
  std::vector<std::string> joints;
  for (int j = 0; j < sim->njnt; ++j) joints.push_back(named_joint(sim.get(), j, path));
  ForceEffects effects(sim.get(), path);
  effects.attach();

  std::mt19937_64 rng(options.seed);
  const std::string label = std::string(global_mismatch ? "simdyn-gl" : "simdyn-ll") + (fresh_interp ? "-fresh" : "");
  Rollout base = simulate(sim.get(), effects, prior.get(), Reference{0.0}, rng, options, label + " offset 0.0");
  Rollout shifted = simulate(sim.get(), effects, prior.get(), Reference{0.3}, rng, options, label + " offset 0.3");
  Rollout fresh;
  if (fresh_interp) fresh = simulate(sim.get(), effects, prior.get(), Reference{0.0, true}, rng, options, label + " new phases");
  effects.detach();

  const Eigen::Index half = base.q.rows() / 2;   // 50 s
  const int ts = std::max(1, options.test_stride);
  Dataset ds;
  ds.splits.push_back(make_split("train", base, 0, half, kTrainStride, joints));
  const Rollout& interp = fresh_interp ? fresh : base;
  ds.splits.push_back(make_split("test_interp", interp, half, interp.q.rows(), ts, joints));
  ds.splits.push_back(make_split("test_extrap", shifted, half, shifted.q.rows(), ts, joints));

  ds.model.name = "planar_arm3";
  ds.model.param_names = planar_arm3::param_names();
  ds.model.prior = planar_arm3::coefficients(prior.get());
  ds.model.truth = planar_arm3::coefficients(truth.get());
  ds.model.mjcf_path = "mjcf/" + file;
  ds.provenance["scenario"] = label;
  ds.provenance["plugins"] = declarations_text(effects);
  ds.provenance["controller"] = "computed torque with mjcf/planar_arm3_prior.xml, kp=3947.8 kd=125.7, 1 kHz";
  ds.provenance["sensor"] = "q + uniform(+-1e-6 rad); qd, qdd by central differences applied twice at 1 kHz";
  ds.provenance["sampling"] = std::string("train: first 50 s of offset 0 every 10th sample (100 Hz); test_interp: last 50 s of ") +
                              (fresh_interp ? "offset 0 with new phases (a new path through the training region)"
                                            : "offset 0 (retraces the training path: the reference repeats every 50 s)") +
                              "; test_extrap: last 50 s of offset 0.3; test stride " + std::to_string(ts);
  return ds;
}

}  // namespace spml
