#include "spml/gp/gp.h"

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <limits>
#include <nlopt.hpp>
#include <sstream>
#include <stdexcept>

namespace spml::gp {

// LAPACK/BLAS (Fortran ABI); OpenBLAS provides them multi-threaded.
extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void dpotri_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void dpotrs_(const char* uplo, const int* n, const int* nrhs, const double* a, const int* lda, double* b,
             const int* ldb, int* info);
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m, const int* n,
            const double* alpha, const double* a, const int* lda, double* b, const int* ldb);
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha, const double* a,
            const int* lda, const double* beta, double* c, const int* ldc);
void dsymm_(const char* side, const char* uplo, const int* m, const int* n, const double* alpha, const double* a,
            const int* lda, const double* b, const int* ldb, const double* beta, double* c, const int* ldc);
}

namespace {

constexpr double kLog2Pi = 1.8378770664093453;

// Lower triangle of the noise-free ARD RBF kernel of X with itself.
void kernel_lower(const Eigen::MatrixXd& X, const Hyper& h, Eigen::MatrixXd& K, Eigen::MatrixXd* Z_out) {
  const int n = static_cast<int>(X.rows()), d = static_cast<int>(X.cols());
  Eigen::MatrixXd Z = X * h.lengthscales.cwiseInverse().asDiagonal();
  Eigen::VectorXd sq = Z.rowwise().squaredNorm();
  K.resize(n, n);
  const double one = 1.0, zero = 0.0;
  dsyrk_("L", "N", &n, &d, &one, Z.data(), &n, &zero, K.data(), &n);   // K = Z Z^T (lower)
  for (int j = 0; j < n; ++j) {
    double* col = K.col(j).data();
    for (int i = j; i < n; ++i) {
      const double r2 = std::max(0.0, sq[i] + sq[j] - 2.0 * col[i]);
      col[i] = h.signal_var * std::exp(-0.5 * r2);
    }
  }
  if (Z_out) *Z_out = std::move(Z);
}

}  // namespace

std::vector<Eigen::Index> evenly_spaced_rows(Eigen::Index n, Eigen::Index count) {
  count = std::min(count, n);
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < count; ++i) rows.push_back(i * n / count);
  return rows;
}

Eigen::MatrixXd cross_kernel(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Xs, const Hyper& h) {
  Eigen::MatrixXd Z = X * h.lengthscales.cwiseInverse().asDiagonal();
  Eigen::MatrixXd Zs = Xs * h.lengthscales.cwiseInverse().asDiagonal();
  Eigen::VectorXd sq = Z.rowwise().squaredNorm(), sqs = Zs.rowwise().squaredNorm();
  Eigen::MatrixXd K = Z * Zs.transpose();
  for (Eigen::Index j = 0; j < K.cols(); ++j)
    for (Eigen::Index i = 0; i < K.rows(); ++i)
      K(i, j) = h.signal_var * std::exp(-0.5 * std::max(0.0, sq[i] + sqs[j] - 2.0 * K(i, j)));
  return K;
}

namespace {

// Residual of Y (n x O) after the mean model.
Eigen::MatrixXd residual(const Eigen::MatrixXd& Y, const Eigen::MatrixXd& phi, const Eigen::VectorXd& theta) {
  Eigen::MatrixXd R = Y;
  if (phi.cols() == 0) return R;
  const Eigen::Index n = Y.rows();
  Eigen::VectorXd m = phi * theta;
  for (Eigen::Index o = 0; o < Y.cols(); ++o) R.col(o) -= m.segment(o * n, n);
  return R;
}

void solve_lower(const Eigen::MatrixXd& L, Eigen::MatrixXd& B) {
  const int n = static_cast<int>(L.rows()), nrhs = static_cast<int>(B.cols());
  int info = 0;
  dpotrs_("L", &n, &nrhs, L.data(), &n, B.data(), &n, &info);
  if (info != 0) throw std::runtime_error("dpotrs failed (info " + std::to_string(info) + ")");
}

}  // namespace

Eigen::VectorXd pack(const Hyper& h) {
  const Eigen::Index d = h.lengthscales.size(), M = h.theta.size();
  Eigen::VectorXd p(d + 2 + M);
  p.head(d) = h.lengthscales.array().log().matrix();
  p[d] = std::log(h.signal_var);
  p[d + 1] = std::log(h.noise_var);
  p.tail(M) = h.theta;
  return p;
}

Hyper unpack(const Eigen::VectorXd& p, int inputs, int params) {
  Hyper h;
  h.lengthscales = p.head(inputs).array().exp().matrix();
  h.signal_var = std::exp(p[inputs]);
  h.noise_var = std::exp(p[inputs + 1]);
  h.theta = p.segment(inputs + 2, params);
  return h;
}

double cholesky_with_jitter(const Eigen::MatrixXd& K, double noise, double scale, Eigen::MatrixXd& factor) {
  const int n = static_cast<int>(K.rows());
  double jitter = 0.0;
  for (int rung = 0; rung <= 7; ++rung) {
    jitter = rung == 0 ? 0.0 : scale * std::pow(10.0, rung - 11);
    factor = K;
    factor.diagonal().array() += noise + jitter;
    int info = 0;
    dpotrf_("L", &n, factor.data(), &n, &info);
    if (info == 0) return jitter;
  }
  std::ostringstream msg;
  msg << "kernel matrix not positive definite even with jitter " << jitter << " (n=" << n << ")";
  throw std::runtime_error(msg.str());
}

Likelihood::Likelihood(Eigen::MatrixXd X, Eigen::MatrixXd Y, Eigen::MatrixXd phi)
    : X_(std::move(X)), Y_(std::move(Y)), phi_(std::move(phi)) {
  if (X_.rows() != Y_.rows()) throw std::invalid_argument("GP: X and Y row counts differ");
  if (phi_.size() > 0 && phi_.rows() != Y_.rows() * Y_.cols())
    throw std::invalid_argument("GP: regressor rows != outputs * rows");
}

Likelihood Likelihood::subset(const std::vector<Eigen::Index>& rows) const {
  const Eigen::Index n = X_.rows(), m = static_cast<Eigen::Index>(rows.size());
  Eigen::MatrixXd X(m, X_.cols()), Y(m, Y_.cols()), phi(phi_.size() ? m * Y_.cols() : 0, phi_.cols());
  for (Eigen::Index i = 0; i < m; ++i) {
    X.row(i) = X_.row(rows[static_cast<size_t>(i)]);
    Y.row(i) = Y_.row(rows[static_cast<size_t>(i)]);
    if (phi.size())
      for (Eigen::Index o = 0; o < Y_.cols(); ++o) phi.row(o * m + i) = phi_.row(o * n + rows[static_cast<size_t>(i)]);
  }
  return Likelihood(std::move(X), std::move(Y), std::move(phi));
}

double Likelihood::evaluate(const Eigen::VectorXd& p, Eigen::VectorXd* grad) {
  const int n = static_cast<int>(X_.rows()), d = inputs(), O = outputs();
  const Hyper h = unpack(p, d, params());
  Eigen::MatrixXd Z;
  kernel_lower(X_, h, kf_, &Z);
  const double jitter = cholesky_with_jitter(kf_, h.noise_var, h.signal_var + h.noise_var, a_);
  max_jitter_ = std::max(max_jitter_, jitter);

  const Eigen::MatrixXd R = residual(Y_, phi_, h.theta);
  Eigen::MatrixXd alpha = R;
  solve_lower(a_, alpha);
  double logdet_half = 0.0;
  for (int i = 0; i < n; ++i) logdet_half += std::log(a_(i, i));
  const double lml = -0.5 * R.cwiseProduct(alpha).sum() - O * logdet_half - 0.5 * O * n * kLog2Pi;
  if (!grad) return lml;

  // dLML/dh = 1/2 sum_ij W_ij dK_ij/dh with W = alpha alpha^T - O K^-1 (summed over outputs).
  int info = 0;
  dpotri_("L", &n, a_.data(), &n, &info);   // a_ = K^-1 (lower)
  if (info != 0) throw std::runtime_error("dpotri failed (info " + std::to_string(info) + ")");
  double trace_w = 0.0, sum_s = 0.0;
  const Eigen::MatrixXd at = alpha.transpose();   // O x n: column i holds alpha_i contiguously
  for (int j = 0; j < n; ++j) {
    double* s = a_.col(j).data();
    const double* k = kf_.col(j).data();
    for (int i = j; i < n; ++i) {
      double w = at.col(i).dot(at.col(j)) - O * s[i];
      if (i == j) trace_w += w;
      s[i] = w * k[i];   // S = W o Kf (lower)
      sum_s += (i == j ? 1.0 : 2.0) * s[i];
    }
  }
  // P = S [Z 1]: sum_ij S_ij (z_id - z_jd)^2 = 2 sum_i z_id^2 s_i - 2 z_d^T S z_d.
  Eigen::MatrixXd B(n, d + 1);
  B.leftCols(d) = Z;
  B.col(d).setOnes();
  Eigen::MatrixXd P(n, d + 1);
  const int cols = d + 1;
  const double one = 1.0, zero = 0.0;
  dsymm_("L", "L", &n, &cols, &one, a_.data(), &n, B.data(), &n, &zero, P.data(), &n);
  grad->resize(p.size());
  for (int k = 0; k < d; ++k)
    (*grad)[k] = Z.col(k).cwiseAbs2().dot(P.col(d)) - Z.col(k).dot(P.col(k));
  (*grad)[d] = 0.5 * sum_s;
  (*grad)[d + 1] = 0.5 * h.noise_var * trace_w;
  if (params() > 0) {
    Eigen::VectorXd g = Eigen::VectorXd::Zero(params());
    for (int o = 0; o < O; ++o) g += phi_.middleRows(static_cast<Eigen::Index>(o) * n, n).transpose() * alpha.col(o);
    grad->tail(params()) = g;
  }
  return lml;
}

Eigen::VectorXd Likelihood::best_theta(const Eigen::VectorXd& p) {
  const int n = static_cast<int>(X_.rows()), O = outputs(), M = params();
  const Hyper h = unpack(p, inputs(), M);
  kernel_lower(X_, h, kf_, nullptr);
  max_jitter_ = std::max(max_jitter_, cholesky_with_jitter(kf_, h.noise_var, h.signal_var + h.noise_var, a_));
  // theta = (sum_o phi_o^T K^-1 phi_o)^-1 sum_o phi_o^T K^-1 y_o
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(M, M);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(M);
  for (int o = 0; o < O; ++o) {
    Eigen::MatrixXd rhs(n, M + 1);
    rhs.leftCols(M) = phi_.middleRows(static_cast<Eigen::Index>(o) * n, n);
    rhs.col(M) = Y_.col(o);
    Eigen::MatrixXd sol = rhs;
    solve_lower(a_, sol);
    A += rhs.leftCols(M).transpose() * sol.leftCols(M);
    b += rhs.leftCols(M).transpose() * sol.col(M);
  }
  return A.completeOrthogonalDecomposition().solve(b);
}

namespace {

const char* nlopt_reason(nlopt::result r) {
  switch (r) {
    case nlopt::SUCCESS: return "SUCCESS";
    case nlopt::STOPVAL_REACHED: return "STOPVAL_REACHED";
    case nlopt::FTOL_REACHED: return "FTOL_REACHED";
    case nlopt::XTOL_REACHED: return "XTOL_REACHED";
    case nlopt::MAXEVAL_REACHED: return "MAXEVAL_REACHED";
    case nlopt::MAXTIME_REACHED: return "MAXTIME_REACHED";
    default: return "FAILURE";
  }
}

// The optimiser works on u with theta = s o u, s_j = 1 / rms(phi column j): it puts the
// mean coefficients on the scale of the kernel's log parameters, which L-BFGS needs.
struct Problem {
  std::function<void(int)> evaluated;   // after each evaluation, with the count so far; may be empty
  Likelihood* lik;
  Eigen::VectorXd scale;   // per packed parameter: 1 for kernel terms, s_j for theta
  bool learn_mean;
  Eigen::VectorXd fixed;   // packed parameters; theta taken from here when not learnt
  int evaluations = 0;
  double best = -std::numeric_limits<double>::infinity();
  Eigen::VectorXd best_x;
  std::vector<std::string> failures;
};

double objective(unsigned n, const double* x, double* grad, void* data) {
  auto* pr = static_cast<Problem*>(data);
  ++pr->evaluations;
  Eigen::VectorXd p = pr->fixed;
  Eigen::Map<const Eigen::VectorXd> u(x, n);
  p.head(n) = u.cwiseProduct(pr->scale.head(n));
  Eigen::VectorXd g;
  double v;
  try {
    v = pr->lik->evaluate(p, grad ? &g : nullptr);
  } catch (const std::exception& e) {
    if (pr->failures.size() < 3) pr->failures.push_back(e.what());
    throw nlopt::forced_stop();
  }
  if (!std::isfinite(v)) {
    if (pr->failures.size() < 3) pr->failures.push_back("non-finite log marginal likelihood");
    throw nlopt::forced_stop();
  }
  if (grad) {
    for (unsigned i = 0; i < n; ++i) grad[i] = g[i] * pr->scale[i];
  }
  static const bool trace = std::getenv("SPML_GP_TRACE") != nullptr;   // read once, not per evaluation
  if (trace) {
    std::fprintf(stderr, "eval %d lml %.6g jit %.3g p", pr->evaluations, v, pr->lik->max_jitter());
    for (unsigned i = 0; i < std::min(n, 12u); ++i) std::fprintf(stderr, " %.3g", p[i]);
    std::fprintf(stderr, "\n");
  }
  if (v > pr->best) {
    pr->best = v;
    pr->best_x = u;
  }
  if (pr->evaluated) pr->evaluated(pr->evaluations);
  return v;
}

// Evaluations a stage run to convergence is expected to take (FitOptions' fit_work).
double expected_evaluations(int optimised, int max_evals) {
  return std::min<double>(max_evals, 4.0 * optimised + 10.0);
}

// How much of a stage `done` evaluations are, for `expected` evaluations: linear up to 95 % at
// the expected count, then creeping towards 1 (a stage may run past the guess; the fraction
// must still grow and stay below the stage's end, which comes when the stage returns).
double stage_fraction(int done, double expected) {
  const double k = done;
  if (k <= expected) return 0.95 * k / expected;
  return 0.95 + 0.05 * (1.0 - std::exp(-(k - expected) / expected));
}

// Progress of one stage: its share [from, from + share] of the whole fit.
struct Stage {
  const std::function<void(double)>* report = nullptr;
  double from = 0, share = 0, expected = 1;
  void operator()(int done) const {
    if (report && *report) (*report)(from + share * stage_fraction(done, expected));
  }
  void end() const {
    if (report && *report) (*report)(from + share);
  }
};

FitResult fit_once(Likelihood& lik, const Hyper& start, const FitOptions& options, const Stage& stage = {}) {
  const int d = lik.inputs(), M = lik.params();
  Hyper h0 = start;
  if (h0.theta.size() != M) throw std::invalid_argument("GP fit: start theta has the wrong size");
  h0.noise_var = std::max(h0.noise_var, options.noise_floor);

  Problem pr;
  if (stage.report && *stage.report) pr.evaluated = stage;
  pr.lik = &lik;
  pr.learn_mean = options.learn_mean && M > 0;
  pr.fixed = pack(h0);
  const int n_opt = d + 2 + (pr.learn_mean ? M : 0);
  pr.scale = Eigen::VectorXd::Ones(pr.fixed.size());
  for (int j = 0; j < M; ++j) {
    const double rms = std::sqrt(lik.phi().col(j).squaredNorm() / std::max<Eigen::Index>(1, lik.phi().rows()));
    pr.scale[d + 2 + j] = rms > 0 ? 1.0 / rms : 1.0;
  }
  std::vector<double> x(n_opt), lb(n_opt, -HUGE_VAL), ub(n_opt, HUGE_VAL);
  for (int i = 0; i < n_opt; ++i) x[i] = pr.fixed[i] / pr.scale[i];
  for (int k = 0; k < d; ++k) { lb[k] = std::log(1e-3); ub[k] = std::log(1e5); }
  lb[d] = std::log(1e-8); ub[d] = std::log(1e12);
  lb[d + 1] = std::log(options.noise_floor); ub[d + 1] = std::log(1e12);

  nlopt::opt opt(nlopt::LD_LBFGS, static_cast<unsigned>(n_opt));
  opt.set_max_objective(objective, &pr);
  opt.set_lower_bounds(lb);
  opt.set_upper_bounds(ub);
  opt.set_maxeval(options.max_evals);
  opt.set_ftol_rel(options.ftol_rel);

  FitResult res;
  auto run = [&] {
    double value = 0.0;
    std::string warning;
    try {
      opt.set_maxeval(std::max(1, options.max_evals - pr.evaluations));   // one budget for all rounds
      nlopt::result r = opt.optimize(x, value);
      res.stop = nlopt_reason(r);
      if (r == nlopt::MAXEVAL_REACHED)
        warning = "L-BFGS stopped at max_evals=" + std::to_string(options.max_evals) + " before converging";
    } catch (const nlopt::roundoff_limited&) {
      res.stop = "ROUNDOFF_LIMITED";
      warning = "L-BFGS stopped abnormally: roundoff-limited (best point kept)";
    } catch (const nlopt::forced_stop&) {
      res.stop = "FORCED_STOP";
      warning = "L-BFGS stopped abnormally: evaluation failed (" +
                (pr.failures.empty() ? std::string("unknown") : pr.failures.front()) + "); best point kept";
    } catch (const std::exception& e) {
      res.stop = "FAILURE";
      warning = std::string("L-BFGS stopped abnormally: ") + e.what() + " (best point kept)";
    }
    return warning;
  };
  std::string warning = run();
  for (int round = 0; pr.learn_mean && pr.best_x.size() > 0 && round < options.theta_refinements &&
                     pr.evaluations < options.max_evals;
       ++round) {
    Eigen::VectorXd p = pr.fixed;
    p.head(n_opt) = pr.best_x.cwiseProduct(pr.scale.head(n_opt));
    try {
      p.tail(M) = lik.best_theta(p);
      if (!(lik.evaluate(p, nullptr) > pr.best + 1e-9 * std::abs(pr.best))) break;
    } catch (const std::exception&) {
      break;
    }
    for (int i = 0; i < n_opt; ++i) x[static_cast<size_t>(i)] = p[i] / pr.scale[i];
    warning = run();
  }
  if (!warning.empty()) res.warnings.push_back(warning);
  if (pr.best_x.size() == 0) {
    throw std::runtime_error("GP fit: no evaluation of the likelihood succeeded" +
                             (pr.failures.empty() ? std::string() : ": " + pr.failures.front()));
  }
  Eigen::VectorXd p = pr.fixed;
  p.head(n_opt) = pr.best_x.cwiseProduct(pr.scale.head(n_opt));
  res.hyper = unpack(p, d, M);
  res.lml = pr.best;
  res.evaluations = pr.evaluations;
  if (lik.max_jitter() > 0) {
    std::ostringstream msg;
    msg << "Cholesky needed jitter up to " << lik.max_jitter();
    res.warnings.push_back(msg.str());
  }
  stage.end();
  return res;
}

// With a mean model: the kernel terms fitted first with theta held at its start, the joint
// fit from there. From "everything at 1.0" the LML's gradient in theta dwarfs the kernel's,
// and a joint L-BFGS moves theta to absorb what the unfitted kernel cannot, into a worse
// basin (SimDyn-Ll, 1000 rows: LML 1501 against 2603 this way; test_extrap 47 Nm against 16).
bool has_kernel_first(int params, const FitOptions& options) {
  return options.learn_mean && options.kernel_first && params > 0;
}

Hyper kernel_first(Likelihood& lik, const Hyper& start, const FitOptions& options, const Stage& stage) {
  if (!has_kernel_first(lik.params(), options)) return start;
  FitOptions kernel = options;
  kernel.learn_mean = false;
  try {
    return fit_once(lik, start, kernel, stage).hyper;
  } catch (const std::exception&) {
    stage.end();
    return start;   // the joint fit reports its own failure
  }
}

// The cost of one likelihood evaluation on n rows, in flops of the n^3 factorisation and
// inverse plus the per-entry work on the n x n kernel (exp, the gradient's loop), which weighs
// as some 1500 flops an entry: measured 0.024 s at 1000 rows, 1.51 s at 5000 (SimDyn, d = 9),
// a ratio of 63 where n^3 alone says 125.
double evaluation_cost(double n) { return n * n * (n + 1500.0); }

// The stages of fit(), as work (fit_work's units) each: kernel-first, joint (on the subset when
// staged), the last stage on all rows (staged only), the posterior.
struct Plan {
  double kernel = 0, joint = 0, last = 0, posterior = 0;
  double kernel_evals = 1, joint_evals = 1, last_evals = 1;
  double total() const { return kernel + joint + last + posterior; }
};

Plan plan_of(Eigen::Index n, int inputs, int params, const FitOptions& options) {
  Plan p;
  const bool two = staged(n, options);
  const double rows = two ? static_cast<double>(evenly_spaced_rows(n, options.subset_rows).size()) : static_cast<double>(n);
  const double all = evaluation_cost(static_cast<double>(n)), cube = evaluation_cost(rows);
  const int kernel_terms = inputs + 2, learnt = kernel_terms + (options.learn_mean ? params : 0);
  if (has_kernel_first(params, options)) {
    p.kernel_evals = expected_evaluations(kernel_terms, options.max_evals);
    p.kernel = p.kernel_evals * cube;
  }
  p.joint_evals = expected_evaluations(learnt, options.max_evals);
  p.joint = p.joint_evals * cube;
  if (two) {
    p.last_evals = std::max(1, options.final_evals);
    p.last = p.last_evals * all;
  }
  p.posterior = 0.5 * all;
  return p;
}

}  // namespace

bool staged(Eigen::Index n, const FitOptions& options) {
  return options.subset_rows > 0 && static_cast<double>(n) > 1.5 * options.subset_rows;
}

double fit_work(Eigen::Index rows, int inputs, int params, const FitOptions& options) {
  return plan_of(rows, inputs, params, options).total();
}

FitResult fit(Likelihood& lik, const Hyper& start, const FitOptions& options) {
  const Eigen::Index n = lik.X().rows();
  const Plan plan = plan_of(n, lik.inputs(), lik.params(), options);
  const double total = plan.total();
  const std::function<void(double)>* report = options.progress ? &options.progress : nullptr;
  const Stage kernel_stage{report, 0.0, plan.kernel / total, plan.kernel_evals};
  const Stage joint_stage{report, plan.kernel / total, plan.joint / total, plan.joint_evals};
  if (!staged(n, options)) return fit_once(lik, kernel_first(lik, start, options, kernel_stage), options, joint_stage);
  // Evenly strided rows keep the whole trajectory's coverage at a fraction of the density.
  Likelihood sub = lik.subset(evenly_spaced_rows(n, options.subset_rows));
  FitOptions first = options;
  first.subset_rows = 0;
  const FitResult coarse = fit_once(sub, kernel_first(sub, start, first, kernel_stage), first, joint_stage);
  FitOptions last = options;
  last.subset_rows = 0;
  last.max_evals = options.final_evals;
  const Stage last_stage{report, (plan.kernel + plan.joint) / total, plan.last / total, plan.last_evals};
  FitResult res = fit_once(lik, coarse.hyper, last, last_stage);
  res.subset_evaluations = coarse.evaluations;
  static const bool trace = std::getenv("SPML_GP_TRACE") != nullptr;
  if (trace)
    std::fprintf(stderr, "staged fit: subset %d rows, %d evaluations, LML %.6g; all %ld rows, %d evaluations, LML %.6g\n",
                 options.subset_rows, coarse.evaluations, coarse.lml, static_cast<long>(n), res.evaluations, res.lml);
  // Stopping at final_evals is the plan, not a failure; the subset fit's warnings still count.
  std::vector<std::string> warnings;
  for (const auto& w : coarse.warnings) warnings.push_back("subset fit: " + w);
  for (const auto& w : res.warnings)
    if (w.find("max_evals") == std::string::npos) warnings.push_back(w);
  res.warnings = warnings;
  return res;
}

Posterior::Posterior(const Likelihood& lik, const Hyper& hyper) : X_(lik.X()), h_(hyper) {
  Eigen::MatrixXd K;
  kernel_lower(X_, h_, K, nullptr);
  jitter_ = cholesky_with_jitter(K, h_.noise_var, h_.signal_var + h_.noise_var, L_);
  L_.triangularView<Eigen::StrictlyUpper>().setZero();
  alpha_ = residual(lik.Y(), lik.phi(), h_.theta);
  solve_lower(L_, alpha_);
}

void Posterior::predict(const Eigen::MatrixXd& Xs, const Eigen::MatrixXd& phi_star, Eigen::MatrixXd* mean,
                        Eigen::MatrixXd* var) const {
  const Eigen::Index m = Xs.rows(), O = alpha_.cols();
  const int n = static_cast<int>(X_.rows());
  mean->resize(m, O);
  if (var) var->resize(m, O);
  Eigen::VectorXd prior_mean;
  if (h_.theta.size() > 0) prior_mean = phi_star * h_.theta;
  constexpr Eigen::Index kBlock = 2048;   // bounds the n x block cross-kernel in memory
  for (Eigen::Index start = 0; start < m; start += kBlock) {
    const Eigen::Index b = std::min(kBlock, m - start);
    Eigen::MatrixXd Ks = cross_kernel(X_, Xs.middleRows(start, b), h_);   // n x b
    mean->middleRows(start, b) = Ks.transpose() * alpha_;
    if (var) {
      const int bi = static_cast<int>(b);
      const double one = 1.0;
      dtrsm_("L", "L", "N", "N", &n, &bi, &one, L_.data(), &n, Ks.data(), &n);   // V = L^-1 Ks
      Eigen::VectorXd v = (h_.signal_var - Ks.colwise().squaredNorm().transpose().array()).max(0.0).matrix();
      for (Eigen::Index o = 0; o < O; ++o) var->col(o).segment(start, b) = v.array() + h_.noise_var;
    }
  }
  if (prior_mean.size() > 0)
    for (Eigen::Index o = 0; o < O; ++o) mean->col(o) += prior_mean.segment(o * m, m);
}

}  // namespace spml::gp
