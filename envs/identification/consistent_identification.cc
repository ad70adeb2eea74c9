#include "spml/envs/consistent_identification.h"

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <nlopt.hpp>
#include <numeric>
#include <algorithm>
#include <stdexcept>

#include "consistent_objective.h"

namespace spml {
namespace {

using identification::ConsistentObjective;
using identification::Layout;

// ||W pi - tau||^2 = ||R pi - z||^2 + rest, from a column-pivoted QR of W with unit-norm
// columns (its rank is the number of directions the data see).
struct Reduced {
  Eigen::MatrixXd R;
  Eigen::VectorXd z;
  int rank = 0;
  double rss_least_squares = 0;   // the residual of the unconstrained least-squares fit
};
Reduced reduce(const Eigen::MatrixXd& W, const Eigen::VectorXd& tau, const Eigen::VectorXd& norms) {
  const Eigen::VectorXd scale = (norms.array() > 0).select(norms, 1.0);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(W * scale.cwiseInverse().asDiagonal());
  qr.setThreshold(1e-8);   // as MjcfRegressor::base_parameters
  const Eigen::VectorXd Qt = qr.householderQ().adjoint() * tau;
  const Eigen::Index k = std::min(W.rows(), W.cols());
  Reduced out;
  out.rank = static_cast<int>(qr.rank());
  const Eigen::MatrixXd Rk = qr.matrixR().topRows(k).triangularView<Eigen::Upper>();
  // W = Q R P^T D with D the column scales.
  out.R = (Rk * qr.colsPermutation().transpose()) * scale.asDiagonal();
  out.z = Qt.head(k);
  out.rss_least_squares = Qt.tail(W.rows() - out.rank).squaredNorm();
  return out;
}

// Which standard parameters are fitted; the others keep the MJCF's values, with a note why.
// Extra columns (past the standard parameters) are free terms, fitted where the data see them.
Layout make_layout(const MjcfRegressor& reg, const Eigen::VectorXd& norms, std::vector<std::string>& body_notes,
                   std::vector<bool>& term_fitted) {
  Layout L;
  const int nb = reg.model()->nbody - 1, p = static_cast<int>(reg.param_names().size());
  for (int b = 0; b < nb; ++b) {
    if (!(norms.segment<10>(10 * b).maxCoeff() > 0))
      body_notes.push_back("not moved by any joint in the data (its regressor columns are zero): kept");
    else if (!realizable(reg.model_params().segment<10>(10 * b)))
      body_notes.push_back("the MJCF's inertial is not realizable (zero mass or a degenerate inertia): kept");
    else {
      body_notes.emplace_back();
      L.bodies.push_back(b);
    }
  }
  for (int k = 10 * nb; k < p; ++k) {
    const std::string& name = reg.param_names()[static_cast<size_t>(k)];
    term_fitted.push_back(norms[k] > 0);
    if (!term_fitted.back()) continue;
    L.terms.push_back(k);
    L.bounded.push_back(joint_attribute_term(name).has_value());
  }
  for (auto k = static_cast<int>(p); k < norms.size(); ++k)
    if (norms[k] > 0) {
      L.terms.push_back(k);
      L.bounded.push_back(false);
    }
  return L;
}

struct Minimum {
  Eigen::VectorXd theta;
  int evaluations = 0;
  std::string stop;
};

const char* reason(nlopt::result r) {
  switch (r) {
    case nlopt::FTOL_REACHED: return "FTOL_REACHED";
    case nlopt::XTOL_REACHED: return "XTOL_REACHED";
    case nlopt::MAXEVAL_REACHED: return "MAXEVAL_REACHED";
    case nlopt::MAXTIME_REACHED: return "MAXTIME_REACHED";
    default: return "SUCCESS";
  }
}

// One round of NLopt's L-BFGS in w, theta = theta_c + T w: the data see some directions a
// million times more sharply than the prior holds the others, so T whitens the Gauss-Newton
// Hessian H at theta_c. The bounded joint terms B keep their own axes (so that their bounds stay
// bounds on w): theta_A = theta_cA + M u + K D v, theta_B = theta_cB + D v, with
// M^T H_AA M = 1, K = -H_AA^-1 H_AB and D the inverse square root of the diagonal of the
// Schur complement H_BB + H_BA K, which makes w's Hessian block diagonal with unit diagonal.
struct Round {
  const ConsistentObjective* obj;
  Eigen::VectorXd theta_c;
  Eigen::MatrixXd T;
  Minimum* best;
  double fbest = HUGE_VAL;
};

Eigen::MatrixXd whitening(const Eigen::MatrixXd& H, const std::vector<bool>& is_bounded) {
  std::vector<Eigen::Index> A, B;
  for (Eigen::Index k = 0; k < H.rows(); ++k) (is_bounded[static_cast<size_t>(k)] ? B : A).push_back(k);
  const Eigen::MatrixXd HAA = H(A, A), HAB = H(A, B), HBB = H(B, B);
  const auto na = static_cast<Eigen::Index>(A.size()), nbd = static_cast<Eigen::Index>(B.size());
  // Cholesky of H_AA with its diagonal first scaled to one.
  const Eigen::VectorXd s = HAA.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::LLT<Eigen::MatrixXd> llt(s.asDiagonal() * HAA * s.asDiagonal() + 1e-12 * Eigen::MatrixXd::Identity(na, na));
  const Eigen::MatrixXd M = s.asDiagonal() * Eigen::MatrixXd(llt.matrixU()).triangularView<Eigen::Upper>().solve(Eigen::MatrixXd::Identity(na, na));
  const Eigen::MatrixXd K = -(s.asDiagonal() * llt.solve(s.asDiagonal() * HAB));
  const Eigen::VectorXd D = (HBB + HAB.transpose() * K).diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(H.rows(), H.cols());
  for (Eigen::Index i = 0; i < na; ++i) {
    for (Eigen::Index j = 0; j < na; ++j) T(A[i], A[j]) = M(i, j);
    for (Eigen::Index j = 0; j < nbd; ++j) T(A[i], B[j]) = K(i, j) * D[j];
  }
  for (Eigen::Index j = 0; j < nbd; ++j) T(B[j], B[j]) = D[j];
  return T;
}

double round_objective(unsigned n, const double* w, double* grad, void* data) {
  auto* c = static_cast<Round*>(data);
  const Eigen::VectorXd th = c->theta_c + c->T * Eigen::Map<const Eigen::VectorXd>(w, n);
  Eigen::VectorXd g;
  const double v = c->obj->value(th, grad ? &g : nullptr);
  ++c->best->evaluations;
  if (!std::isfinite(v) || (grad && !g.allFinite())) {
    if (grad) std::fill(grad, grad + n, 0.0);
    return HUGE_VAL;
  }
  if (grad) Eigen::Map<Eigen::VectorXd>(grad, n) = c->T.transpose() * g;
  if (v < c->fbest) c->fbest = v, c->best->theta = th;
  return v;
}

// Rounds of whitened L-BFGS from best.theta until a round gains nothing.
void minimise(const ConsistentObjective& obj, double sigma, const ConsistentOptions& o, std::chrono::steady_clock::time_point t0,
              Minimum& best) {
  const auto n = best.theta.size();
  const Layout& L = obj.layout();
  std::vector<bool> is_bounded(10 * L.bodies.size(), false);
  is_bounded.insert(is_bounded.end(), L.bounded.begin(), L.bounded.end());
  double f_prev = obj.value(best.theta);
  for (int round = 0; round < 40; ++round) {
    Round r{&obj, best.theta, whitening(obj.hessian(best.theta, sigma), is_bounded), &best, f_prev};
    std::vector<double> lower(static_cast<size_t>(n), -HUGE_VAL);
    for (Eigen::Index k = 0; k < n; ++k)
      if (is_bounded[static_cast<size_t>(k)]) lower[static_cast<size_t>(k)] = std::min(0.0, -r.theta_c[k] / r.T(k, k));
    nlopt::opt opt(nlopt::LD_LBFGS, static_cast<unsigned>(n));
    opt.set_min_objective(round_objective, &r);
    opt.set_lower_bounds(lower);
    opt.set_ftol_rel(1e-15);
    opt.set_xtol_rel(1e-12);
    opt.set_vector_storage(20);
    opt.set_maxeval(std::max(1, std::min(1000, o.max_evaluations - best.evaluations)));   // then re-whiten
    const double left = o.max_seconds - std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    opt.set_maxtime(std::max(left, 1e-3));
    std::vector<double> w(static_cast<size_t>(n), 0.0);
    double value = 0;
    try {
      best.stop = reason(opt.optimize(w, value));
    } catch (const nlopt::roundoff_limited&) {
      best.stop = "ROUNDOFF_LIMITED";   // at the optimum to the precision the objective has
    } catch (const std::runtime_error& e) {
      // NLopt's L-BFGS gives up when its line search fails on the curved valley; the next
      // round starts again from the best point, whitened there.
      best.stop = std::string("FAILURE: ") + e.what();
    }
    for (Eigen::Index k = 0; k < n; ++k)   // theta_B = theta_cB + D v >= 0 up to rounding
      if (is_bounded[static_cast<size_t>(k)]) best.theta[k] = std::max(best.theta[k], 0.0);
    const bool converged = r.fbest >= f_prev - 1e-12 * std::fabs(f_prev);
    f_prev = std::min(f_prev, r.fbest);
    if (converged) best.stop = "CONVERGED";   // a whole round gained less than 1e-12 of the objective
    if (converged || best.evaluations >= o.max_evaluations || best.stop == "MAXTIME_REACHED") break;
  }
}

std::string body_name(const MjcfRegressor& reg, int b) {
  const std::string& n = reg.param_names()[static_cast<size_t>(10 * b)];   // "m:<body>"
  return n.substr(n.find(':') + 1);
}

// Per-body and per-term results from the fit and the covariance of pi.
void describe(const MjcfRegressor& reg, const std::vector<std::string>& body_notes, const std::vector<bool>& term_fitted,
              const Layout& L, const ConsistentOptions& o, ConsistentIdentification& out) {
  const int nb = reg.model()->nbody - 1;
  for (int b = 0; b < nb; ++b) {
    ConsistentBody body;
    body.name = body_name(reg, b);
    body.body_id = b + 1;
    body.note = body_notes[static_cast<size_t>(b)];
    body.fitted = body.note.empty();
    const Vector10d p0 = out.prior.segment<10>(10 * b), p = out.pi.segment<10>(10 * b);
    if (p0[0] > 0) body.prior = body_inertial(p0);
    body.identified = body.fitted ? body_inertial(p) : body.prior;
    if (body.fitted) {
      body.std_error = body_inertial_std_errors(p, out.covariance.block<10, 10>(10 * b, 10 * b));
      const Vector10d diff = mjcf_quantities(body.identified) - mjcf_quantities(body.prior);
      for (int k = 0; k < 10; ++k)
        if (body.std_error[k] > 0) body.max_z = std::max(body.max_z, std::fabs(diff[k]) / body.std_error[k]);
      body.changed = body.max_z > o.change_z;
    }
    out.bodies.push_back(body);
  }
  size_t t = 0, fitted = 0;
  for (auto k = static_cast<Eigen::Index>(10 * nb); k < out.pi.size(); ++k, ++t) {
    ConsistentTerm term;
    term.name = reg.param_names()[static_cast<size_t>(k)];
    term.value = out.pi[k];
    term.prior = out.prior[k];
    term.fitted = term_fitted[t];
    term.std_error = std::sqrt(std::max(out.covariance(k, k), 0.0));
    if (term.fitted) term.at_bound = L.bounded[fitted++] && term.value <= 0;
    out.terms.push_back(term);
  }
}

}  // namespace

Eigen::MatrixXd stacked_standard_regressor(const MjcfRegressor& reg, const RowMatrix& X, const JointColumns& cols,
                                           const std::string& where) {
  MjcfRegressor::Base all;   // every standard parameter kept as a column
  all.rank = static_cast<int>(reg.param_names().size());
  all.independent.resize(static_cast<size_t>(all.rank));
  std::iota(all.independent.begin(), all.independent.end(), 0);
  return stacked_base_regressor(reg, all, X, cols, where);
}

ConsistentIdentification fit_consistent(const MjcfRegressor& reg, const Eigen::MatrixXd& W_standard, const Eigen::VectorXd& tau,
                                        const ConsistentOptions& o, const Eigen::MatrixXd& extra) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto p = static_cast<Eigen::Index>(reg.param_names().size());
  if (extra.cols() > 0 && extra.rows() != W_standard.rows())
    throw std::runtime_error("consistent identification: " + std::to_string(extra.rows()) + " rows of extra columns for " +
                             std::to_string(W_standard.rows()) + " rows of the regressor");
  Eigen::MatrixXd W_joined;
  if (extra.cols() > 0) {
    W_joined.resize(W_standard.rows(), W_standard.cols() + extra.cols());
    W_joined << W_standard, extra;
  }
  const Eigen::MatrixXd& W = extra.cols() > 0 ? W_joined : W_standard;
  if (W_standard.cols() != p || W.rows() != tau.size() || W.rows() == 0)
    throw std::runtime_error("consistent identification: the regressor has " + std::to_string(W.cols()) + " columns and " +
                             std::to_string(W.rows()) + " rows for " + std::to_string(p) + " parameters and " +
                             std::to_string(tau.size()) + " torques");
  if (!W.allFinite() || !tau.allFinite()) throw std::runtime_error("consistent identification: the regressor or the torques are not finite");
  if (!(o.prior_weight > 0)) throw std::runtime_error("consistent identification: the prior weight must be > 0");
  const Eigen::VectorXd norms = W.colwise().norm().transpose();
  const Reduced red = reduce(W, tau, norms);
  const double dof = static_cast<double>(W.rows() - red.rank);
  if (dof < 1)
    throw std::runtime_error("consistent identification: " + std::to_string(W.rows()) + " equations for " + std::to_string(red.rank) +
                             " directions the data see: too few to fit them and estimate the noise");
  const double rms = std::sqrt(tau.squaredNorm() / static_cast<double>(tau.size()));
  const double floor = std::max(o.sigma_floor * rms, 1e-300);
  ConsistentIdentification out;
  out.sigma_objective = std::max(std::sqrt(red.rss_least_squares / dof), floor);
  out.rank = red.rank;
  out.prior = Eigen::VectorXd::Zero(W.cols());   // extra columns: toward 0, worth lambda equations like every term
  out.prior.head(p) = reg.model_params();
  out.prior_weight = o.prior_weight;
  std::vector<std::string> body_notes;
  std::vector<bool> term_fitted;
  const Layout L = make_layout(reg, norms, body_notes, term_fitted);
  auto objective = [&](double sigma) {
    Eigen::VectorXd w(static_cast<Eigen::Index>(L.terms.size()));
    for (size_t t = 0; t < L.terms.size(); ++t)
      w[static_cast<Eigen::Index>(t)] = o.prior_weight * norms[L.terms[t]] * norms[L.terms[t]] / (static_cast<double>(W.rows()) * sigma * sigma);
    return ConsistentObjective(L, red.R, red.z, sigma, out.prior, w, o.prior_weight);
  };
  const ConsistentObjective obj = objective(out.sigma_objective);
  Minimum min{obj.start(), 0, ""};
  // Continuation in sigma, from 10 % of the torques' RMS down by tenfold steps: the sharper the
  // data, the narrower and more curved (in psi) the valley of parameters that fit them, which
  // L-BFGS follows slowly; each step starts next to its own optimum.
  for (double s = std::max(0.1 * rms, out.sigma_objective);; s = std::max(0.1 * s, out.sigma_objective)) {
    minimise(s == out.sigma_objective ? obj : objective(s), s, o, t0, min);
    if (s == out.sigma_objective) break;
  }
  out.evaluations = min.evaluations;
  out.stop = min.stop;
  Eigen::MatrixXd Jt;
  out.pi = obj.standard(min.theta, &Jt);
  out.sigma = std::sqrt((W * out.pi - tau).squaredNorm() / dof);
  // Posterior covariance with the fit's own noise level (the prior's weights as fitted).
  const Eigen::MatrixXd H = obj.hessian(min.theta, std::max(out.sigma, floor));
  const Eigen::MatrixXd cov = H.ldlt().solve(Eigen::MatrixXd::Identity(H.rows(), H.cols()));
  out.covariance = Jt * cov * Jt.transpose();
  if (extra.cols() > 0) {   // split the extra columns' coefficients off
    out.extra = out.pi.tail(extra.cols());
    out.extra_std_error = out.covariance.diagonal().tail(extra.cols()).cwiseMax(0.0).cwiseSqrt();
    out.pi.conservativeResize(p);
    out.prior.conservativeResize(p);
    out.covariance.conservativeResize(p, p);
  }
  describe(reg, body_notes, term_fitted, L, o, out);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

ConsistentIdentification identify_consistent(const MjcfRegressor& reg, const Dataset& ds, const std::string& split,
                                             const ConsistentOptions& o) {
  const std::string src = ds.source.empty() ? "" : ds.source + ": ";
  auto stack = [&](const Split& s, Eigen::MatrixXd& W, Eigen::VectorXd& tau) {
    try {
      W = stacked_standard_regressor(reg, s.X, JointColumns(reg, s), s.name);
    } catch (const DatasetError& e) {
      throw DatasetError(src + e.what());
    }
    tau = stacked_torques(s, ds.source);
  };
  Eigen::MatrixXd W;
  Eigen::VectorXd tau;
  const Split& train = ds.get(split);
  stack(train, W, tau);
  ConsistentIdentification out;
  try {
    out = fit_consistent(reg, W, tau, o);
  } catch (const std::runtime_error& e) {
    throw DatasetError(src + "split '" + split + "': " + e.what());
  }
  auto score = [&](const Split& s, const Eigen::MatrixXd& Ws, const Eigen::VectorXd& ts) {
    const Eigen::VectorXd r = ts - Ws * out.pi;
    out.errors.push_back({s.name, s.rows(), r.norm() / ts.norm(), std::sqrt(r.squaredNorm() / static_cast<double>(ts.size()))});
  };
  score(train, W, tau);
  for (const Split& s : ds.splits) {
    if (s.name == split) continue;
    stack(s, W, tau);
    score(s, W, tau);
  }
  return out;
}

}  // namespace spml
