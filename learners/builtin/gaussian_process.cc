// GP and semi-parametric GP learners over spml::gp. "-SepKer" fits one GP (and, for SPGP,
// one coefficient vector) per output; otherwise all outputs share one kernel and theta.
// "SPGP-Sparse" takes its kernel from the exact fit on a strided subset and predicts with
// the variational sparse posterior over every row.
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include "learners.h"
#include "spml/gp/gp.h"

namespace spml::builtin {
namespace {

enum class MeanStart { kNone, kPrior, kZeros, kOnes };

template <MeanStart kMean, bool kSeparate, bool kSparse = false>
class GaussianProcess : public Learner {
 public:
  void fit(const View& d, const spml_learner_model& model, const Config& config) override {
    if (kMean != MeanStart::kNone) require_model(d, model, "SPGP");
    // Every value comes from the key table's defaults or the user (the host fills them in).
    gp::FitOptions options;
    options.max_evals = static_cast<int>(config.number("max_evals"));
    options.noise_floor = config.number("noise_floor");
    options.learn_mean = kMean != MeanStart::kNone;
    options.subset_rows = static_cast<int>(config.number("subset_rows"));
    if (!kSparse) options.final_evals = static_cast<int>(config.number("final_evals"));
    // Holding theta at zeros or ones while the kernel is fitted would hand the whole model to
    // the kernel; only a prior is a start worth fitting the kernel around.
    options.kernel_first = kMean == MeanStart::kPrior && config.number("kernel_first") != 0.0;
    const bool standardize = config.number("standardize") != 0.0;
    if (options.max_evals < 1) throw std::runtime_error("max_evals must be >= 1");
    if (!(options.noise_floor > 0)) throw std::runtime_error("noise_floor must be > 0");

    const Eigen::Index n = d.X.rows(), O = d.Y.cols(), M = options.learn_mean ? d.phi.cols() : 0;
    gp::Hyper start;
    start.lengthscales = Eigen::VectorXd::Ones(d.X.cols());   // the paper: everything starts at 1.0
    start.signal_var = 1.0;
    start.noise_var = 1.0;
    start.theta = initial_theta(model, M);

    const Eigen::MatrixXd X = d.X;
    outputs_ = O;
    const int groups = kSeparate ? static_cast<int>(O) : 1;
    for (int g = 0; g < groups; ++g) {
      // Each output group (one for a shared kernel) is an equal share of the fit's progress.
      const double from = static_cast<double>(g) / groups, to = static_cast<double>(g + 1) / groups;
      Eigen::MatrixXd Y = kSeparate ? Eigen::MatrixXd(d.Y.col(g)) : Eigen::MatrixXd(d.Y);
      // Work on targets scaled to unit RMS, so that "everything starts at 1.0" means
      // sf2 = sn2 = mean(y^2) in data units. Raw 1.0 against torques of hundreds of Nm
      // sends L-BFGS' first step to sf2 ~ 1e10, where the kernel matrix is singular.
      const double rms = std::sqrt(Y.squaredNorm() / static_cast<double>(std::max<Eigen::Index>(1, Y.size())));
      const double scale = standardize && rms > 0 ? rms : 1.0;
      Y /= scale;
      gp::Hyper first = start;
      first.theta /= scale;
      Eigen::MatrixXd phi;
      if (M > 0) phi = kSeparate ? Eigen::MatrixXd(d.phi.middleRows(g * n, n)) : Eigen::MatrixXd(d.phi);
      auto lik = std::make_unique<gp::Likelihood>(X, std::move(Y), std::move(phi));
      if (kSparse) {
        const int inducing = static_cast<int>(config.number("inducing"));
        if (inducing < 1) throw std::runtime_error("inducing must be >= 1");
        // The kernel from the exact (semi-parametric) fit on a strided subset; then the sparse
        // posterior over all rows, with theta maximising its bound.
        gp::Likelihood sub = lik->subset(gp::evenly_spaced_rows(n, options.subset_rows));
        gp::FitOptions exact = options;
        exact.subset_rows = 0;
        // Progress: the exact subset fit against the sparse posterior's O(n m^2) pass over all
        // rows (a few n m^2 flops per output), both in gp::fit_work's units.
        const double m = std::min<double>(inducing, static_cast<double>(n));
        const double fit_work = gp::fit_work(sub.X().rows(), sub.inputs(), sub.params(), exact);
        const double split = fit_work / (fit_work + 3.0 * static_cast<double>(n) * m * m * static_cast<double>(sub.outputs()));
        exact.progress = progress_part(progress, from, from + split * (to - from), "subset fit");
        const gp::FitResult r = gp::fit(sub, first, exact);
        for (const auto& w : r.warnings) add_note("subset fit: " + w);
        const std::vector<Eigen::Index> z = gp::evenly_spaced_rows(n, inducing);
        Eigen::MatrixXd Z(static_cast<Eigen::Index>(z.size()), X.cols());
        for (size_t i = 0; i < z.size(); ++i) Z.row(static_cast<Eigen::Index>(i)) = X.row(z[i]);
        sparse_.emplace_back(lik->X(), lik->Y(), lik->phi(), std::move(Z), r.hyper);
        theta_.push_back(sparse_.back().theta() * scale);
      } else {
        gp::FitOptions mine = options;
        mine.progress = progress_part(progress, from, to, staged_text(n, options));
        gp::FitResult r = gp::fit(*lik, first, mine);
        for (const auto& w : r.warnings) add_note((kSeparate ? "output " + std::to_string(g) + ": " : std::string()) + w);
        posteriors_.emplace_back(*lik, r.hyper);
        if (posteriors_.back().jitter() > 0) add_note("posterior Cholesky needed jitter");
        theta_.push_back(r.hyper.theta * scale);
      }
      scale_.push_back(scale);
      progress(to, "posterior");
    }
  }

  void predict(const View& q, double* mean, double* var) const override {
    const Eigen::Index m = q.X.rows();
    const Eigen::Index M = theta_.empty() ? 0 : theta_.front().size();
    if (M > 0 && q.phi.cols() != M) throw std::runtime_error("query regressor has the wrong number of columns");
    const Eigen::MatrixXd Xs = q.X;
    const Eigen::Index O = q.outputs;
    if (O != outputs_) throw std::runtime_error("query has " + std::to_string(O) + " outputs, the fit had " + std::to_string(outputs_));
    for (size_t g = 0; g < scale_.size(); ++g) {
      Eigen::MatrixXd phi;
      if (M > 0) phi = kSeparate ? Eigen::MatrixXd(q.phi.middleRows(static_cast<Eigen::Index>(g) * m, m)) : Eigen::MatrixXd(q.phi);
      Eigen::MatrixXd mu, v;
      if (kSparse) sparse_[g].predict(Xs, phi, &mu, var ? &v : nullptr);
      else posteriors_[g].predict(Xs, phi, &mu, var ? &v : nullptr);
      for (Eigen::Index i = 0; i < m; ++i)
        for (Eigen::Index k = 0; k < mu.cols(); ++k) {
          const Eigen::Index o = kSeparate ? static_cast<Eigen::Index>(g) : k;
          mean[i * O + o] = mu(i, k) * scale_[g];
          if (var) var[i * O + o] = v(i, k) * scale_[g] * scale_[g];
        }
    }
  }

  Eigen::VectorXd coefficients() const override {
    if (kSeparate || theta_.empty()) return {};
    return theta_.front();
  }

 private:
  static Eigen::VectorXd initial_theta(const spml_learner_model& model, Eigen::Index M) {
    switch (kMean) {
      case MeanStart::kNone: return {};
      case MeanStart::kZeros: return Eigen::VectorXd::Zero(M);
      case MeanStart::kOnes: return Eigen::VectorXd::Ones(M);
      case MeanStart::kPrior:
        if (!model.prior) throw std::runtime_error("SPGP starts from the model's prior coefficients; the dataset has none "
                                                   "(use SPGP-from-zeros or SPGP-from-ones)");
        return Eigen::Map<const Eigen::VectorXd>(model.prior, M);
    }
    return {};
  }
  void add_note(const std::string& s) { notes += (notes.empty() ? "" : "; ") + s; }
  // The stage text of a progress report (static: the ABI passes it as a plain C string).
  static const char* staged_text(Eigen::Index n, const gp::FitOptions& o) {
    return gp::staged(n, o) ? "likelihood evaluations (subset, then all rows)" : "likelihood evaluations";
  }

  std::vector<gp::Posterior> posteriors_;
  std::vector<gp::SparsePosterior> sparse_;
  std::vector<Eigen::VectorXd> theta_;
  std::vector<double> scale_;   // per posterior: the target scale it was fitted in
  Eigen::Index outputs_ = 0;
};

constexpr uint32_t kGpFlags = SPML_LEARNER_VARIANCE | SPML_LEARNER_DETERMINISTIC | SPML_LEARNER_PROGRESS;
constexpr spml_config_key kGpKeys[] = {
    {"max_evals", SPML_VALUE_INTEGER, 1, 1e9, "1000", "most likelihood evaluations of L-BFGS"},
    {"noise_floor", SPML_VALUE_NUMBER, 1e-300, HUGE_VAL, "1e-6", "lower bound of the noise variance (scaled units)"},
    {"standardize", SPML_VALUE_INTEGER, 0, 1, "1", "1: fit on targets scaled to unit RMS"},
    {"subset_rows", SPML_VALUE_INTEGER, 0, 1e9, "1000",
     "above 1.5x this many rows: fit the hyper-parameters on this many strided rows first (0: off)"},
    {"kernel_first", SPML_VALUE_INTEGER, 0, 1, "1",
     "SPGP, SPGP-SepKer: 1 fits the kernel with theta at the prior first, then jointly; 0 jointly from the "
     "start (the paper; always so from zeros/ones)"},
    {"final_evals", SPML_VALUE_INTEGER, 1, 1e9, "6", "most evaluations on all rows after the subset fit"},
    {nullptr, 0, 0, 0, nullptr, nullptr}};
constexpr spml_config_key kSparseKeys[] = {
    {"inducing", SPML_VALUE_INTEGER, 1, 1e6, "500", "inducing inputs: this many training rows, evenly strided"},
    {"subset_rows", SPML_VALUE_INTEGER, 1, 1e9, "1000", "rows (strided) of the exact fit that gives the kernel"},
    {"max_evals", SPML_VALUE_INTEGER, 1, 1e9, "1000", "most likelihood evaluations of the subset fit"},
    {"noise_floor", SPML_VALUE_NUMBER, 1e-300, HUGE_VAL, "1e-6", "lower bound of the noise variance (scaled units)"},
    {"standardize", SPML_VALUE_INTEGER, 0, 1, "1", "1: fit on targets scaled to unit RMS"},
    {"kernel_first", SPML_VALUE_INTEGER, 0, 1, "1", "1: subset fit of the kernel with theta at the prior first"},
    {nullptr, 0, 0, 0, nullptr, nullptr}};

}  // namespace

void add_gaussian_process_learners(std::vector<spml_learner>& out) {
  out.push_back(make_learner<GaussianProcess<MeanStart::kNone, false>>(
      "GP", "GP, ARD RBF kernel shared by all outputs, zero mean", kGpFlags | SPML_LEARNER_NONPARAMETRIC, kGpKeys));
  out.push_back(make_learner<GaussianProcess<MeanStart::kNone, true>>(
      "GP-SepKer", "one GP per output, ARD RBF kernel, zero mean", kGpFlags | SPML_LEARNER_NONPARAMETRIC, kGpKeys));
  out.push_back(make_learner<GaussianProcess<MeanStart::kPrior, false>>(
      "SPGP", "GP with mean phi(x).theta, theta learnt jointly, from the prior",
      kGpFlags | SPML_LEARNER_USES_MODEL | SPML_LEARNER_NEEDS_PRIOR,
      kGpKeys));
  out.push_back(make_learner<GaussianProcess<MeanStart::kPrior, true>>(
      "SPGP-SepKer", "SPGP with kernel and theta per output, from the prior",
      kGpFlags | SPML_LEARNER_USES_MODEL | SPML_LEARNER_NEEDS_PRIOR,
      kGpKeys));
  out.push_back(make_learner<GaussianProcess<MeanStart::kPrior, false, true>>(
      "SPGP-Sparse",
      "sparse SPGP for large data (Titsias 2009 variational posterior on 500 strided inducing rows; kernel from an "
      "exact SPGP fit on 1000 strided rows; theta maximises the bound)",
      kGpFlags | SPML_LEARNER_USES_MODEL | SPML_LEARNER_NEEDS_PRIOR, kSparseKeys));
  out.push_back(make_learner<GaussianProcess<MeanStart::kZeros, false>>(
      "SPGP-from-zeros", "SPGP started from theta = 0", kGpFlags | SPML_LEARNER_USES_MODEL, kGpKeys));
  out.push_back(make_learner<GaussianProcess<MeanStart::kOnes, false>>(
      "SPGP-from-ones", "SPGP started from theta = 1", kGpFlags | SPML_LEARNER_USES_MODEL, kGpKeys));
}

}  // namespace spml::builtin
