// The purely parametric learners: least squares, epsilon-SVR with the model as kernel
// basis, and the model with fixed (prior / true) coefficients.
#include <linear.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <vector>

#include "learners.h"

namespace spml::builtin {
namespace {

// Least squares on the stacked regressor. The complete orthogonal decomposition gives the
// minimum-norm solution when the data do not excite every parameter (rank-deficient phi).
// Pivots below eps * max(rows, cols) of the largest count as zero, LAPACK's (and numpy's
// lstsq) rule: Eigen's default, eps * min(rows, cols), kept the rounding residue of
// proportional columns (constant X) as a direction, and theta came out ~1e15 (RMSE 6e13
// where the minimum-norm fit gives 8.0).
Eigen::VectorXd least_squares(const View& d, Eigen::Index* rank) {
  const Eigen::MatrixXd A(d.phi);
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod;
  cod.setThreshold(Eigen::NumTraits<double>::epsilon() * static_cast<double>(std::max(A.rows(), A.cols())));
  cod.compute(A);
  *rank = cod.rank();
  return cod.solve(stacked_targets(d.Y));
}

// A linear-in-parameters model with coefficients theta; subclasses decide theta.
class LinearModel : public Learner {
 public:
  void predict(const View& q, double* mean, double*) const override {
    require_columns(q);
    Eigen::VectorXd m = q.phi * theta_;
    const Eigen::Index n = q.X.rows(), O = q.outputs;
    for (Eigen::Index i = 0; i < n; ++i)
      for (Eigen::Index o = 0; o < O; ++o) mean[i * O + o] = m[o * n + i] + bias_;
  }
  Eigen::VectorXd coefficients() const override { return theta_; }

 protected:
  void require_columns(const View& q) const {
    if (q.phi.cols() != theta_.size())
      throw std::runtime_error("regressor has " + std::to_string(q.phi.cols()) + " columns, the fit had " +
                               std::to_string(theta_.size()));
  }
  Eigen::VectorXd theta_;
  double bias_ = 0.0;
};

class LeastSquares : public LinearModel {
 public:
  void fit(const View& d, const spml_learner_model& model, const Config&) override {
    require_model(d, model, "LLS");
    Eigen::Index rank = 0;
    theta_ = least_squares(d, &rank);
    if (rank < d.phi.cols())
      notes = "regressor rank " + std::to_string(rank) + " < " + std::to_string(d.phi.cols()) +
              " parameters: minimum-norm solution";
  }
};

template <bool kTruth>
class FixedCoefficients : public LinearModel {
 public:
  void fit(const View& d, const spml_learner_model& model, const Config&) override {
    const char* name = kTruth ? "LLS-simulated" : "LLS-prior";
    require_model(d, model, name);
    const double* values = kTruth ? model.truth : model.prior;
    if (!values)
      throw std::runtime_error(std::string(name) + ": the dataset's model has no " +
                               (kTruth ? "true (simulated)" : "prior") + " coefficients");
    theta_ = Eigen::Map<const Eigen::VectorXd>(values, model.params);
  }
};

// epsilon-SVR with a linear kernel on the model features, so that w is theta and the fit
// differs from LLS only by its loss (linear, epsilon-insensitive, robust to outliers). Solved
// by liblinear's dual coordinate descent (L2-regularised L1-loss SVR), the solver built for
// linear kernels: libsvm's SMO, kernel-agnostic, needed 186 s on SimDyn's 15 000 stacked rows
// and stopped at its iteration cap; this converges in well under a second there.
// Features are scaled to unit RMS before the fit (and w back afterwards), so that C acts alike
// on every coefficient; the intercept is one more unit feature (liblinear regularises it like
// the others, where libsvm leaves it free; README "SVR" has the numbers of both).
// Defaults after Cherkassky & Ma (2004):
//   C = max(|mean(y) + 3 std(y)|, |mean(y) - 3 std(y)|)
//   epsilon = 3 sigma sqrt(ln(n) / n), sigma = RMS residual of the least-squares fit.
// liblinear's L2-regularised L1-loss SVR on the features F (n x K) with an intercept:
// returns w (K) and the bias. Features are scaled to unit RMS for the solver and w back.
std::pair<Eigen::VectorXd, double> linear_svr(const Eigen::MatrixXd& F, const Eigen::VectorXd& y, double C,
                                              double epsilon, double tolerance) {
  const Eigen::Index n = F.rows(), K = F.cols();
  Eigen::VectorXd scale(K);
  for (Eigen::Index j = 0; j < K; ++j) {
    const double rms = std::sqrt(F.col(j).squaredNorm() / static_cast<double>(n));
    scale[j] = rms > 0 ? 1.0 / rms : 1.0;
  }
  // Row i: K features, the intercept feature (index K + 1, value 1) and the terminator.
  const Eigen::Index width = K + 2;
  std::vector<feature_node> nodes(static_cast<size_t>(n * width));
  std::vector<feature_node*> rows(static_cast<size_t>(n));
  std::vector<double> targets(y.data(), y.data() + n);
  for (Eigen::Index i = 0; i < n; ++i) {
    feature_node* row = &nodes[static_cast<size_t>(i * width)];
    rows[static_cast<size_t>(i)] = row;
    for (Eigen::Index j = 0; j < K; ++j) row[j] = feature_node{static_cast<int>(j + 1), F(i, j) * scale[j]};
    row[K] = feature_node{static_cast<int>(K + 1), 1.0};
    row[K + 1] = feature_node{-1, 0.0};
  }
  problem prob{static_cast<int>(n), static_cast<int>(K + 1), targets.data(), rows.data(), -1.0};
  parameter param{};
  param.solver_type = L2R_L1LOSS_SVR_DUAL;
  param.C = C;
  param.p = epsilon;
  param.eps = tolerance;
  ::set_print_string_function([](const char*) {});
  if (const char* err = ::check_parameter(&prob, &param)) throw std::runtime_error(std::string("SVR: ") + err);
  // liblinear's dual coordinate descent visits the rows in an order drawn with the C library's
  // rand(): a fixed srand makes the fit repeat, as its DETERMINISTIC flag promises (found by
  // spml check-plugin: two fits differed by 0.017 in the mean).
  std::srand(1);
  ::model* m = ::train(&prob, &param);
  std::pair<Eigen::VectorXd, double> out{Eigen::Map<const Eigen::VectorXd>(m->w, K).cwiseProduct(scale), m->w[K]};
  free_and_destroy_model(&m);
  return out;
}

class SupportVectorRegression : public LinearModel {
 public:
  void fit(const View& d, const spml_learner_model& model, const Config& config) override {
    require_model(d, model, "SVR");
    const Eigen::Index n = d.phi.rows(), M = d.phi.cols();
    const Eigen::VectorXd y = stacked_targets(d.Y);
    const double mean = y.mean();
    const double sd = std::sqrt((y.array() - mean).square().mean());
    const double C_default = std::max(std::abs(mean + 3 * sd), std::abs(mean - 3 * sd));
    Eigen::Index rank = 0;
    const Eigen::VectorXd r = y - d.phi * least_squares(d, &rank);
    const double sigma = std::sqrt(r.squaredNorm() / static_cast<double>(n));
    const double eps_default = 3.0 * sigma * std::sqrt(std::log(static_cast<double>(n)) / static_cast<double>(n));
    const double C = config.number("C", C_default > 0 ? C_default : 1.0);
    const double epsilon = config.number("epsilon", eps_default);
    const double tolerance = config.number("tolerance");
    if (!(C > 0)) throw std::runtime_error("SVR: C must be > 0");
    if (!(epsilon >= 0)) throw std::runtime_error("SVR: epsilon must be >= 0");
    const Eigen::MatrixXd basis = excited_directions(d.phi);
    if (basis.cols() == M) {
      std::tie(theta_, bias_) = linear_svr(d.phi, y, C, epsilon, tolerance);
      return;
    }
    // Constant or degenerate inputs: directions the data do not excite stay at 0, as in
    // LLS' minimum-norm fit. Unit-RMS scaling of a column that is nearly 0 in training gave
    // it a huge weight, and SVR predicted 1.8e6 N m on the arm's test split after training on
    // one repeated state (LLS: 123 N m).
    Eigen::VectorXd w;
    std::tie(w, bias_) = linear_svr(d.phi * basis, y, C, epsilon, tolerance);
    theta_ = basis * w;
    notes = "regressor rank " + std::to_string(basis.cols()) + " < " + std::to_string(M) +
            " parameters: fitted in the excited directions only";
  }

 private:
  // An orthonormal basis (M x r) of the parameter directions the data excite: the right
  // singular vectors of the regressor above LAPACK's rank threshold, as LLS decides its rank.
  // In raw units, as LLS' minimum norm: a basis taken after unit-norm column scaling leaned on
  // the columns that are nearly 0 in training, and predicted 1.5e6 N m where they are not.
  static Eigen::MatrixXd excited_directions(const Eigen::MatrixXd& phi) {
    const Eigen::Index M = phi.cols();
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(phi, Eigen::ComputeThinV);   // not BDCSVD: see envs/base_parameters.cc
    svd.setThreshold(Eigen::NumTraits<double>::epsilon() * static_cast<double>(std::max(phi.rows(), M)));
    const Eigen::Index r = svd.rank();
    if (r == M) return Eigen::MatrixXd::Identity(M, M);
    return svd.matrixV().leftCols(r);
  }
};

constexpr spml_config_key kSvrKeys[] = {
    {"C", SPML_VALUE_NUMBER, 1e-300, HUGE_VAL, nullptr, "box constraint (default max|mean(y) +- 3 std(y)|)"},
    {"epsilon", SPML_VALUE_NUMBER, 0, HUGE_VAL, nullptr, "tube width (default 3 sigma sqrt(ln n / n))"},
    {"tolerance", SPML_VALUE_NUMBER, 1e-12, 1, "1e-4", "liblinear's stopping tolerance"},
    {nullptr, 0, 0, 0, nullptr, nullptr}};

}  // namespace

spml_learner lls_learner() {
  return make_learner<LeastSquares>("LLS", "linear least squares on the stacked model regressor",
                                    SPML_LEARNER_USES_MODEL | SPML_LEARNER_PARAMETRIC | SPML_LEARNER_DETERMINISTIC, nullptr);
}
spml_learner lls_prior_learner() {
  return make_learner<FixedCoefficients<false>>("LLS-prior", "the model with the dataset's prior coefficients, no fit",
                                                SPML_LEARNER_USES_MODEL | SPML_LEARNER_DETERMINISTIC |
                                                    SPML_LEARNER_NEEDS_PRIOR, nullptr);
}
spml_learner lls_simulated_learner() {
  return make_learner<FixedCoefficients<true>>("LLS-simulated",
                                               "the model with the simulation's true coefficients, no fit",
                                               SPML_LEARNER_USES_MODEL | SPML_LEARNER_DETERMINISTIC |
                                                   SPML_LEARNER_NEEDS_TRUTH, nullptr);
}
spml_learner svr_learner() {
  return make_learner<SupportVectorRegression>(
      "SVR", "epsilon-SVR (liblinear), linear kernel on the model features",
      SPML_LEARNER_USES_MODEL | SPML_LEARNER_PARAMETRIC | SPML_LEARNER_DETERMINISTIC, kSvrKeys);
}

}  // namespace spml::builtin
