#include "spml/envs/instruments.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"
#include "spml/signal.h"

namespace spml {
namespace {

struct Columns {
  std::vector<int> q, qd, qdd, tau;   // per model joint; tau -1 when the split has none
};

Columns columns_of(const mjModel* m, const Split& s, std::vector<std::string>& joints) {
  Columns c;
  for (int j = 0; j < m->njnt; ++j) {
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE)
      throw std::runtime_error("instruments: " + joint_description(m, j) + " is not a hinge or slide joint");
    const char* name = mj_id2name(m, mjOBJ_JOINT, j);
    if (!name) throw std::runtime_error("instruments: " + joint_description(m, j) + " has no name to find its columns by");
    joints.emplace_back(name);
    c.q.push_back(s.x_index("q:" + joints.back()));
    c.qd.push_back(s.x_index("qd:" + joints.back()));
    c.qdd.push_back(s.x_index("qdd:" + joints.back()));
    c.tau.push_back(s.y_index("tau:" + joints.back()));
    if (c.q.back() < 0 || c.qd.back() < 0 || c.qdd.back() < 0)
      throw std::runtime_error("split '" + s.name + "' lacks q:/qd:/qdd:" + joints.back() + " (instruments simulate every joint)");
  }
  return c;
}

// First rows of the records: 0, the given ones, and every row after a time jump.
std::vector<Eigen::Index> record_starts(const Split& s, const std::vector<Eigen::Index>& runs) {
  std::vector<Eigen::Index> starts{0};
  starts.insert(starts.end(), runs.begin(), runs.end());
  const double dt = median_step(s.t);
  for (Eigen::Index i = 1; i < s.rows(); ++i)
    if (!(s.t[i] > s.t[i - 1]) || s.t[i] - s.t[i - 1] > 5 * dt) starts.push_back(i);
  std::sort(starts.begin(), starts.end());
  starts.erase(std::unique(starts.begin(), starts.end()), starts.end());
  starts.push_back(s.rows());
  return starts;
}

// One simulation along the whole split with tracking bandwidth w [rad/s]: fills out.split's
// q:/qd:/qdd: columns and out.rms_tracking.
void simulate_along(mjModel* m, mjData* d, ForceEffects& effects, const Split& s, const Columns& c,
                    const std::vector<Eigen::Index>& starts, double w, SimulatedTwin& out) {
  const int J = m->njnt;
  const double max_step = m->opt.timestep;
  std::vector<double> sq(static_cast<size_t>(J), 0.0);
  std::vector<mjtNum> err(static_cast<size_t>(m->nv)), pd(static_cast<size_t>(m->nv));
  out.rms_tracking.clear();
  for (size_t r = 0; r + 1 < starts.size(); ++r) {
    mj_resetData(m, d);
    effects.reset();
    for (int j = 0; j < J; ++j) {
      d->qpos[m->jnt_qposadr[j]] = s.X(starts[r], c.q[static_cast<size_t>(j)]);
      d->qvel[m->jnt_dofadr[j]] = s.X(starts[r], c.qd[static_cast<size_t>(j)]);
    }
    for (Eigen::Index i = starts[r]; i < starts[r + 1]; ++i) {
      const bool last = i + 1 == starts[r + 1];
      const double span = last ? 0 : s.t[i + 1] - s.t[i];
      const int substeps = last ? 1 : std::max(1, static_cast<int>(std::ceil(span / max_step)));
      m->opt.timestep = last ? max_step : span / substeps;
      for (int k = 0; k < substeps; ++k) {
        // Measured states and torques, linearly interpolated at the substep's time.
        const double f = last ? 0.0 : static_cast<double>(k) / substeps;
        const Eigen::Index i1 = last ? i : i + 1;
        mj_step1(m, d);
        std::fill(err.begin(), err.end(), 0.0);
        for (int j = 0; j < J; ++j) {
          const auto jj = static_cast<size_t>(j);
          const int dof = m->jnt_dofadr[j];
          const double qm = (1 - f) * s.X(i, c.q[jj]) + f * s.X(i1, c.q[jj]);
          const double qdm = (1 - f) * s.X(i, c.qd[jj]) + f * s.X(i1, c.qd[jj]);
          err[static_cast<size_t>(dof)] = w * w * (qm - d->qpos[m->jnt_qposadr[j]]) + 2 * w * (qdm - d->qvel[dof]);
        }
        mj_mulM(m, d, pd.data(), err.data());
        for (int j = 0; j < J; ++j) {
          const auto jj = static_cast<size_t>(j);
          const int dof = m->jnt_dofadr[j];
          const double tau = c.tau[jj] < 0 ? 0.0 : (1 - f) * s.Y(i, c.tau[jj]) + f * s.Y(i1, c.tau[jj]);
          d->qfrc_applied[dof] = tau + pd[static_cast<size_t>(dof)];
        }
        // The states at the row's time: the first substep starts there (Euler: qacc of that state).
        if (k == 0)
          for (int j = 0; j < J; ++j) {
            const auto jj = static_cast<size_t>(j);
            const double q = d->qpos[m->jnt_qposadr[j]];
            out.split.X(i, c.q[jj]) = q;
            out.split.X(i, c.qd[jj]) = d->qvel[m->jnt_dofadr[j]];
            sq[jj] += (q - s.X(i, c.q[jj])) * (q - s.X(i, c.q[jj]));
          }
        mj_step2(m, d);
        if (k == 0)
          for (int j = 0; j < J; ++j) out.split.X(i, c.qdd[static_cast<size_t>(j)]) = d->qacc[m->jnt_dofadr[j]];
        effects.advance(d, m->opt.timestep);
      }
      // MuJoCo resets a state whose accelerations blow up (and counts a warning): diverged too.
      const bool reset = d->warning[mjWARN_BADQACC].number + d->warning[mjWARN_BADQVEL].number + d->warning[mjWARN_BADQPOS].number > 0;
      for (int j = 0; j < J; ++j)
        if (reset || !std::isfinite(out.split.X(i, c.q[static_cast<size_t>(j)])) || !std::isfinite(out.split.X(i, c.qdd[static_cast<size_t>(j)])))
          throw std::runtime_error("split '" + s.name + "': the simulation along the measured motion diverged at row " + std::to_string(i) +
                                   " (t = " + std::to_string(s.t[i]) + ", joint '" + out.joints[static_cast<size_t>(j)] + "')");
    }
  }
  m->opt.timestep = max_step;
  for (double v : sq) out.rms_tracking.push_back(std::sqrt(v / static_cast<double>(s.rows())));
}

}  // namespace

SimulatedTwin simulated_twin(const std::string& mjcf_path, const Split& s, const std::vector<Eigen::Index>& runs,
                             const InstrumentOptions& options) {
  if (s.t.size() != s.rows() || s.rows() < 2)
    throw std::runtime_error("split '" + s.name + "' has no time stamps: the instruments simulate the model along them");
  const Simulation sim = open_simulation(mjcf_path);
  mjModel* m = sim.m();
  SimulatedTwin out;
  out.split = s;
  const Columns c = columns_of(m, s, out.joints);
  const std::vector<Eigen::Index> starts = record_starts(s, runs);
  out.records = static_cast<int>(starts.size()) - 1;
  const double ceiling = 0.1 / median_step(s.t);
  if (options.tracking_hz > ceiling)
    throw std::runtime_error("a tracking bandwidth of " + std::to_string(options.tracking_hz) + " Hz is above a tenth of the sampling rate (" +
                             std::to_string(ceiling) + " Hz): the loop would not be stable between the samples");
  if (options.tracking_hz > 0) {
    out.tracking_hz = options.tracking_hz;
    simulate_along(m, sim.d(), *sim.effects, s, c, starts, 2 * M_PI * out.tracking_hz, out);
    return out;
  }
  // Automatic: the lowest bandwidth (1, 2, 4, ... Hz, at most a tenth of the sampling rate)
  // that keeps every joint within max_gap of its own motion (RMS about its mean). Too low, the
  // instruments do not follow the motion (a model missing a 2 kg payload drifted 0.4-0.8 rad
  // under a 1 Hz loop: IV standard errors so large nothing was contradicted); too high, the
  // loop feeds the encoder noise into them, correlated with the noise of the differentiated
  // accelerations (4-joint arm missing a payload, raw differences of 16-bit encoders: largest
  // |estimate - truth| 0.7 / 1.5 / 3.2 / 10 / 49 standard errors at 1 / 4 / 8 / 16 / 32 Hz,
  // the gap 1.1 / 0.046 / 0.012 / 0.003 / 7e-4 rad; a 1 % rule took 32 Hz). Through a low-pass
  // the noise is gone, and a tight loop keeps the model's own errors out of the instruments (a
  // 7-joint chain missing a friction band: `parameters` named at 4 Hz, not at 16 Hz).
  std::vector<double> motion;
  for (size_t j = 0; j < c.q.size(); ++j) {
    const Eigen::VectorXd q = s.X.col(c.q[j]);
    motion.push_back(std::sqrt((q.array() - q.mean()).square().mean()));
  }
  for (double hz = 1;; hz *= 2) {
    out.tracking_hz = std::min(hz, ceiling);
    simulate_along(m, sim.d(), *sim.effects, s, c, starts, 2 * M_PI * out.tracking_hz, out);
    bool close = true;
    for (size_t j = 0; j < motion.size(); ++j) close &= out.rms_tracking[j] <= options.max_gap * motion[j];
    if (close || out.tracking_hz >= ceiling) return out;
  }
}

}  // namespace spml
