#include "rollout.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>

#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"

namespace spml::diagnose_detail {

namespace {

// Advances `row` to the last sample at or before `time`; returns the fraction of the way to the
// next sample (0 past the last).
double locate(const Eigen::VectorXd& ts, Eigen::Index& row, double time) {
  const Eigen::Index N = ts.size();
  while (row + 1 < N && ts[row + 1] <= time) ++row;
  return row + 1 < N ? std::clamp((time - ts[row]) / (ts[row + 1] - ts[row]), 0.0, 1.0) : 0.0;
}

double lerp(const RowMatrix& M, Eigen::Index row, double f, int c) {
  return (1 - f) * M(row, c) + f * M(std::min(row + 1, M.rows() - 1), c);
}

// One model's rollouts on one split: the columns, the start rows, one window at a time.
class Windows {
 public:
  Windows(const std::string& mjcf_path, const Split& s, double horizon, const std::vector<Eigen::Index>& runs);
  // The start row of window w of `windows`, spread evenly over the possible starts.
  Eigen::Index start(int w, int windows) const {
    return starts_[static_cast<size_t>(static_cast<double>(w) * static_cast<double>(starts_.size() - 1) / std::max(1, windows - 1))];
  }
  // Simulates the window from `start`; returns per joint |q_sim - q_measured| at its end.
  std::vector<double> run(Eigen::Index start, RolloutTrace* trace);
  std::vector<std::string> joints;

 private:
  const Split& s_;
  const Simulation sim_;
  std::vector<int> qc_, qdc_, tauc_;
  std::vector<Eigen::Index> starts_;
  int steps_ = 1;
};

Windows::Windows(const std::string& mjcf_path, const Split& s, double horizon, const std::vector<Eigen::Index>& runs)
    : s_(s), sim_(open_simulation(mjcf_path)) {
  const mjModel* m = sim_.m();
  if (s.t.size() != s.rows()) throw std::runtime_error("split '" + s.name + "' has no time stamps: rollouts need them");
  for (int j = 0; j < m->njnt; ++j) {
    const std::string name = mj_id2name(m, mjOBJ_JOINT, j);
    joints.push_back(name);
    qc_.push_back(s.x_index("q:" + name));
    qdc_.push_back(s.x_index("qd:" + name));
    tauc_.push_back(s.y_index("tau:" + name));
    if (qc_.back() < 0 || qdc_.back() < 0) throw std::runtime_error("split '" + s.name + "' lacks q:/qd:" + name);
  }
  const Eigen::Index N = s.rows();
  // Rows spanned by one horizon.
  Eigen::Index span = 0;
  while (span + 1 < N && s.t[span + 1] - s.t[0] < horizon) ++span;
  ++span;
  if (span >= N) throw std::runtime_error("split '" + s.name + "' is shorter than one rollout horizon");
  // Start rows whose window stays within one record.
  std::vector<Eigen::Index> bounds{0};
  bounds.insert(bounds.end(), runs.begin(), runs.end());
  bounds.push_back(N);
  for (size_t r = 0; r + 1 < bounds.size(); ++r)
    for (Eigen::Index i = bounds[r]; i + span < bounds[r + 1]; ++i) starts_.push_back(i);
  if (starts_.empty()) throw std::runtime_error("split '" + s.name + "': no record is longer than one rollout horizon");
  steps_ = std::max(1, static_cast<int>(std::lround(horizon / m->opt.timestep)));
}

std::vector<double> Windows::run(Eigen::Index start, RolloutTrace* trace) {
  mjModel* m = sim_.m();
  mjData* d = sim_.d();
  const auto nj = static_cast<size_t>(m->njnt);
  mj_resetData(m, d);
  for (size_t j = 0; j < nj; ++j) {
    d->qpos[m->jnt_qposadr[j]] = s_.X(start, qc_[j]);
    d->qvel[m->jnt_dofadr[j]] = s_.X(start, qdc_[j]);
  }
  // A stateful plugin's state at the measured start, as diagnose's fits take it: reset, a
  // window that starts in motion began with LuGre's bristles unloaded.
  sim_.effects->start_steady(d);
  Eigen::Index row = start, qrow = start;
  const double t0 = s_.t[start];
  std::vector<double> measured(nj), error(nj);
  for (int k = 0;; ++k) {
    const double t = t0 + k * m->opt.timestep;
    if (trace || k == steps_) {   // the measured position at the step's time
      const double f = locate(s_.t, qrow, t);
      for (size_t j = 0; j < nj; ++j) measured[j] = lerp(s_.X, qrow, f, qc_[j]);
    }
    if (trace) {
      trace->t.push_back(t);
      trace->measured.push_back(measured);
      trace->simulated.emplace_back();
      for (size_t j = 0; j < nj; ++j) trace->simulated.back().push_back(d->qpos[m->jnt_qposadr[j]]);
    }
    if (k == steps_) break;
    // Measured torque, linearly interpolated at the step's time.
    const double f = locate(s_.t, row, t);
    for (size_t j = 0; j < nj; ++j) d->qfrc_applied[m->jnt_dofadr[j]] = tauc_[j] < 0 ? 0.0 : lerp(s_.Y, row, f, tauc_[j]);
    step(m, d, *sim_.effects);
  }
  for (size_t j = 0; j < nj; ++j) {
    error[j] = std::fabs(d->qpos[m->jnt_qposadr[j]] - measured[j]);
    if (!std::isfinite(error[j])) error[j] = std::numeric_limits<double>::infinity();
  }
  return error;
}

}  // namespace

RolloutResult rollout(const std::string& mjcf_path, const Split& s, int windows, double horizon, const std::vector<Eigen::Index>& runs) {
  Windows sim(mjcf_path, s, horizon, runs);
  RolloutResult out;
  out.horizon = horizon;
  out.joints = sim.joints;
  out.position_error.assign(out.joints.size(), 0.0);
  for (int w = 0; w < windows; ++w) {
    const Eigen::Index start = sim.start(w, windows);
    out.window_start.push_back(s.t[start]);
    out.window_error.push_back(sim.run(start, nullptr));
    for (size_t j = 0; j < out.joints.size(); ++j) out.position_error[j] += out.window_error.back()[j] / windows;
  }
  out.windows = windows;
  return out;
}

std::vector<bool> worse_joints(const RolloutResult& before, const RolloutResult& after) {
  std::vector<bool> out(before.joints.size(), false);
  for (size_t j = 0; j < out.size(); ++j) out[j] = !(after.position_error[j] <= before.position_error[j]);
  return out;
}

std::vector<RolloutTrace> rollout_traces(const std::string& mjcf_path, const Split& s, int windows, double horizon,
                                         const std::vector<Eigen::Index>& runs, const std::vector<int>& which) {
  Windows sim(mjcf_path, s, horizon, runs);
  std::vector<RolloutTrace> out;
  for (const int w : which) {
    out.emplace_back();
    out.back().window = w;
    sim.run(sim.start(w, windows), &out.back());
  }
  return out;
}

std::vector<int> windows_to_trace(const RolloutResult& r) {
  const auto W = r.window_error.size();
  if (W == 0) return {};
  std::vector<double> score(W, 0.0);
  for (size_t j = 0; j < r.joints.size(); ++j) {
    double mean = 0;
    int finite = 0;
    for (const auto& e : r.window_error)
      if (std::isfinite(e[j])) mean += e[j], ++finite;
    mean = finite ? mean / finite : 0;
    // A diverged window ranks first.
    for (size_t w = 0; w < W; ++w)
      score[w] = std::max(score[w], !std::isfinite(r.window_error[w][j]) ? std::numeric_limits<double>::infinity()
                                                                          : mean > 0 ? r.window_error[w][j] / mean : 0.0);
  }
  std::vector<int> order(W);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return score[static_cast<size_t>(a)] > score[static_cast<size_t>(b)]; });
  std::vector<int> picked;
  for (const size_t k : {size_t{0}, W / 2, W - 1})
    if (std::find(picked.begin(), picked.end(), order[k]) == picked.end()) picked.push_back(order[k]);
  return picked;
}

std::string rollout_csv(const std::vector<std::string>& joints, const std::vector<RolloutTrace>& given,
                        const std::vector<RolloutTrace>& extended) {
  std::ostringstream csv;
  csv.precision(17);   // round trip: |simulated - measured| read back is report.json's end error
  csv << "window,t";
  for (const auto& j : joints) csv << ",q:" << j << ",given:" << j << ",extended:" << j;
  csv << "\n";
  for (size_t w = 0; w < given.size(); ++w) {
    const RolloutTrace &g = given[w], &e = extended[w];
    for (size_t i = 0; i < g.t.size(); ++i) {
      csv << g.window << "," << g.t[i];
      for (size_t j = 0; j < joints.size(); ++j) csv << "," << g.measured[i][j] << "," << g.simulated[i][j] << "," << e.simulated[i][j];
      csv << "\n";
    }
  }
  return csv.str();
}

}  // namespace spml::diagnose_detail
