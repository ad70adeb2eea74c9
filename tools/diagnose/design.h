// The least-squares machinery of diagnose: a stacked design of column blocks (the base
// parameters, and one block per cause) over the fit and test rows of a dataset.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

namespace spml::diagnose_detail {

// Columns of one block on one split, stored per output (rows o*N .. o*N+N-1 of the stacked
// design): outputs that are all zero are not stored, since most effects act on one joint.
struct BlockColumns {
  Eigen::Index rows_per_output = 0;
  int outputs = 0, cols = 0;
  std::vector<int> active;                 // outputs with a nonzero part
  std::vector<Eigen::MatrixXd> parts;      // per active output: rows_per_output x cols
  Eigen::MatrixXd dense() const;           // the full stacked block
  Eigen::VectorXd times(const Eigen::VectorXd& x) const;   // block * x, stacked
  static BlockColumns from_dense(const Eigen::MatrixXd& M, Eigen::Index rows_per_output, int outputs);
};

// A block built row by row (a plugin's regressor or simulated force along a split), each
// output's part allocated at its first nonzero entry: a force plugin acts on its own joints,
// and a stacked matrix over every output was most of a shape or stateful evaluation's cost on
// long logs (14 560 rows x 7 outputs on the undecimated Panda).
class BlockBuilder {
 public:
  BlockBuilder(Eigen::Index rows_per_output, int outputs, int cols);
  void set(int output, Eigen::Index row, int col, double v) {
    if (v == 0 && parts_[static_cast<size_t>(output)].size() == 0) return;
    part(output)(row, col) = v;
  }
  bool all_finite() const;
  // The block, each part passed through `filter` first (parts that are then all zero dropped).
  template <typename Filter>
  BlockColumns finish(Filter&& filter) && {
    BlockColumns b;
    b.rows_per_output = rows_;
    b.outputs = static_cast<int>(parts_.size());
    b.cols = cols_;
    for (size_t o = 0; o < parts_.size(); ++o) {
      if (parts_[o].size() == 0) continue;
      filter(parts_[o]);
      if (parts_[o].cwiseAbs().maxCoeff() == 0) continue;
      b.active.push_back(static_cast<int>(o));
      b.parts.push_back(std::move(parts_[o]));
    }
    return b;
  }

 private:
  Eigen::MatrixXd& part(int output);
  Eigen::Index rows_;
  int cols_;
  std::vector<Eigen::MatrixXd> parts_;
};

// A least-squares fit of target y on the concatenated blocks, with columns scaled to unit norm
// and a rank-revealing QR; columns the data leave undetermined get 0 (for the base block:
// the prior) and an infinite standard error.
struct Factors;
struct Fit {
  Eigen::VectorXd coef, stderr_;
  // The coefficients' covariance (cols x cols; the ordinary or, with hac_rows_per_output, the
  // autocorrelation-robust one that stderr_ is the diagonal of); zero where not determined.
  Eigen::MatrixXd cov;
  bool robust = false;   // cov is the autocorrelation-robust one
  std::vector<bool> determined;
  int rank = 0;
  double rss = 0;
  Eigen::VectorXd residual;   // y - F coef on the fit rows
  // The orthonormal basis of the determined columns on the fit rows (rows x rank), formed on
  // first use from the factorization the fit keeps (want_basis): most fits are trials that
  // never need it, and forming it costs as much as the factorization. Safe to call from
  // several threads.
  const Eigen::MatrixXd& Q() const;
  std::shared_ptr<const Factors> factors;
  mutable std::shared_ptr<const Eigen::MatrixXd> basis;
};
// hac_rows_per_output > 0: standard errors robust to autocorrelation within each output's
// rows (statistics.h), else the ordinary ones (white residuals).
Fit fit_blocks(const std::vector<const BlockColumns*>& blocks, const Eigen::VectorXd& y, bool want_basis, Eigen::Index hac_rows_per_output = 0);

// The residual sum of squares of y on the blocks' columns, and nothing else: the normal
// equations (one product over the rows, where fit_blocks' QR sweeps them column by column),
// the residual formed from the coefficients and refined once, so that their rounding enters
// it only to second order. For searches that evaluate the minimum many times (estimate_delay:
// a hundred designs of 10^5 rows); what is reported comes from fit_blocks.
double rss_of(const std::vector<const BlockColumns*>& blocks, const Eigen::VectorXd& y);

// The instrumental-variable fit (IDIM-IV, spml/envs/instruments.h) of y on the blocks, with
// instruments `inst` laid out like them (the same blocks on the model's simulated states):
// coef = (Z^T F)^-1 Z^T y over the columns least squares determines (the others as in
// fit_blocks), standard errors the sandwich (Z^T F)^-1 S (F^T Z)^-1, S the long-run
// covariance of the rows z_i r_i (hac_rows_per_output > 0) or sigma^2 Z^T Z. The residual is
// y - F coef; no basis.
Fit iv_fit_blocks(const std::vector<const BlockColumns*>& blocks, const std::vector<const BlockColumns*>& inst, const Eigen::VectorXd& y,
                  Eigen::Index hac_rows_per_output);

// What adding block C to a fit with basis Q and residual r gains: the drop of the residual
// sum of squares and the number of new independent directions (rank increase).
struct Gain {
  double rss_drop = 0;
  int rank = 0;
  Eigen::VectorXd coef;   // the columns' least-squares coefficients (minimum norm where they are collinear with Q)
};
Gain gain_of(const BlockColumns& C, const Eigen::MatrixXd& Q, const Eigen::VectorXd& r);

// Weighted least squares across outputs (joints): each output's rows scaled by w[o]. A stacked
// fit in N m weighs a wrist joint's rows by nothing beside a base joint's hundredfold torque, and
// the parameters the wrist's torque alone pins down follow the base joint's noise instead
// (written_parameters.cc says where that wrote a worse model).
// The weights: sigma / sigma_o, sigma_o the RMS of residual r on output o (floored at 1e-3
// sigma), sigma the RMS over all rows, so that a residual of that shape keeps its sum of squares.
Eigen::VectorXd output_weights(const Eigen::VectorXd& r, Eigen::Index rows_per_output);
Eigen::VectorXd scale_outputs(const Eigen::VectorXd& y, const Eigen::VectorXd& w, Eigen::Index rows_per_output);
void scale_outputs_in_place(Eigen::MatrixXd& M, const Eigen::VectorXd& w, Eigen::Index rows_per_output);

// The prediction of blocks with coefficients coef (concatenated in block order).
Eigen::VectorXd predict_blocks(const std::vector<const BlockColumns*>& blocks, const Eigen::VectorXd& coef,
                               Eigen::Index rows);

}  // namespace spml::diagnose_detail
