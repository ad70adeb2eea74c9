// Stage 3, estimate: least-squares refits of the base parameters (free or held at the MJCF's
// values) jointly with the causes' amplitudes, and the residual of such a fit on any split.
#include "diagnosis.h"

namespace spml::diagnose_detail {

std::vector<const BlockColumns*> Diagnosis::blocks(const std::vector<int>& causes, bool base_free) const {
  std::vector<const BlockColumns*> out;
  if (base_free) out.push_back(&fit_.base);
  for (int c : causes) out.push_back(&cands_[static_cast<size_t>(c)].fit_cols);
  return out;
}

// robust: standard errors from the long-run covariance of the residuals (statistics.h).
// Held at the MJCF's values or free, the base parameters hold none of the own levels the causes
// take over (own_friction.cc): their force is returned to the targets. weights: each output's
// rows weighted so (weighted least squares: the fit of one noise variance per joint, where the
// unweighted one leaves a light joint the large joints' misfit), the residual returned in the
// targets' own units.
Fit Diagnosis::refit(const std::vector<int>& causes, bool base_free, bool robust, const Eigen::VectorXd* weights) const {
  const TakenBase t = taken_base(causes);
  std::vector<const BlockColumns*> with = blocks(causes, base_free);
  if (base_free && t.base) with[0] = &*t.base;   // free, the base parameters still hold no taken level
  if (!weights) return fit_blocks(with, t.y, true, robust ? fit_.N : 0);
  std::vector<BlockColumns> scaled;
  scaled.reserve(with.size());
  for (const BlockColumns* b : with) {
    BlockColumns s = *b;
    for (size_t k = 0; k < s.parts.size(); ++k) s.parts[k] *= (*weights)[s.active[k]];
    scaled.push_back(std::move(s));
  }
  std::vector<const BlockColumns*> ptrs;
  for (const auto& s : scaled) ptrs.push_back(&s);
  Fit f = fit_blocks(ptrs, scale_outputs(t.y, *weights, fit_.N), false, robust ? fit_.N : 0);
  f.residual = scale_outputs(f.residual, weights->cwiseInverse(), fit_.N);
  f.rss = f.residual.squaredNorm();
  return f;
}

// Residual of a fit on another split (test, cross): the causes' columns evaluated there.
Eigen::VectorXd Diagnosis::residual_on(const SplitData& s, const std::vector<int>& causes, bool base_free, const Fit& f) const {
  Eigen::VectorXd pred = Eigen::VectorXd::Zero(s.y0.size());
  if (const Eigen::VectorXd returned = returned_levels(s, causes); returned.size()) pred -= returned;   // a taken level's coefficient is 0 (refit)
  Eigen::Index c = 0;
  if (base_free) {
    pred += s.base.times(f.coef.segment(0, s.base.cols));
    c += s.base.cols;
  }
  for (int k : causes) {
    const BlockColumns cols = columns_of(cands_[static_cast<size_t>(k)], s);
    pred += cols.times(f.coef.segment(c, cols.cols));
    c += cols.cols;
  }
  return s.y0 - pred;
}

// A stacked 0/1 mask of the fit split's rows: 0 on each output's rows within half a period of
// the data's low-pass (at least two samples) of a velocity reversal of its joint.
Eigen::VectorXd Diagnosis::away_from_reversals(double* half_width_s) const {
  const Eigen::Index N = fit_.N;
  const auto O = static_cast<Eigen::Index>(out_joint_index_.size());
  Eigen::VectorXd mask = Eigen::VectorXd::Ones(N * O);
  if (fit_.split.t.size() != N || N < 3) return Eigen::VectorXd();
  const double dt = (fit_.split.t[N - 1] - fit_.split.t[0]) / static_cast<double>(N - 1);
  const double cutoff = filter_plan_.source == FilterPlan::Source::none ? 0.0 : filter_plan_.lowpass.cutoff_hz;
  const double half = std::max(2 * dt, cutoff > 0 ? 0.5 / cutoff : 0.0);
  if (half_width_s) *half_width_s = half;
  const auto w = static_cast<Eigen::Index>(std::ceil(half / dt));
  for (Eigen::Index o = 0; o < O; ++o) {
    for (const Eigen::Index i : reversal_rows(out_joint_index_[static_cast<size_t>(o)])) {
      const Eigen::Index from = std::max<Eigen::Index>(0, i - w), to = std::min<Eigen::Index>(N - 1, i + w);
      mask.segment(o * N + from, to - from + 1).setZero();
    }
  }
  return mask;
}

double Diagnosis::rss_on(const Eigen::VectorXd& r, const std::vector<int>& outputs, Eigen::Index N) const {
  double s = 0;
  for (int o : outputs) s += r.segment(o * N, N).squaredNorm();
  return s;
}

std::vector<int> Diagnosis::outputs_of(int candidate) const { return cands_[static_cast<size_t>(candidate)].fit_cols.active; }

}  // namespace spml::diagnose_detail
