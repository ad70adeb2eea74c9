// Stage 2, prepare: one split made ready for the least squares - its joint columns, the stacked
// base regressor, the stacked torques and what the model as given predicts.
#include <algorithm>
#include <cmath>

#include "diagnosis.h"
#include "spml/signal.h"

namespace spml::diagnose_detail {

SplitData Diagnosis::prepare(const Split& s, const std::vector<Eigen::Index>& runs, const SplitData* continues, bool filtered) {
  SplitData d;
  d.name = s.name;
  d.split = s;
  d.runs = runs;
  d.continues = continues;
  const std::string where = opt_.data + ": ";
  try {
    d.cols = std::make_unique<JointColumns>(*reg_, s);
  } catch (const DatasetError& e) {
    std::string msg = e.what();
    if (msg.find("qdd:") != std::string::npos) msg += " (measured data: `spml import --derive` adds qd:/qdd: by filtered differentiation)";
    throw DatasetError(where + msg);
  }
  if (!s.X.allFinite() || !s.Y.allFinite()) throw DatasetError(where + "split '" + s.name + "': holds NaN or Inf values");
  // Filters, hold-outs and rollouts run in time order.
  for (Eigen::Index i = 1; i < s.t.size(); ++i)
    if (!(s.t[i] > s.t[i - 1]))
      throw DatasetError(where + "split '" + s.name + "': time stamps do not increase at row " + std::to_string(i) + " (t = " + fmt(s.t[i - 1]) +
                         ", then " + fmt(s.t[i]) + "): sort the rows by time");
  d.N = s.rows();
  {
    // The base block touches every output: kept whole.
    const Eigen::MatrixXd A = stacked_base_regressor(*reg_, base_, s.X, *d.cols, where + "split " + s.name);
    d.base.rows_per_output = d.N;
    d.base.outputs = static_cast<int>(s.Y.cols());
    d.base.cols = static_cast<int>(A.cols());
    for (int o = 0; o < d.base.outputs; ++o) {
      d.base.active.push_back(o);
      d.base.parts.emplace_back(A.middleRows(o * d.N, d.N));
    }
  }
  d.b = stacked_torques(s, opt_.data);
  d.soft = frictionloss_correction(d, reg_->model());
  d.friction = d.soft;
  add_declared_forces(d, d.friction);
  d.own_level = own_level_force(d, d.soft);
  d.given = d.base.times(base_.model_values);
  if (d.friction.size()) d.given += d.friction;
  const double rms_torque = rms(d.b);
  for (Eigen::Index i = 0; i < d.given.size(); ++i)
    if (!(std::fabs(d.given[i]) <= kAbsurdTorqueRatio * rms_torque))
      throw DatasetError(opt_.model + ": the model as given predicts " + fmt(d.given[i]) + " on split '" + s.name + "' of " + opt_.data +
                         " (row " + std::to_string(i % d.N) + ", torque column '" + s.y_columns[static_cast<size_t>(i / d.N)] +
                         "'), " + fmt(kAbsurdTorqueRatio) + " times the measured torques' RMS (" + fmt(rms_torque) + ") or more: a declared value (a plugin's, "
                         "a joint's, a body's) is off by orders of magnitude");
  d.y0 = d.b - d.given;
  if (filtered) apply_filter(d);
  return d;
}

// Decided on the fit split (prepared unfiltered), then applied to it; later splits are
// filtered as they are prepared.
void Diagnosis::plan_parallel_filter() {
  std::vector<Eigen::VectorXd> q, qdd;
  for (int j : out_joint_index_) {
    q.push_back(fit_.split.X.col(fit_.cols->q[static_cast<size_t>(j)]));
    qdd.push_back(fit_.split.X.col(fit_.cols->qdd[static_cast<size_t>(j)]));
  }
  std::vector<Eigen::VectorXd> residual;
  for (Eigen::Index o = 0; o * fit_.N < fit_.y0.size(); ++o) residual.push_back(fit_.y0.segment(o * fit_.N, fit_.N));
  const double dt = fit_.split.t.size() == fit_.split.rows() ? median_step(fit_.split.t) : 0;
  filter_plan_ = plan_filter(ds_, q, qdd, residual, dt > 0 ? 1 / dt : 0, notes_);
  weigh_second_pass();
  apply_filter(fit_);
  if (fit_.sos.probe_hz > 0)
    filter_plan_.description += "; the states went through it too, and a second pass would change the torques and the model's "
                                "prediction alike by " + fmt(100 * filter_plan_.second_pass_change, 3) + " % of their RMS on a joint (more than " + fmt(100 * kSecondPassChange) +
                                " %, and a fair part of what it changes in the prediction): only the columns that switch faster than its band (the power above " + fmt(fit_.sos.probe_hz, 4) + " Hz more than " +
                                fmt(100 * kSwitchingShare) + " % of the power above half that) are filtered, the smooth ones left as the states made them";
  if (filter_plan_.source != FilterPlan::Source::none && fit_.sos.empty())
    filter_plan_.description += "; not applied: the cut-off (" + fmt(filter_plan_.lowpass.cutoff_hz) +
                                " Hz) is not below 0.4 of the sampling rate of the split, so nothing is left to filter";
}

// Under a recorded low-pass the torques went through it once, and so did the states: a column
// that is a smooth function of them (the rigid-body columns, a damping, a spring) already is
// what the low-pass made of the raw one, and a second pass takes out of it what the torques
// kept in the filter's transition band. A reference of holds joined by 80 ms ramps put that
// much there that the MJCF that made the log left 8.3 % of every joint's torque at 14 bits
// (`parameters` named) and `stick_slip` was named on two joints of four at 10 bits (3 of 3
// seeds). The second pass also takes the encoders' noise out of that band, which the torques
// never held (errors in variables): on a 10-bit log under a slow stepped sine, filtered once,
// `parameters` was named on the MJCF that made it. The dynamics' own content in the band is in
// both the torques and the model's prediction from the states; the encoders' noise is only in
// the prediction, the torque sensor's only in the torques. So the dynamics' part is measured by
// the inner product of the two changes (independent noises average out of it), per joint, as
// an RMS relative to the torques'. The smooth columns are left as the states made them where
// that is more than kSecondPassChange on a joint (8 % on the holds, at 10 bits as at 14) and a
// fair part of what a second pass changes in the prediction (over the joints, squared, more
// than kSecondPassShared; the rest is noise a second pass would remove: 0.48-0.98 on the
// holds, where a structured mismatch named causes and the noise named none). Below (0.05-0.5 %
// on the suite's smooth excitations), or where the encoders' noise is nearly all of it (under
// 0.01: a 10-bit stepped sine, 2-3 times the torques' RMS changed in the prediction and 3-6 %
// shared, a controller's chatter following the quantized positions), every column is
// filtered again, as before.
void Diagnosis::weigh_second_pass() {
  if (filter_plan_.source != FilterPlan::Source::recorded || filter_plan_.raw_differences) return;
  const ParallelFilter every = plan_sections(filter_plan_, fit_.split);
  if (every.empty()) return;
  // A stacked series made mean-free per joint (a constant goes through a low-pass unchanged),
  // and what a second pass changes of it.
  auto centred = [&](Eigen::VectorXd x) {
    for (Eigen::Index o = 0; o * fit_.N < x.size(); ++o) x.segment(o * fit_.N, fit_.N).array() -= x.segment(o * fit_.N, fit_.N).mean();
    return x;
  };
  auto change = [&](const Eigen::VectorXd& x) {
    Eigen::VectorXd twice = x;
    filter_stacked(every, twice, fit_.N, fit_.runs, true);
    return Eigen::VectorXd(twice - x);
  };
  const Eigen::VectorXd b = centred(fit_.b), torques = change(b), model = change(centred(fit_.base.times(base_.model_values)));
  double signal = 0, model_change = 0;   // summed over the joints, each relative to its torques' RMS, squared
  for (Eigen::Index o = 0; o * fit_.N < b.size(); ++o) {
    const double size = b.segment(o * fit_.N, fit_.N).squaredNorm();
    if (!(size > 0)) continue;
    const double shared = std::max(0.0, torques.segment(o * fit_.N, fit_.N).dot(model.segment(o * fit_.N, fit_.N))) / size,
                 own = model.segment(o * fit_.N, fit_.N).squaredNorm() / size;
    signal += shared;
    model_change += own;
    filter_plan_.second_pass_change = std::max(filter_plan_.second_pass_change, std::sqrt(shared));
    filter_plan_.second_pass_model_change = std::max(filter_plan_.second_pass_model_change, std::sqrt(own));
  }
  filter_plan_.smooth_kept = filter_plan_.second_pass_change > kSecondPassChange && signal > kSecondPassShared * model_change;
}

void Diagnosis::apply_filter(SplitData& d) const {
  d.sos = plan_sections(filter_plan_, d.split);
  if (d.sos.empty()) return;
  for (auto& part : d.base.parts) filter_stacked(d.sos, part, d.N, d.runs, true);
  if (filter_plan_.torques) filter_stacked(d.sos, d.b, d.N, d.runs);
  d.given = d.base.times(base_.model_values);
  if (d.friction.size()) {
    filter_stacked(d.sos, d.friction, d.N, {}, true);
    d.given += d.friction;
  }
  if (d.soft.size()) filter_stacked(d.sos, d.soft, d.N, {}, true);
  if (d.own_level.size()) filter_stacked(d.sos, d.own_level, d.N, {}, true);
  d.y0 = d.b - d.given;
}

}  // namespace spml::diagnose_detail
