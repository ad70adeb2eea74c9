#include <algorithm>
#include <cmath>
#include <limits>

#include "spml/learners/evaluate.h"

namespace spml {

Scores score(const RowMatrix& Y, const LearnerPrediction& p) {
  Scores s;
  const double n = static_cast<double>(Y.rows());
  for (Eigen::Index o = 0; o < Y.cols(); ++o) {
    // Scaled sums (Eigen's stableNorm, error over predicted std): squares of values beyond
    // 1e154 overflow and below 1e-154 underflow, which made RMSE inf or 0 for Y x 1e200 / 1e-300.
    const Eigen::VectorXd err = Y.col(o) - p.mean.col(o);
    s.rmse.push_back(err.stableNorm() / std::sqrt(n));
    if (p.var.size() == 0) {
      s.nllh.push_back(std::numeric_limits<double>::infinity());
    } else {
      const Eigen::ArrayXd v = p.var.col(o).array();
      const Eigen::ArrayXd z = err.array() / v.sqrt();
      s.nllh.push_back((0.5 * (std::log(2.0 * M_PI) + v.log()) + 0.5 * z.square()).sum() / n);
    }
  }
  return s;
}

Summary summarize(const std::vector<double>& values) {
  Summary s;
  if (values.empty()) return s;
  s.min = *std::min_element(values.begin(), values.end());
  s.max = *std::max_element(values.begin(), values.end());
  if (s.min == s.max) {
    // Identical repetitions (a deterministic learner, or +inf NLLH without a variance):
    // the mean is the value and the spread exactly 0, not a rounding residue or NaN.
    s.mean = s.min;
    return s;
  }
  double sum = 0;
  for (double v : values) sum += v;
  s.mean = sum / static_cast<double>(values.size());
  if (std::isinf(s.mean)) return s;
  double sq = 0;
  for (double v : values) sq += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(sq / static_cast<double>(values.size()));
  return s;
}

std::vector<Eigen::Index> strided_rows(Eigen::Index rows, Eigen::Index max) {
  const Eigen::Index stride = max > 0 && rows > max ? (rows + max - 1) / max : 1;
  std::vector<Eigen::Index> idx;
  for (Eigen::Index i = 0; i < rows; i += stride) idx.push_back(i);
  return idx;
}

}  // namespace spml
