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
Fit Diagnosis::refit(const std::vector<int>& causes, bool base_free, bool robust) const {
  return fit_blocks(blocks(causes, base_free), fit_.y0, true, robust ? fit_.N : 0);
}

// Residual of a fit on another split (test, cross): the causes' columns evaluated there.
Eigen::VectorXd Diagnosis::residual_on(const SplitData& s, const std::vector<int>& causes, bool base_free, const Fit& f) const {
  Eigen::VectorXd pred = Eigen::VectorXd::Zero(s.y0.size());
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

double Diagnosis::rss_on(const Eigen::VectorXd& r, const std::vector<int>& outputs, Eigen::Index N) const {
  double s = 0;
  for (int o : outputs) s += r.segment(o * N, N).squaredNorm();
  return s;
}

std::vector<int> Diagnosis::outputs_of(int candidate) const { return cands_[static_cast<size_t>(candidate)].fit_cols.active; }

}  // namespace spml::diagnose_detail
