#include "rollout.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"

namespace spml::diagnose_detail {

RolloutResult rollout(const std::string& mjcf_path, const Split& s, int windows, double horizon, const std::vector<Eigen::Index>& runs) {
  const Simulation sim = open_simulation(mjcf_path);
  mjModel* m = sim.m();
  mjData* d = sim.d();
  ForceEffects& effects = *sim.effects;
  RolloutResult out;
  out.horizon = horizon;
  if (s.t.size() != s.rows()) throw std::runtime_error("split '" + s.name + "' has no time stamps: rollouts need them");
  std::vector<int> qc, qdc, tauc;
  for (int j = 0; j < m->njnt; ++j) {
    const std::string name = mj_id2name(m, mjOBJ_JOINT, j);
    out.joints.push_back(name);
    qc.push_back(s.x_index("q:" + name));
    qdc.push_back(s.x_index("qd:" + name));
    tauc.push_back(s.y_index("tau:" + name));
    if (qc.back() < 0 || qdc.back() < 0) throw std::runtime_error("split '" + s.name + "' lacks q:/qd:" + name);
  }
  out.position_error.assign(static_cast<size_t>(m->njnt), 0.0);
  out.window_error.assign(static_cast<size_t>(std::max(windows, 0)), std::vector<double>(static_cast<size_t>(m->njnt), 0.0));
  const Eigen::Index N = s.rows();
  // Rows spanned by one horizon.
  Eigen::Index span = 0;
  while (span + 1 < N && s.t[span + 1] - s.t[0] < horizon) ++span;
  ++span;
  if (span >= N) throw std::runtime_error("split '" + s.name + "' is shorter than one rollout horizon");
  // Start rows whose window stays within one record, spread evenly over them.
  std::vector<Eigen::Index> starts, bounds{0};
  bounds.insert(bounds.end(), runs.begin(), runs.end());
  bounds.push_back(N);
  for (size_t r = 0; r + 1 < bounds.size(); ++r)
    for (Eigen::Index i = bounds[r]; i + span < bounds[r + 1]; ++i) starts.push_back(i);
  if (starts.empty()) throw std::runtime_error("split '" + s.name + "': no record is longer than one rollout horizon");
  const int steps = std::max(1, static_cast<int>(std::lround(horizon / m->opt.timestep)));
  for (int w = 0; w < windows; ++w) {
    const Eigen::Index start = starts[static_cast<size_t>(static_cast<double>(w) * static_cast<double>(starts.size() - 1) / std::max(1, windows - 1))];
    mj_resetData(m, d);
    effects.reset();
    for (int j = 0; j < m->njnt; ++j) {
      d->qpos[m->jnt_qposadr[j]] = s.X(start, qc[static_cast<size_t>(j)]);
      d->qvel[m->jnt_dofadr[j]] = s.X(start, qdc[static_cast<size_t>(j)]);
    }
    Eigen::Index row = start;
    const double t0 = s.t[start];
    for (int k = 0; k < steps; ++k) {
      // Measured torque, linearly interpolated at the step's time.
      const double t = t0 + k * m->opt.timestep;
      while (row + 1 < N && s.t[row + 1] <= t) ++row;
      const double f = row + 1 < N ? std::clamp((t - s.t[row]) / (s.t[row + 1] - s.t[row]), 0.0, 1.0) : 0.0;
      for (int j = 0; j < m->njnt; ++j) {
        const int c = tauc[static_cast<size_t>(j)];
        d->qfrc_applied[m->jnt_dofadr[j]] = c < 0 ? 0.0 : (1 - f) * s.Y(row, c) + f * s.Y(std::min(row + 1, N - 1), c);
      }
      step(m, d, effects);
    }
    // Measured position at the end time.
    const double tend = t0 + steps * m->opt.timestep;
    Eigen::Index r = start;
    while (r + 1 < N && s.t[r + 1] <= tend) ++r;
    const double f = r + 1 < N ? std::clamp((tend - s.t[r]) / (s.t[r + 1] - s.t[r]), 0.0, 1.0) : 0.0;
    for (int j = 0; j < m->njnt; ++j) {
      const int c = qc[static_cast<size_t>(j)];
      const double qm = (1 - f) * s.X(r, c) + f * s.X(std::min(r + 1, N - 1), c);
      double e = std::fabs(d->qpos[m->jnt_qposadr[j]] - qm);
      if (!std::isfinite(e)) e = std::numeric_limits<double>::infinity();
      out.window_error[static_cast<size_t>(w)][static_cast<size_t>(j)] = e;
      out.position_error[static_cast<size_t>(j)] += e / windows;
    }
  }
  out.windows = windows;
  return out;
}

}  // namespace spml::diagnose_detail
