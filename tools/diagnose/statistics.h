// Statistics that hold on autocorrelated residuals (real logs, filtered signals): an effective
// sample size for the information criterion and autocorrelation-robust standard errors.
//
// Long-run variances are estimated by non-overlapping batch means, the blocks as long as
// Andrews' (1991) automatic bandwidth for the Bartlett kernel under an AR(1) fit of each
// output's residual: a HAC estimator in the family of Newey & West (1987), cheap enough for
// every refit (n x rank work instead of n x rank^2 per lag).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace spml::diagnose_detail {

// The block length for one output's residual segment r (Andrews' rule, 1..N/4).
Eigen::Index hac_block_length(const Eigen::Ref<const Eigen::VectorXd>& r);

// n_eff / n for a stacked residual (outputs of N rows each): sum of squares over long-run
// variance, per output, pooled; 1 for white residuals, small for smooth ones.
double effective_fraction(const Eigen::VectorXd& r, Eigen::Index N);

// Long-run covariance of the rows z_i = Z.row(i) (a stacked matrix, N rows per output), by
// batch means with each output's block length from its residual segment.
Eigen::MatrixXd long_run_covariance(const Eigen::MatrixXd& Z, const Eigen::VectorXd& r, Eigen::Index N);

// The value at position floor(share * n) of v sorted (0 when v is empty): the median at 0.5.
double quantile(std::vector<double> v, double share);

// The two-sided normal bound z that each of k independent tests must pass for the family to
// err with probability alpha: P(|Z| > z) = 1 - (1 - alpha)^(1/k) (Sidak).
double familywise_z(double alpha, int k);

}  // namespace spml::diagnose_detail
