// Part of stage 2 (prepare): which zero-phase low-pass the model's columns and the torques go
// through (filtering.h).
#include "filtering.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>

namespace spml::diagnose_detail {
namespace {

std::string text(double v) {
  std::ostringstream s;
  s.precision(4);
  s << v;
  return s.str();
}

// Fraction of the (mean-free) power of x above cut-off fc (zero-phase order-4 Butterworth).
double power_above(const Eigen::VectorXd& x, double fc, double rate) {
  const Eigen::VectorXd c = x.array() - x.mean();
  const double total = c.squaredNorm();
  if (!(total > 0)) return 0;
  return (c - filtfilt(butterworth_lowpass(4, fc, rate), c)).squaredNorm() / total;
}

// The band the trajectory excites: the lowest cut-off of a ladder (0.1 Hz doubling) below
// which every joint's positions keep 99.99 % of their variance; 0 when there is none.
double excitation_band(const std::vector<Eigen::VectorXd>& q, double rate) {
  for (double fc = 0.1; fc < 0.1 * rate; fc *= 2) {
    bool below = true;
    for (const auto& x : q) below &= power_above(x, fc, rate) < 1e-4;
    if (below) return fc;
  }
  return 0;
}

}  // namespace

namespace {

// The dataset's decimation record (nullopt: none, or not understood).
std::optional<DecimationRecord> decimation_of(const Dataset& ds) {
  const auto it = ds.provenance.find("decimation");
  return it == ds.provenance.end() ? std::nullopt : parse_decimation_record(it->second);
}

}  // namespace

double decimated_by(const Dataset& ds) {
  const auto d = decimation_of(ds);
  return d ? d->keep : 1;
}

FilterPlan plan_filter(const Dataset& ds, const std::vector<Eigen::VectorXd>& q, const std::vector<Eigen::VectorXd>& qdd,
                       const std::vector<Eigen::VectorXd>& residual, double rate_hz, std::vector<std::string>& notes) {
  FilterPlan plan;
  plan.ends_transient = ds.provenance.count("start_up_transient") > 0;
  const auto derived = ds.provenance.find("derivatives");
  const bool differences = derived != ds.provenance.end() && derived->second == "central-difference";
  const auto it = ds.provenance.find("filter");
  if (it != ds.provenance.end()) {
    const auto rec = parse_lowpass_record(it->second);
    const auto d = decimation_of(ds);
    const double keep = d ? d->keep : 1, kept = kWidestLowpassShare * rate_hz;
    if (rec && keep > 1 && rate_hz > 0 && rec->cutoff_hz >= kept) {
      // The decimation's anti-alias kept less than the recorded low-pass passes (--lowpass 150
      // --decimate 5 at 1 kHz keeps 80 Hz; EMPS's published 100 Hz before decimating by 10, 40
      // Hz): that low-pass can no longer be run at this rate, and reading it as the band left the
      // data unfiltered - LuGre named `coulomb` in a review. The band kept is the decimation's,
      // as if no low-pass were recorded: noise in it is looked for below.
      const std::string kept_by = d && d->anti_alias ? "the band its decimation to " + text(rate_hz) + " Hz kept (its anti-alias at " +
                                                           text(d->anti_alias->cutoff_hz) + " Hz)"
                                                     : "what its plain decimation to " + text(rate_hz) + " Hz keeps unfolded (" + text(kept) + " Hz)";
      notes.push_back("the dataset records a low-pass at " + text(rec->cutoff_hz) + " Hz ('" + it->second + "'), above " + kept_by +
                      ": the band is the decimation's, and noise in it is looked for as in a dataset that records no low-pass");
    } else if (rec) {
      plan.source = FilterPlan::Source::recorded;
      plan.lowpass = *rec;
      // A low-pass at or above 0.4 of the rate it ran at (before a decimation) smoothed next to
      // nothing (--lowpass 450 at 1 kHz, decimated 6: a delay of +2.9 ms named on clean data).
      plan.raw_differences = differences && rate_hz > 0 && rec->cutoff_hz >= kWidestLowpassShare * rate_hz * keep;
      plan.description = "the dataset records the low-pass it went through ('" + it->second +
                         "'): every model and candidate column is filtered alike (parallel filtering); the torques already were";
      return plan;
    } else {
      notes.push_back("the dataset's filter attribute '" + it->second + "' is not understood: no parallel filtering");
      plan.description = "the dataset's filter attribute is not understood: nothing filtered";
      return plan;
    }
  }
  plan.raw_differences = differences;
  // Why nothing is filtered, for report.json (a review read an empty `why`).
  auto unfiltered = [&](const std::string& why) {
    plan.description = "the dataset records no low-pass it can be filtered alike with, and " + why + ": nothing filtered";
    return plan;
  };
  if (!(rate_hz > 0)) return unfiltered("its fit split has no uniform time stamps");
  const double band = excitation_band(q, rate_hz);
  if (!(band > 0)) return unfiltered("no band below a tenth of the rate holds the positions");
  const double cutoff = 5 * band;
  if (!(cutoff < kWidestLowpassShare * rate_hz))
    return unfiltered("five times the band the positions excite (" + text(cutoff) + " Hz) is not below 0.4 of the rate");
  // Two signs of noise above the band, either enough: the accelerations' own power there
  // (differences of noisy positions), or the model's error there - noise in the accelerations
  // that is small beside their signal can still be most of what the model as given misses
  // (raw differences of 20-bit positions: 2 % of the accelerations' power, 99 % of the
  // residual's on every joint without an effect). White torque noise puts the share of the
  // spectrum above the cut-off there: the bar lies well above it.
  double worst_qdd = 0, worst_residual = 0;
  for (const auto& x : qdd) worst_qdd = std::max(worst_qdd, power_above(x, cutoff, rate_hz));
  for (const auto& e : residual) worst_residual = std::max(worst_residual, power_above(e, cutoff, rate_hz));
  const double white = 1 - cutoff / (0.5 * rate_hz);
  const double residual_bar = white + 0.5 * (1 - white);
  if (worst_qdd <= 0.05 && worst_residual <= residual_bar)
    return unfiltered("no noise lies above five times the band the positions excite (" + text(cutoff) + " Hz): the accelerations hold " +
                      text(100 * worst_qdd) + " % of their power there (the bar: 5 %), the model's error " + text(100 * worst_residual) +
                      " % on its worst joint (the bar: " + text(100 * residual_bar) + " %)");
  plan.source = FilterPlan::Source::detected;
  plan.raw_differences = true;
  plan.lowpass = {4, cutoff};
  plan.torques = true;
  const std::string evidence =
      worst_qdd > 0.05 ? "the accelerations hold " + text(100 * worst_qdd) + " % of their power above " + text(cutoff) + " Hz"
                       : "the model as given leaves " + text(100 * worst_residual) + " % of its error power above " + text(cutoff) +
                             " Hz on one joint (white noise would leave " + text(100 * white) + " %)";
  plan.description = evidence + " (five times the band the positions excite, " + text(band) +
                     " Hz) and the dataset records no filter: torques and every column go through a zero-phase Butterworth "
                     "low-pass (order 4, " + text(cutoff) + " Hz) alike (parallel filtering)";
  return plan;
}

ParallelFilter plan_sections(const FilterPlan& plan, const Split& s) {
  ParallelFilter f;
  if (plan.source == FilterPlan::Source::none || s.t.size() != s.rows() || s.rows() < 3) return f;
  const double dt = median_step(s.t);
  if (!(dt > 0) || plan.lowpass.cutoff_hz >= kWidestLowpassShare / dt) return f;
  f.sections = butterworth_lowpass(plan.lowpass.order, plan.lowpass.cutoff_hz, 1.0 / dt);
  f.predicted_ends = !plan.torques && !plan.ends_transient && !plan.smooth_kept;
  f.settle = settling_samples(f.sections);
  // Below 0.4 of the rate, a probe low-pass still separates the columns (filter_stacked); a
  // cut-off too near the rate for one leaves every column filtered, as before the probe.
  const double probe = kSwitchingProbe * plan.lowpass.cutoff_hz;
  if (plan.smooth_kept && probe < kWidestLowpassShare / dt) {
    f.probe = butterworth_lowpass(4, probe, 1.0 / dt);
    f.probe_half = butterworth_lowpass(4, 0.5 * probe, 1.0 / dt);
    f.probe_hz = probe;
  }
  return f;
}

std::vector<Eigen::Index> segment_bounds(Eigen::Index N, const std::vector<Eigen::Index>& runs) {
  std::vector<Eigen::Index> bounds{0};
  bounds.insert(bounds.end(), runs.begin(), runs.end());
  bounds.push_back(N);
  return bounds;
}

namespace {

// Linear prediction's order and the least number of samples it is fitted on.
constexpr Eigen::Index kPredictionOrder = 16, kPredictionRows = 8 * kPredictionOrder;

// x continued by `len` samples past its last one: a least-squares forward predictor of order
// kPredictionOrder fitted on x's last `window` samples and run on its own output. Empty where
// the continuation is not finite or leaves x's range widened by its span on either side
// (an unstable predictor: the caller reflects instead).
Eigen::VectorXd predicted_continuation(const Eigen::VectorXd& x, Eigen::Index len, Eigen::Index window) {
  const Eigen::Index p = kPredictionOrder, n = std::min(window, x.size());
  const Eigen::VectorXd w = x.tail(n);
  Eigen::MatrixXd A(n - p, p);
  for (Eigen::Index i = 0; i + p < n; ++i) A.row(i) = w.segment(i, p).transpose();
  const Eigen::VectorXd a = A.completeOrthogonalDecomposition().solve(w.tail(n - p));
  Eigen::VectorXd out(p + len);
  out.head(p) = w.tail(p);
  for (Eigen::Index i = 0; i < len; ++i) out[p + i] = out.segment(i, p).dot(a);
  const double lo = x.minCoeff(), hi = x.maxCoeff(), span = hi - lo;
  const Eigen::VectorXd tail = out.tail(len);
  if (!tail.allFinite() || tail.maxCoeff() > hi + span || tail.minCoeff() < lo - span) return {};
  return tail;
}

// One segment's pass. The torques of a recorded low-pass went through it once over the whole
// log, so at a split's ends they hold no start-up transient; a second pass over the model's
// columns of that split alone, started on an odd reflection, does: its curvature flips at the
// end. Under 3-8 Hz moves at 200 Hz (a 20 Hz import) an exact hinge's test split had its last
// 50 rows 0.229 N m off where its middle lay within 0.040, most of the model as given's
// held-out error. Continued by linear prediction over the pass's settling, the columns' ends
// follow the motion (0.039 N m there). Where the predictor is unstable, or the segment too
// short to fit it, the odd reflection stays. Only the model's own columns are continued
// (filter_stacked's `model_columns`), its declared levels and frictionloss correction with
// them; a candidate's and a stateful force's keep the reflection the friction tests were set
// against (with every column continued, a Coulomb level beside a flat hump was no longer
// determined). Nor where the import's own start-up transient stayed in the log's ends
// (FilterPlan::ends_transient): LuGre logs that keep it (200 rows dropped where 612 settle)
// were read as `coulomb` with their ends continued.
Eigen::VectorXd segment_pass(const ParallelFilter& f, const Eigen::VectorXd& x, bool predicted) {
  if (!predicted) return filtfilt(f.sections, x);
  const Eigen::Index len = f.settle, window = std::max(4 * len, kPredictionRows);
  if (x.size() < kPredictionRows) return filtfilt(f.sections, x);
  const Eigen::VectorXd after = predicted_continuation(x, len, window), before = predicted_continuation(x.reverse(), len, window);
  if (after.size() == 0 || before.size() == 0) return filtfilt(f.sections, x);
  Eigen::VectorXd ext(x.size() + 2 * len);
  ext << before.reverse(), x, after;
  return filtfilt(f.sections, ext).segment(len, x.size());
}

// Whether column c switches faster than the states' band: the power above the probe more than
// kSwitchingShare of the power above half of it (per segment; none above half: smooth).
bool switches(const ParallelFilter& f, const Eigen::MatrixXd& A, Eigen::Index c, Eigen::Index N, const std::vector<Eigen::Index>& bounds) {
  double above = 0, above_half = 0, total = 0;
  for (Eigen::Index o = 0; o * N < A.rows(); ++o)
    for (size_t r = 0; r + 1 < bounds.size(); ++r) {
      const Eigen::Index at = o * N + bounds[r], len = bounds[r + 1] - bounds[r];
      if (len < 2) continue;
      const Eigen::VectorXd seg = A.col(c).segment(at, len);
      total += seg.squaredNorm();
      above += (seg - filtfilt(f.probe, seg)).squaredNorm();
      above_half += (seg - filtfilt(f.probe_half, seg)).squaredNorm();
    }
  return above_half > 1e-12 * total && above > kSwitchingShare * above_half;
}

}  // namespace

// With a probe (FilterPlan::smooth_kept), a column that does not switch is left as it is
// (prepare.cc, weigh_second_pass says why); one that switches (sign(qd), a LuGre force, a
// ripple faster than the band) holds power far above the band, which the torques lost, and
// goes through the low-pass again, as the discontinuous forces parallel filtering is for.
// Without one every column goes through again, the model's own with their ends predicted
// where the filter says so (segment_pass).
void filter_stacked(const ParallelFilter& f, Eigen::MatrixXd& A, Eigen::Index N, const std::vector<Eigen::Index>& runs, bool model_columns) {
  if (f.sections.empty() || N < 2) return;
  const std::vector<Eigen::Index> bounds = segment_bounds(N, runs);
  const bool predicted = model_columns && f.predicted_ends;
  for (Eigen::Index c = 0; c < A.cols(); ++c) {
    if (!f.probe.empty() && !switches(f, A, c, N, bounds)) continue;
    for (Eigen::Index o = 0; o * N < A.rows(); ++o)
      for (size_t r = 0; r + 1 < bounds.size(); ++r) {
        const Eigen::Index at = o * N + bounds[r], len = bounds[r + 1] - bounds[r];
        if (len < 2) continue;
        const Eigen::VectorXd seg = A.col(c).segment(at, len);
        if (seg.cwiseAbs().maxCoeff() > 0) A.col(c).segment(at, len) = segment_pass(f, seg, predicted);
      }
  }
}

void filter_stacked(const ParallelFilter& f, Eigen::VectorXd& b, Eigen::Index N, const std::vector<Eigen::Index>& runs, bool model_columns) {
  Eigen::MatrixXd B = b;
  filter_stacked(f, B, N, runs, model_columns);
  b = B.col(0);
}

}  // namespace spml::diagnose_detail
