// Forward simulation of a user's MJCF under a joint controller, recorded as a real logger
// would: the controller and logger run at `rate`; MuJoCo integrates with a step that divides
// the controller period; the logger samples positions at jittered instants (linear
// interpolation between integration steps, far below an encoder count) and reads the torque
// command held over that instant (zero-order hold), then quantizes and adds noise.
#include "spml/envs/measured_run.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>

#include "plugin_text.h"
#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"
#include "spml/matrix_file.h"
#include "spml/signal.h"

namespace spml {
namespace {

// What the integrator recorded: every sub-step's time and qpos, every tick's exact state.
struct Trace {
  std::vector<double> time;
  std::vector<Eigen::VectorXd> qpos;
};

void check_options(const MeasurementOptions& o) {
  auto bad = [](const std::string& what) { throw std::runtime_error("generate: " + what); };
  if (!(o.duration > 0)) bad("duration must be > 0 s");
  if (!(o.rate > 0)) bad("rate must be > 0 Hz");
  if (o.controller != "pd" && o.controller != "torque") bad("controller '" + o.controller + "': choose pd or torque");
  if (!(o.bandwidth > 0 && o.bandwidth < 0.1 * o.rate)) bad("PD bandwidth must lie in (0, rate / 10)");
  if (!(o.torque_noise >= 0)) bad("torque noise must be >= 0");
  if (o.encoder_bits < 0 || o.encoder_bits > 40) bad("encoder bits must lie in [0, 40] (0: no quantization)");
  if (!(o.jitter >= 0)) bad("jitter must be >= 0 s");
}

// One controller tick (after mj_step1, so qM and qfrc_bias belong to this state). PD (w > 0):
// tau = bias + M(q) (w^2 (q_ref - q) + 2 w (qd_ref - qd)), the PD error scaled by the inertia
// matrix so every joint is critically damped at bandwidth w whatever the coupling (a diagonal
// gain on a strongly coupled chain rings and goes unstable). Open loop (w = 0): tau = M(q) qdd_ref.
void control(const mjModel* m, mjData* d, const ReferenceTrack& ref, Eigen::Index k, double w, Eigen::VectorXd& acc,
             Eigen::VectorXd& tau, MeasuredRun& run) {
  for (int j = 0; j < m->njnt; ++j) {
    const int a = m->jnt_qposadr[j], v = m->jnt_dofadr[j];
    acc[v] = w > 0 ? w * w * (ref.q(k, j) - d->qpos[a]) + 2 * w * (ref.qd(k, j) - d->qvel[v]) : ref.qdd(k, j);
    run.tick_qpos(k, j) = d->qpos[a];
    run.tick_qvel(k, j) = d->qvel[v];
  }
  mj_mulM(m, d, tau.data(), acc.data());
  for (int j = 0; j < m->njnt; ++j) {
    const int v = m->jnt_dofadr[j];
    if (w > 0) tau[v] += d->qfrc_bias[v];
    run.tick_tau(k, j) = tau[v];
    d->qfrc_applied[v] = tau[v];
  }
}

// Runs the closed (or open) loop over `ticks` controller periods of `substeps` steps each.
void run_loop(const mjModel* m, mjData* d, ForceEffects& fx, const ReferenceTrack& ref, const MeasurementOptions& o,
              int substeps, MeasuredRun& run, Trace& trace) {
  const int nj = m->njnt;
  const Eigen::Index ticks = ref.q.rows();
  const double h = m->opt.timestep;
  for (int j = 0; j < nj; ++j) d->qpos[m->jnt_qposadr[j]] = ref.q(0, j), d->qvel[m->jnt_dofadr[j]] = ref.qd(0, j);
  mj_forward(m, d);
  const double w = 2 * M_PI * o.bandwidth;
  Eigen::VectorXd acc(m->nv), tau(m->nv);
  for (auto* M : {&run.tick_qpos, &run.tick_qvel, &run.tick_qacc, &run.tick_tau}) M->resize(ticks, nj);
  for (Eigen::Index k = 0; k < ticks; ++k) {
    for (int s = 0; s < substeps; ++s) {
      mj_step1(m, d);   // positions and velocities: bias forces for this state
      if (s == 0) control(m, d, ref, k, o.controller == "pd" ? w : 0.0, acc, tau, run);
      trace.time.push_back(d->time);
      trace.qpos.push_back(Eigen::Map<const Eigen::VectorXd>(d->qpos, m->nq));
      mj_step2(m, d);
      fx.advance(d, h);
      if (s == 0)
        for (int j = 0; j < nj; ++j) run.tick_qacc(k, j) = d->qacc[m->jnt_dofadr[j]];
      // MuJoCo resets the state when the acceleration blows up; a run must not hide that.
      if (d->warning[mjWARN_BADQACC].number > 0)
        throw std::runtime_error("generate: the simulation went unstable at t = " + std::to_string(d->time) +
                                 " s; lower --bandwidth or the model's timestep");
    }
  }
  trace.time.push_back(d->time);
  trace.qpos.push_back(Eigen::Map<const Eigen::VectorXd>(d->qpos, m->nq));
}

// The logger: jittered instants, interpolated positions, held torques, quantization, noise.
void sample(const mjModel* m, const Trace& trace, const MeasurementOptions& o, MeasuredRun& run) {
  const double T = 1.0 / o.rate;
  const auto N = static_cast<Eigen::Index>(std::llround(o.duration * o.rate));
  const int nj = m->njnt;
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> unit(0, 1);
  run.t.resize(N);
  for (Eigen::Index i = 0; i < N; ++i)
    run.t[i] = static_cast<double>(i + 1) * T + std::clamp(o.jitter * unit(rng), -0.45 * T, 0.45 * T);
  const Eigen::VectorXd times = Eigen::Map<const Eigen::VectorXd>(trace.time.data(), static_cast<Eigen::Index>(trace.time.size()));
  Eigen::VectorXd col(times.size());
  run.q_true.resize(N, nj);
  run.tau_true.resize(N, nj);
  for (int j = 0; j < nj; ++j) {
    for (Eigen::Index k = 0; k < times.size(); ++k) col[k] = trace.qpos[static_cast<size_t>(k)][m->jnt_qposadr[j]];
    run.q_true.col(j) = interpolate(times, col, run.t);
  }
  for (Eigen::Index i = 0; i < N; ++i) {
    const auto tick = std::min<Eigen::Index>(static_cast<Eigen::Index>(std::floor(run.t[i] / T + 1e-9)), run.tick_tau.rows() - 1);
    run.tau_true.row(i) = run.tick_tau.row(tick);
  }
  run.rms = (run.tau_true.array().square().colwise().mean()).sqrt().transpose();
  run.q = run.q_true;
  for (int j = 0; j < nj && o.encoder_bits > 0; ++j) {
    const double count = (m->jnt_type[j] == mjJNT_HINGE ? 2 * M_PI : 1.0) / std::ldexp(1.0, o.encoder_bits);
    run.q.col(j) = (run.q_true.col(j) / count).array().round() * count;
  }
  run.tau = run.tau_true;
  for (int j = 0; j < nj; ++j)
    for (Eigen::Index i = 0; i < N; ++i) run.tau(i, j) += o.torque_noise * run.rms[j] * unit(rng);
}

std::string settings_text(const MeasurementOptions& o, double h) {
  std::ostringstream s;
  s << "excitation=" << o.excitation.kind << " amplitude=" << o.excitation.amplitude << " band=" << o.excitation.f_low << "-"
    << o.excitation.f_high << "Hz duration=" << o.duration << "s rate=" << o.rate << "Hz controller=" << o.controller
    << " bandwidth=" << o.bandwidth << "Hz torque_noise=" << o.torque_noise << " encoder_bits=" << o.encoder_bits
    << " jitter=" << o.jitter << "s seed=" << o.seed << " excitation_seed=" << o.excitation.seed << " timestep=" << h << "s";
  return s.str();
}

}  // namespace

MeasuredRun simulate_measured(const std::string& model_path, const MeasurementOptions& o) {
  check_options(o);
  ModelPtr m = load_mjcf(model_path);
  MeasuredRun run;
  run.joints = joint_names(m.get(), model_path);
  if (m->nq != m->nv || m->njnt != m->nv) throw std::runtime_error(model_path + ": only hinge and slide joints can be measured");
  m->opt.disableflags |= mjDSBL_ACTUATION;   // the controller is the only actuation
  const double T = 1.0 / o.rate;
  // An integration step that divides the period, no longer than the model's nor T / 4.
  const int substeps = std::max(4, static_cast<int>(std::ceil(T / m->opt.timestep - 1e-9)));
  m->opt.timestep = T / substeps;
  run.sim_timestep = m->opt.timestep;
  ForceEffects fx(m.get(), model_path);
  run.plugins = declarations_text(fx);
  const auto ticks = static_cast<Eigen::Index>(std::llround(o.duration * o.rate)) + 2;
  const Eigen::VectorXd tick_times = Eigen::VectorXd::LinSpaced(ticks, 0.0, static_cast<double>(ticks - 1) * T);
  const ReferenceTrack ref = make_reference(m.get(), o.excitation, tick_times);
  DataPtr d = make_data(m.get());
  Trace trace;
  fx.reset();
  fx.attach();
  try {
    run_loop(m.get(), d.get(), fx, ref, o, substeps, run, trace);
  } catch (...) {
    fx.detach();
    throw;
  }
  fx.detach();
  sample(m.get(), trace, o, run);
  run.settings = settings_text(o, run.sim_timestep);
  return run;
}

Table measured_table(const MeasuredRun& run, const std::string& source) {
  Table t;
  t.source = source;
  t.names.push_back("t");
  t.columns.push_back(run.t);
  for (size_t j = 0; j < run.joints.size(); ++j) {
    t.names.push_back("q:" + run.joints[j]);
    t.columns.push_back(run.q.col(static_cast<Eigen::Index>(j)));
  }
  for (size_t j = 0; j < run.joints.size(); ++j) {
    t.names.push_back("tau:" + run.joints[j]);
    t.columns.push_back(run.tau.col(static_cast<Eigen::Index>(j)));
  }
  return t;
}

Dataset measured_dataset(const MeasuredRun& run, bool derive, const std::string& source) {
  ImportSpec spec;
  for (const auto& j : run.joints) spec.x.push_back("q:" + j), spec.y.push_back("tau:" + j);
  spec.t = "t";
  spec.conditioning.derive = derive;
  spec.conditioning.drop_edges = derive ? 2 : 0;   // the one-sided differences at the ends
  Dataset ds = table_to_dataset(measured_table(run, source), spec);
  ds.provenance["generator"] = "spml generate --model";
  ds.provenance["source"] = source;
  ds.provenance["settings"] = run.settings;
  ds.provenance["plugins"] = run.plugins;
  ds.provenance["sensor"] = derive ? "quantized q; qd, qdd by central differences (no filter)" : "quantized q only";
  ds.model.mjcf_path = source;
  return ds;
}

void write_measured_csv(const std::string& path, const MeasuredRun& run) {
  const Table t = measured_table(run, path);
  std::ostringstream out;
  out.precision(17);
  for (size_t c = 0; c < t.names.size(); ++c) out << (c ? "," : "") << t.names[c];
  out << "\n";
  for (Eigen::Index i = 0; i < t.rows(); ++i) {
    for (size_t c = 0; c < t.columns.size(); ++c) out << (c ? "," : "") << t.columns[c][i];
    out << "\n";
  }
  write_text_atomic(path, out.str());
}

}  // namespace spml
