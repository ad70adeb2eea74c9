// Exact Gaussian-process regression with an ARD RBF kernel, a Gaussian likelihood and an
// optional linear-in-parameters mean m_o(x) = phi_o(x) . theta (the semi-parametric GP).
//
// Several outputs can share one kernel: their log marginal likelihoods are summed, so the
// log-determinant is counted once per output while one Cholesky factor serves them all.
// Dense linear algebra goes to LAPACK/BLAS (OpenBLAS in the default build): one likelihood
// and gradient costs one Cholesky plus one inverse, about n^3 flops.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

namespace spml::gp {

// Parameter vector of the likelihood, all kernel terms in log space:
//   [log l_1 .. log l_d, log sf2, log sn2, theta_1 .. theta_M]
// (theta only when the likelihood has a mean model).
struct Hyper {
  Eigen::VectorXd lengthscales;   // d
  double signal_var = 1.0;        // sf2
  double noise_var = 1.0;         // sn2
  Eigen::VectorXd theta;          // M (empty without a mean model)
};
Eigen::VectorXd pack(const Hyper& h);
Hyper unpack(const Eigen::VectorXd& p, int inputs, int params);

// The log marginal likelihood of Y (n x O) given X (n x d) and, optionally, the mean
// model's regressor phi ((O*n) x M, row o*n+i = phi_o(x_i)).
class Likelihood {
 public:
  Likelihood(Eigen::MatrixXd X, Eigen::MatrixXd Y, Eigen::MatrixXd phi = {});
  int inputs() const { return static_cast<int>(X_.cols()); }
  int outputs() const { return static_cast<int>(Y_.cols()); }
  int params() const { return static_cast<int>(phi_.cols()); }
  int size() const { return inputs() + 2 + params(); }
  // Returns the LML; fills its gradient w.r.t. the packed parameters when grad != nullptr.
  double evaluate(const Eigen::VectorXd& p, Eigen::VectorXd* grad);
  // The theta that maximises the LML for the kernel terms of p (a generalised least-squares
  // solve: the LML is quadratic in theta).
  Eigen::VectorXd best_theta(const Eigen::VectorXd& p);
  // Largest jitter the Cholesky ladder had to add so far (0 when never needed).
  double max_jitter() const { return max_jitter_; }
  // The same likelihood over the given rows only (phi's row blocks of every output kept).
  Likelihood subset(const std::vector<Eigen::Index>& rows) const;
  const Eigen::MatrixXd& X() const { return X_; }
  const Eigen::MatrixXd& Y() const { return Y_; }
  const Eigen::MatrixXd& phi() const { return phi_; }

 private:
  Eigen::MatrixXd X_, Y_, phi_;
  Eigen::MatrixXd kf_, a_;   // n x n work matrices (noise-free kernel; factor / inverse)
  double max_jitter_ = 0.0;
};

struct FitOptions {
  int max_evals = 1000;
  double ftol_rel = 2.2e-9;      // scipy L-BFGS-B's default factr 1e7 * eps
  double noise_floor = 1e-6;     // lower bound on the noise variance
  bool learn_mean = false;       // optimise theta jointly (SPGP); else it stays fixed
  // With learn_mean: after L-BFGS stops, theta jumps to its exact conditional optimum
  // (best_theta) and L-BFGS resumes, while that raises the LML, at most this many times.
  // L-BFGS alone can stall where a large, smooth kernel has absorbed part of the model.
  int theta_refinements = 3;
  // With learn_mean: fit the kernel terms first with theta held at its start, then jointly.
  // Meant for a start that is a model already (a prior): from zeros the kernel takes it all.
  bool kernel_first = false;
  // Staged fit for large n (0: off). With n > 1.5 * subset_rows, the hyper-parameters are
  // first fitted to convergence on an evenly strided subset of subset_rows rows (cheap: the
  // cost is cubic in n), then refined on all rows with at most final_evals evaluations,
  // which is where the LML is measured. Prediction always uses every row.
  int subset_rows = 0;
  int final_evals = 6;
  // Called after every likelihood evaluation with the fraction of fit()'s work done so far, a
  // best estimate (see fit_work), and with the fraction at which fit() returns when it ends.
  // The work counts one posterior on all rows after the fit (half an evaluation), which the
  // caller builds; the caller reports the rest. May be empty.
  std::function<void(double)> progress;
};

// The work fit() is expected to do, in flops: per stage, its evaluations times the cost of
// one on its rows (n^2 (n + 1500): the n^3 of the factorisation and inverse, and the per-entry
// work on the n x n kernel), plus half an evaluation on all rows for the posterior. A stage run to convergence is expected to take min(max_evals,
// 4 (parameters optimised) + 10) evaluations (SimDyn: 50 for the zero-mean GP's 11, 102 for
// SPGP's 28 measured); the staged fit's last stage takes final_evals. The basis of progress.
double fit_work(Eigen::Index rows, int inputs, int params, const FitOptions& options);
// Whether fit() on n rows runs staged (a subset first, then all rows), as subset_rows asks.
bool staged(Eigen::Index n, const FitOptions& options);

struct FitResult {
  Hyper hyper;
  double lml = 0.0;
  int evaluations = 0;                  // on all rows
  int subset_evaluations = 0;           // on the subset (staged fit only)
  std::string stop;                     // NLopt's reason, e.g. "FTOL_REACHED"
  std::vector<std::string> warnings;    // abnormal stops, jitter, failed evaluations
};

// Maximises the LML from `start` with NLopt's L-BFGS in log space, analytic gradients
// (staged through a subset first when options.subset_rows asks for it).
FitResult fit(Likelihood& lik, const Hyper& start, const FitOptions& options);

// The posterior for fixed hyper-parameters, for prediction.
class Posterior {
 public:
  Posterior(const Likelihood& lik, const Hyper& hyper);
  // phi_star: (O*m) x M regressor of the query points (ignored without a mean model).
  // mean, var: m x O; var is the predictive variance of an observation (noise included).
  void predict(const Eigen::MatrixXd& Xs, const Eigen::MatrixXd& phi_star, Eigen::MatrixXd* mean,
               Eigen::MatrixXd* var) const;
  double jitter() const { return jitter_; }

 private:
  Eigen::MatrixXd X_, L_, alpha_;
  Hyper h_;
  double jitter_ = 0.0;
};

// Exactly `count` of n rows (all n when count >= n), evenly spaced from the first. (The host's
// spml::strided_rows caps a split with a whole-number stride instead, often fewer rows.)
std::vector<Eigen::Index> evenly_spaced_rows(Eigen::Index n, Eigen::Index count);

// The ARD RBF kernel between rows of X (n x d) and rows of Xs (m x d): n x m.
Eigen::MatrixXd cross_kernel(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Xs, const Hyper& h);

// Titsias' (2009) variational sparse GP with the mean model phi . theta, for data an exact
// GP cannot hold: m inducing inputs Z, the optimal q(u) in closed form, O(n m^2) time and
// O(m^2 + block * m) memory (the rows are streamed in blocks). The kernel terms of `hyper`
// are used as given; theta is the maximiser of the collapsed bound (a generalised
// least-squares solve under Q + sn2 I, Q = K_nm K_mm^-1 K_mn; the trace term does not
// depend on theta).
class SparsePosterior {
 public:
  SparsePosterior(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, const Eigen::MatrixXd& phi, Eigen::MatrixXd Z,
                  const Hyper& hyper);
  // As Posterior::predict: phi_star (O*m) x M, mean and var (noise included) rows x O.
  void predict(const Eigen::MatrixXd& Xs, const Eigen::MatrixXd& phi_star, Eigen::MatrixXd* mean,
               Eigen::MatrixXd* var) const;
  const Eigen::VectorXd& theta() const { return h_.theta; }
  double bound() const { return bound_; }   // the collapsed evidence lower bound at theta

 private:
  Eigen::MatrixXd Z_, L_, LS_, w_;   // chol(K_mm), chol(sn2 I + V V^T), S^-1 V r per output
  Hyper h_;
  double bound_ = 0.0;
};

// Factorises K + noise*I (lower triangle of K used) into `factor` (lower Cholesky factor).
// A numerically singular matrix is retried with the jitter ladder
// (sf2 + sn2) * 1e-10, 1e-9, ..., 1e-4 added to the diagonal. Returns the jitter used;
// throws std::runtime_error when even the last rung fails.
double cholesky_with_jitter(const Eigen::MatrixXd& K, double noise, double scale, Eigen::MatrixXd& factor);

}  // namespace spml::gp
