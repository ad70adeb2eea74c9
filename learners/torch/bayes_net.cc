// Bayes by backprop on LibTorch (the only translation unit of the tree that includes it).
//
// Every weight has a factorised Gaussian posterior q(w) = N(mu, softplus(rho)^2) and a
// Gaussian prior; training maximises the (tempered) ELBO per row,
//   -loss = mean_rows log N(y | f(x; w), noise) - (kl_weight KL_dense + KL_model) / rows,  w ~ q,
// with the KLs in closed form. kl_weight = 1 is the exact ELBO; the default tempers the dense
// weights' KL (README "BNN and BaMbANN" has the numbers that chose it). Training samples each layer's pre-activations instead of its
// weights (the local reparameterisation of Kingma et al. 2015): the same ELBO and gradient
// in expectation, with independent noise per row and so a far less noisy gradient per step.
// Prediction draws whole weight sets, as the paper does (30 draws -> mean and variance).
#include "bayes_net.h"

#include <ATen/CPUGeneratorImpl.h>
#include <torch/torch.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace spml::torch_learners {
namespace {

using torch::Tensor;
const torch::TensorOptions kFloat = torch::TensorOptions().dtype(torch::kFloat32);
constexpr double kLog2Pi = 1.8378770664093453;
constexpr double kInitialSigma = 1e-3;     // posterior std of every weight at the start
constexpr double kInitialNoise = 1e-2;     // learned noise at the start, fraction of the target variance
constexpr int kPredictChunk = 2048;        // rows per forward pass at prediction (bounds memory)

double inverse_softplus(double s) { return std::log(std::expm1(s)); }

// KL(N(mu_q, sigma_q^2) || N(mu_p, sigma_p^2)) element by element.
Tensor kl_terms(const Tensor& mu_q, const Tensor& sigma_q, const Tensor& mu_p, const Tensor& sigma_p) {
  return torch::log(sigma_p) - torch::log(sigma_q) +
         (sigma_q.square() + (mu_q - mu_p).square()) / (2.0 * sigma_p.square()) - 0.5;
}

// Gaussian negative log-likelihood, summed over outputs, mean over rows.
Tensor gaussian_nll(const Tensor& y, const Tensor& f, const Tensor& var) {
  return (0.5 * (kLog2Pi + torch::log(var) + (y - f).square() / var)).sum(1).mean();
}

// The factorised Gaussian posterior over every weight of a network, kept in flat vectors so
// that one KL expression and one Adam parameter cover all layers (small tensors make LibTorch's
// per-operation overhead the cost; fewer, larger operations are faster). q(w_k) =
// N(mu_k, softplus(rho_k)^2), prior N(prior_mu_k, prior_sigma_k^2).
struct Posterior {
  Tensor mu, rho, prior_mu, prior_sigma;
  Tensor sigma() const { return torch::nn::functional::softplus(rho); }
  Tensor kl(const Tensor& sigma) const { return kl_terms(mu, sigma, prior_mu, prior_sigma); }   // per weight
  int64_t size() const { return mu.size(0); }
};

// Where a weight matrix (rows x cols; a bias is 1 x cols) lies in the flat vectors.
struct Block {
  int64_t offset = 0, rows = 0, cols = 0;
  Tensor of(const Tensor& flat) const { return flat.slice(0, offset, offset + rows * cols).view({rows, cols}); }
  // draws x rows x cols from draws x size
  Tensor of_draws(const Tensor& flat) const {
    return flat.slice(1, offset, offset + rows * cols).view({flat.size(0), rows, cols});
  }
};

// Builds the flat vectors block by block.
class PosteriorBuilder {
 public:
  Block add(Tensor start_mu, double prior_std, Tensor prior_mean) {
    const int64_t rows = start_mu.dim() == 1 ? 1 : start_mu.size(0);
    const Block b{offset_, rows, start_mu.numel() / rows};
    mu_.push_back(start_mu.reshape({-1}));
    prior_mu_.push_back(prior_mean.reshape({-1}).expand({start_mu.numel()}));
    prior_sigma_.push_back(torch::full({start_mu.numel()}, prior_std, kFloat));
    offset_ += start_mu.numel();
    return b;
  }
  Posterior build() const {
    Posterior p;
    p.mu = torch::cat(mu_).detach().clone().requires_grad_(true);
    p.rho = torch::full({offset_}, inverse_softplus(kInitialSigma), kFloat).requires_grad_(true);
    p.prior_mu = torch::cat(prior_mu_).clone();
    p.prior_sigma = torch::cat(prior_sigma_).clone();
    return p;
  }

 private:
  int64_t offset_ = 0;
  std::vector<Tensor> mu_, prior_mu_, prior_sigma_;
};

// A dense layer y = x W + b with pre-activations sampled per row (local reparameterisation);
// var_flat holds sigma^2 of every weight.
struct Layer {
  Block w, b;
  Tensor forward_train(const Tensor& x, const Posterior& q, const Tensor& var_flat, at::Generator& gen) const {
    Tensor mean = torch::addmm(b.of(q.mu), x, w.of(q.mu));
    Tensor var = torch::addmm(b.of(var_flat), x.square(), w.of(var_flat));
    return mean + var.sqrt() * at::randn(mean.sizes(), gen, kFloat);
  }
};

std::vector<double> column_of(const Tensor& t) {
  Tensor c = t.detach().to(torch::kFloat64).contiguous();
  return std::vector<double>(c.data_ptr<double>(), c.data_ptr<double>() + c.numel());
}

// LibTorch's intra-op thread count is process-wide: set it for one call, then restore it.
class ThreadScope {
 public:
  explicit ThreadScope(int threads) : previous_(at::get_num_threads()) { at::set_num_threads(threads); }
  ~ThreadScope() { at::set_num_threads(previous_); }

 private:
  int previous_;
};

// Per column: the RMS of M - centre; 1 where that is 0 (a constant column) or not finite.
Eigen::RowVectorXd column_scale(const Eigen::Ref<const RowMatrix>& M, const Eigen::RowVectorXd& centre) {
  Eigen::RowVectorXd scale = ((M.rowwise() - centre).array().square().colwise().mean()).sqrt();
  for (Eigen::Index j = 0; j < scale.size(); ++j)
    if (!(scale[j] > 0)) scale[j] = 1.0;
  return scale;
}

Tensor to_tensor(const Eigen::Ref<const RowMatrix>& m) {
  return torch::from_blob(const_cast<double*>(m.data()), {m.rows(), m.cols()}, torch::kFloat64)
      .to(torch::kFloat32)
      .clone();
}

}  // namespace

struct BayesNet::Impl {
  BayesNetOptions opt;
  Posterior q;                    // every weight: dense layers, then the model path
  std::vector<Layer> layers;
  Block theta;                    // model path (1 x params): whitened coefficients v, theta = whiten v
  Tensor log_noise, fixed_noise;  // observation variance, scaled target units
  Eigen::RowVectorXd x_mean, x_scale, y_mean, y_scale;
  Eigen::MatrixXd whiten;         // params x params
  Eigen::VectorXd theta_identified;      // BaMbANN: theta under the orthogonality convention
  Eigen::MatrixXd theta_identified_cov;  // and its posterior covariance (identify_theta)
  Eigen::Index inputs = 0, outputs = 0, params = 0;
  int epochs_run = 0;
  double final_loss = 0.0;

  Tensor noise() const {
    if (fixed_noise.defined()) return fixed_noise;
    return opt.noise_floor + torch::exp(log_noise);
  }

  std::vector<Tensor> parameters() const {
    std::vector<Tensor> p{q.mu, q.rho};
    if (log_noise.defined()) p.push_back(log_noise);
    return p;
  }

  // One stochastic forward pass in training: x (rows x inputs, scaled), phi (rows x outputs x
  // params, scaled). Returns the prediction and the weighted KL(q || prior): the dense
  // weights' KL times kl_weight, the model path's in full.
  // dense = false: the model path alone (the warm-up of BaMbANN).
  std::pair<Tensor, Tensor> forward_train(const Tensor& x, const Tensor& phi, const Tensor& phi_sq, bool dense,
                                          at::Generator& gen) const {
    const Tensor sigma = q.sigma();
    const Tensor var = sigma.square();
    Tensor h = dense ? x : torch::zeros({x.size(0), outputs}, kFloat);
    for (size_t i = 0; dense && i < layers.size(); ++i) {
      h = layers[i].forward_train(h, q, var, gen);
      if (i + 1 < layers.size()) h = torch::elu(h);
    }
    if (opt.model_path) {
      const Tensor mean = torch::matmul(phi, theta.of(q.mu).view({params}));
      const Tensor v = torch::matmul(phi_sq, theta.of(var).view({params}));
      h = h + mean + v.sqrt() * at::randn(mean.sizes(), gen, kFloat);
    }
    const Tensor kl = q.kl(sigma);
    const int64_t dense_size = opt.model_path ? theta.offset : q.size();
    Tensor weighted = dense ? opt.kl_weight * kl.slice(0, 0, dense_size).sum() : torch::zeros({}, kFloat);
    if (opt.model_path) weighted = weighted + kl.slice(0, dense_size).sum();
    return {h, weighted};
  }

  // The dense path under whole weight draws (S x weights): S x rows x outputs, scaled units.
  Tensor dense_draws(const Tensor& x, const Tensor& draws) const {
    const int64_t S = draws.size(0);
    Tensor h = x.unsqueeze(0).expand({S, x.size(0), inputs});
    for (size_t i = 0; i < layers.size(); ++i) {
      h = torch::baddbmm(layers[i].b.of_draws(draws), h, layers[i].w.of_draws(draws));
      if (i + 1 < layers.size()) h = torch::elu(h);
    }
    return h;
  }

  // Identifies theta (BaMbANN): the dense path's function can also express anything in the
  // span of the model regressor (a constant, a linear trend), and with its tempered prior
  // nothing makes it leave that to theta -- on data from the model alone it took a quarter of
  // the constant after a model-only warm-up, and most of every coefficient without one. Reported coefficients therefore follow the orthogonality convention of
  // calibration with a discrepancy (Plumlee 2017): theta absorbs the least-squares projection
  // of the dense path onto the regressor's columns over the training rows, so that what the
  // network adds is orthogonal to the model there. Per posterior draw s: v_s + c_s with
  // c_s = (P^T P)^-1 P^T dense_s (P the whitened regressor); the predictions, Phi theta +
  // dense = Phi (theta + c) + (dense - Phi c), do not change.
  void identify_theta(const Tensor& x, const Tensor& phi) {
    torch::NoGradGuard no_grad;
    at::Generator gen = at::detail::createCPUGenerator(opt.seed ^ 0x2545f491u);
    const int64_t S = std::max(2, opt.samples), n = x.size(0);
    const Tensor draws = q.mu + q.sigma() * at::randn({S, q.size()}, gen, kFloat);
    const Tensor P = phi.reshape({n * outputs, params}).to(torch::kFloat64);
    Tensor Ptd = torch::zeros({params, S}, torch::kFloat64);   // P^T dense_s, column per draw
    for (int64_t s = 0; s < n; s += kPredictChunk) {
      const int64_t e = std::min<int64_t>(n, s + kPredictChunk), c = e - s;
      const Tensor d = dense_draws(x.slice(0, s, e), draws).reshape({S, c * outputs}).to(torch::kFloat64);
      Ptd += torch::mm(P.slice(0, s * outputs, e * outputs).t(), d.t());
    }
    const Tensor G = torch::mm(P.t(), P).contiguous();
    const Eigen::Map<const Eigen::MatrixXd> gram(G.data_ptr<double>(), params, params);
    const Tensor Ptd_c = Ptd.contiguous();
    const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> rhs(
        Ptd_c.data_ptr<double>(), params, S);
    const Eigen::MatrixXd C = gram.completeOrthogonalDecomposition().solve(Eigen::MatrixXd(rhs));   // params x S
    // v and the dense weights are independent under q: Cov(v + c) = diag(sigma_v^2) + Cov(c).
    const auto mu_v = column_of(theta.of(q.mu)), sd_v = column_of(theta.of(q.sigma()));
    const Eigen::VectorXd c_mean = C.rowwise().mean();
    const Eigen::MatrixXd dev = C.colwise() - c_mean;
    Eigen::MatrixXd cov = dev * dev.transpose() / static_cast<double>(S - 1);
    Eigen::VectorXd v(params);
    for (Eigen::Index j = 0; j < params; ++j) {
      v[j] = mu_v[static_cast<size_t>(j)] + c_mean[j];
      cov(j, j) += sd_v[static_cast<size_t>(j)] * sd_v[static_cast<size_t>(j)];
    }
    theta_identified = whiten * v;
    theta_identified_cov = whiten * cov * whiten.transpose();
  }

  // Prediction from scaled inputs x and scaled regressor phi: `samples` whole weight draws,
  // their mean and variance plus `noise` (scaled units), written unscaled into mean and var
  // (rows x outputs; var may be null).
  void predict_scaled(const Tensor& x, const Tensor& phi, const Tensor& noise, double* mean, double* var) const {
    torch::NoGradGuard no_grad;
    // Draws depend on the seed only, so predicting the same rows twice gives the same numbers.
    at::Generator gen = at::detail::createCPUGenerator(opt.seed ^ 0x5bd1e995u);
    const int64_t S = std::max(1, opt.samples), n = x.size(0);
    const Tensor draws = q.mu + q.sigma() * at::randn({S, q.size()}, gen, kFloat);   // S x weights
    const Tensor U = opt.model_path ? theta.of_draws(draws).view({S, params}) : Tensor();
    for (int64_t s = 0; s < n; s += kPredictChunk) {
      const int64_t e = std::min<int64_t>(n, s + kPredictChunk), c = e - s;
      Tensor h = dense_draws(x.slice(0, s, e), draws);
      if (opt.model_path)   // (c*outputs x params)(params x S) -> S x c x outputs
        h = h + torch::mm(phi.slice(0, s, e).reshape({c * outputs, params}), U.t())
                    .view({c, outputs, S})
                    .permute({2, 0, 1});
      const Tensor mu = h.mean(0).to(torch::kFloat64).contiguous();
      const Tensor v = (h.var(0, /*unbiased=*/true) + noise).to(torch::kFloat64).contiguous();
      const double* mp = mu.data_ptr<double>();
      const double* vp = v.data_ptr<double>();
      for (int64_t i = 0; i < c; ++i)
        for (Eigen::Index o = 0; o < outputs; ++o) {
          const int64_t k = i * outputs + o, out = (s + i) * outputs + o;
          mean[out] = mp[k] * y_scale[o] + y_mean[o];
          if (var) var[out] = vp[k] * y_scale[o] * y_scale[o];
        }
    }
  }

  Tensor scaled_inputs(const Eigen::Ref<const RowMatrix>& X) const {
    RowMatrix s = (X.rowwise() - x_mean).array().rowwise() / x_scale.array();
    return to_tensor(s);
  }

  // phi (outputs*rows) x params output-major -> rows x outputs x params, each output divided
  // by its target scale, times `transform` (the whitening, once it is known).
  Tensor scaled_regressor(const Eigen::Ref<const RowMatrix>& phi, Eigen::Index rows,
                          const Eigen::MatrixXd& transform) const {
    RowMatrix s(rows * outputs, params);
    for (Eigen::Index i = 0; i < rows; ++i)
      for (Eigen::Index o = 0; o < outputs; ++o) s.row(i * outputs + o) = phi.row(o * rows + i) / y_scale[o];
    if (transform.size()) s = s * transform;
    return to_tensor(s).view({rows, outputs, params});
  }
};

BayesNet::BayesNet(BayesNetOptions options) : impl_(std::make_unique<Impl>()) { impl_->opt = std::move(options); }
BayesNet::~BayesNet() = default;

void BayesNet::fit(const Eigen::Ref<const RowMatrix>& X, const Eigen::Ref<const RowMatrix>& Y,
                   const Eigen::Ref<const RowMatrix>& phi, const Eigen::VectorXd& theta_prior,
                   const std::function<void(double, const char*)>& progress) {
  Impl& m = *impl_;
  const BayesNetOptions& o = m.opt;
  const Eigen::Index n = X.rows();
  if (n < 2) throw std::runtime_error("needs at least 2 training rows, got " + std::to_string(n));
  if (Y.rows() != n) throw std::runtime_error("inputs have " + std::to_string(n) + " rows, targets " + std::to_string(Y.rows()));
  if (!X.allFinite() || !Y.allFinite()) throw std::runtime_error("training data contain NaN or infinite values");
  if (o.hidden.empty()) throw std::runtime_error("needs at least one hidden layer");
  m.inputs = X.cols();
  m.outputs = Y.cols();
  m.params = o.model_path ? phi.cols() : 0;
  if (o.model_path && (phi.rows() != n * m.outputs || theta_prior.size() != m.params))
    throw std::runtime_error("regressor is " + std::to_string(phi.rows()) + " x " + std::to_string(phi.cols()) +
                             ", expected " + std::to_string(n * m.outputs) + " rows and " +
                             std::to_string(theta_prior.size()) + " columns");
  ThreadScope threads(o.threads);
  at::Generator gen = at::detail::createCPUGenerator(o.seed);

  // Standard scaling. The dense-only network also centres the targets; with a model path
  // the targets are only divided by their RMS, so that theta keeps its physical meaning.
  m.x_mean = X.colwise().mean();
  m.x_scale = column_scale(X, m.x_mean);
  m.y_mean = o.model_path ? Eigen::RowVectorXd::Zero(m.outputs) : Eigen::RowVectorXd(Y.colwise().mean());
  m.y_scale = column_scale(Y, m.y_mean);
  const Tensor x = m.scaled_inputs(X);
  const Tensor y = to_tensor((Y.rowwise() - m.y_mean).array().rowwise() / m.y_scale.array());

  // Dense path: inputs -> hidden (ELU) -> outputs (linear). Prior std prior_scale/sqrt(fan_in)
  // keeps the prior function's scale independent of the layer widths.
  PosteriorBuilder builder;
  std::vector<int64_t> sizes{m.inputs};
  for (int h : o.hidden) sizes.push_back(h);
  sizes.push_back(m.outputs);
  m.layers.clear();
  const Tensor zero = torch::zeros({1}, kFloat);
  for (size_t i = 0; i + 1 < sizes.size(); ++i) {
    const double bound = 1.0 / std::sqrt(static_cast<double>(sizes[i]));
    const double prior = o.prior_scale / std::sqrt(static_cast<double>(sizes[i]));
    const double start = bound;
    Layer l;
    l.w = builder.add(torch::empty({sizes[i], sizes[i + 1]}, kFloat).uniform_(-start, start, gen), prior, zero);
    l.b = builder.add(torch::empty({sizes[i + 1]}, kFloat).uniform_(-start, start, gen), prior, zero);
    m.layers.push_back(l);
  }
  Tensor phi_t, phi_sq;
  if (o.model_path) {
    // The model path is trained in whitened coordinates v (theta = whiten v) in which every
    // direction changes the scaled prediction by unit RMS: correlated regressor columns
    // (1, x, x^2; inertial parameters) would otherwise make Adam's per-coordinate steps crawl.
    // q(v) is factorised, so q(theta) is a full-covariance Gaussian. The prior
    // v ~ N(v_prior, s^2 I) is Zellner's g-prior on theta, centred on the dataset's prior:
    // wide (s = model_prior_scale target RMS per direction) and invariant to units.
    const Tensor scaled = m.scaled_regressor(phi, n, Eigen::MatrixXd()).view({n * m.outputs, m.params});
    Eigen::MatrixXd gram(m.params, m.params);
    {
      const Tensor g = torch::mm(scaled.t().to(torch::kFloat64), scaled.to(torch::kFloat64)).contiguous() /
                       static_cast<double>(n * m.outputs);
      gram = Eigen::Map<const Eigen::MatrixXd>(g.data_ptr<double>(), m.params, m.params);
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram);
    // Directions the data do not excite keep their prior (their eigenvalue is floored).
    const Eigen::VectorXd lambda = eig.eigenvalues().cwiseMax(1e-12 * std::max(eig.eigenvalues().maxCoeff(), 1e-300));
    m.whiten = eig.eigenvectors() * lambda.cwiseSqrt().cwiseInverse().asDiagonal();
    phi_t = m.scaled_regressor(phi, n, m.whiten);
    phi_sq = phi_t.square();
    Eigen::VectorXd v0 = lambda.cwiseSqrt().asDiagonal() * (eig.eigenvectors().transpose() * theta_prior);
    const Tensor v0_t = torch::from_blob(v0.data(), {m.params}, torch::kFloat64).to(torch::kFloat32).clone();
    m.theta = builder.add(v0_t, o.model_prior_scale, v0_t);
  }
  m.q = builder.build();
  if (o.obs_var > 0) {
    Eigen::VectorXd v = o.obs_var / m.y_scale.array().square().transpose();
    m.fixed_noise = torch::from_blob(v.data(), {m.outputs}, torch::kFloat64).to(torch::kFloat32).clone();
    m.log_noise = Tensor();
  } else {
    m.fixed_noise = Tensor();
    m.log_noise = torch::full({m.outputs}, std::log(kInitialNoise), kFloat).requires_grad_(true);
  }

  torch::optim::Adam adam(m.parameters(), torch::optim::AdamOptions(o.learning_rate).betas({0.9, 0.999}).eps(1e-7));
  const int64_t batch = std::min<int64_t>(std::max(1, o.batch), n);
  const int64_t per_epoch = (n + batch - 1) / batch;
  const int epochs = o.epochs > 0 ? o.epochs : static_cast<int>(std::max<int64_t>(1, (o.steps + per_epoch - 1) / per_epoch));
  const double rows = static_cast<double>(n);

  // model_warmup > 0: BaMbANN first fits the model path alone for that fraction of the
  // epochs. That keeps the dense path from taking model terms early and helps extrapolation
  // (SimDyn-Ll test_extrap joint 0: 39.0 at 0.3, 49.3 at 0), but it leaves the dense path too
  // few steps at a high rate to learn the residual (Toy-Interp 0.50 vs 0.48, VIA-inst 3.71 vs
  // 3.05, SimDyn-Ll test_interp joint 0 36.6 vs 15.5; README). The default is 0: the
  // coefficients no longer need it, being identified after the fit (identify_theta).
  const int warmup_epochs = o.model_path ? static_cast<int>(std::floor(o.model_warmup * epochs)) : 0;
  // The step size decays along a half cosine to zero at the end: a constant step leaves Adam
  // jittering around the optimum, which the learned noise then mistakes for observation noise.
  const double total_steps = static_cast<double>(epochs) * static_cast<double>(per_epoch);
  // Progress: each training row costs a forward and a backward pass (about 3 forwards); the
  // passes after training predict every training row once per weight draw (forward only):
  // the noise recalibration and theta's identification, one pass each when they run.
  const double passes = (o.obs_var <= 0 ? 1.0 : 0.0) + (o.model_path ? 1.0 : 0.0);
  const double train_work = 3.0 * total_steps * static_cast<double>(batch);
  const double after_work = passes * std::max(1, o.samples) * rows;
  const double train_share = train_work / (train_work + after_work);
  auto report = [&](double fraction, const char* stage) {
    if (progress) progress(fraction, stage);
  };
  int64_t step = 0;
  for (int e = 0; e < epochs; ++e) {
    const Tensor order = torch::randperm(n, gen, torch::TensorOptions().dtype(torch::kLong));
    Tensor epoch_loss = torch::zeros({}, kFloat);
    for (int64_t s = 0; s < n; s += batch) {
      const Tensor idx = order.slice(0, s, std::min<int64_t>(n, s + batch));
      const Tensor xb = x.index_select(0, idx), yb = y.index_select(0, idx);
      Tensor pb, pb2;
      if (o.model_path) {
        pb = phi_t.index_select(0, idx);
        pb2 = phi_sq.index_select(0, idx);
      }
      auto [f, kl] = m.forward_train(xb, pb, pb2, e >= warmup_epochs, gen);
      Tensor loss = gaussian_nll(yb, f, m.noise()) + kl / rows;
      adam.zero_grad();
      loss.backward();
      const double lr = 0.5 * o.learning_rate * (1.0 + std::cos(M_PI * static_cast<double>(step++) / total_steps));
      for (auto& group : adam.param_groups()) static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
      adam.step();
      epoch_loss += loss.detach() * static_cast<double>(idx.size(0));
    }
    m.final_loss = epoch_loss.item<double>() / rows;
    if (!std::isfinite(m.final_loss))
      throw std::runtime_error("training diverged at epoch " + std::to_string(e + 1) +
                               " (loss not finite); try a smaller learning_rate");
    report(train_share * (e + 1) / epochs, "epochs");
  }
  m.epochs_run = epochs;

  // The noise learned in training also absorbs the per-row sampling noise of the stochastic
  // forward pass, and prediction adds the weight draws' variance on top of it: on Toy that
  // counted the spread twice (noise std 0.98 learned, 0.5 true). Recalibrate: observation
  // variance = mean squared training residual of the predictive mean minus the mean model
  // variance, per output, not below the floor.
  if (o.obs_var <= 0) {
    std::vector<double> mean(static_cast<size_t>(n * m.outputs)), var(mean.size());
    m.predict_scaled(x, phi_t, torch::zeros({m.outputs}, kFloat), mean.data(), var.data());   // model variance alone
    Eigen::VectorXd calibrated(m.outputs);
    for (Eigen::Index j = 0; j < m.outputs; ++j) {
      double residual = 0, model = 0;
      for (Eigen::Index i = 0; i < n; ++i) {
        const double r = (Y(i, j) - mean[static_cast<size_t>(i * m.outputs + j)]) / m.y_scale[j];
        residual += r * r;
        model += var[static_cast<size_t>(i * m.outputs + j)] / (m.y_scale[j] * m.y_scale[j]);
      }
      calibrated[j] = std::max(o.noise_floor, (residual - model) / static_cast<double>(n));
    }
    m.fixed_noise = torch::from_blob(calibrated.data(), {m.outputs}, torch::kFloat64).to(torch::kFloat32).clone();
    report(train_share + (1.0 - train_share) / passes, "noise recalibration");
  }
  if (o.model_path) m.identify_theta(x, phi_t);
}

void BayesNet::predict(const Eigen::Ref<const RowMatrix>& X, const Eigen::Ref<const RowMatrix>& phi, double* mean,
                       double* var) const {
  const Impl& m = *impl_;
  if (m.layers.empty()) throw std::runtime_error("predict before fit");
  if (X.cols() != m.inputs)
    throw std::runtime_error("query has " + std::to_string(X.cols()) + " inputs, the fit had " + std::to_string(m.inputs));
  const Eigen::Index n = X.rows();
  if (m.opt.model_path && (phi.rows() != n * m.outputs || phi.cols() != m.params))
    throw std::runtime_error("query regressor is " + std::to_string(phi.rows()) + " x " + std::to_string(phi.cols()) +
                             ", expected " + std::to_string(n * m.outputs) + " x " + std::to_string(m.params));
  ThreadScope threads(m.opt.threads);
  m.predict_scaled(m.scaled_inputs(X), m.opt.model_path ? m.scaled_regressor(phi, n, m.whiten) : Tensor(),
                   m.noise().detach(), mean, var);
}

Eigen::VectorXd BayesNet::theta_mean() const {
  if (!impl_->opt.model_path) return {};
  return impl_->theta_identified;
}

Eigen::VectorXd BayesNet::theta_std() const {
  if (!impl_->opt.model_path || !impl_->theta_identified_cov.size()) return {};
  return impl_->theta_identified_cov.diagonal().cwiseMax(0.0).cwiseSqrt();
}

Eigen::VectorXd BayesNet::model_layer_mean() const {   // whiten * mu_v
  if (!impl_->opt.model_path || !impl_->q.mu.defined()) return {};
  const auto v = column_of(impl_->theta.of(impl_->q.mu));
  return impl_->whiten * Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

Eigen::VectorXd BayesNet::noise_var() const {
  if (impl_->layers.empty()) return {};
  const auto v = column_of(impl_->noise().expand({impl_->outputs}));
  Eigen::VectorXd out(impl_->outputs);
  for (Eigen::Index o = 0; o < impl_->outputs; ++o) out[o] = v[o] * impl_->y_scale[o] * impl_->y_scale[o];
  return out;
}

double BayesNet::noise_floor_var(Eigen::Index output) const {
  return impl_->opt.noise_floor * impl_->y_scale[output] * impl_->y_scale[output];
}

int BayesNet::epochs_run() const { return impl_->epochs_run; }
double BayesNet::final_loss() const { return impl_->final_loss; }

double gaussian_kl(const std::vector<double>& mu_q, const std::vector<double>& sigma_q, const std::vector<double>& mu_p,
                   const std::vector<double>& sigma_p) {
  auto t = [](const std::vector<double>& v) { return torch::tensor(v, torch::TensorOptions().dtype(torch::kFloat64)); };
  return kl_terms(t(mu_q), t(sigma_q), t(mu_p), t(sigma_p)).sum().item<double>();
}

double negative_elbo_gradient(const std::vector<double>& xs, const std::vector<double>& ys, double mu, double sigma,
                              double mu_p, double sigma_p, double noise_var, int draws, std::uint64_t seed) {
  at::Generator gen = at::detail::createCPUGenerator(seed);
  const auto rows = static_cast<int64_t>(xs.size());
  const Tensor x = torch::tensor(std::vector<float>(xs.begin(), xs.end()), kFloat).view({rows, 1});
  const Tensor y = torch::tensor(std::vector<float>(ys.begin(), ys.end()), kFloat).view({rows, 1});
  // One layer 1 -> 1: w ~ q(w); the bias is pinned at 0 with a tiny std and does not move
  // the gradient in mu.
  PosteriorBuilder builder;
  Layer l;
  l.w = builder.add(torch::full({1, 1}, mu, kFloat), sigma_p, torch::full({1}, mu_p, kFloat));
  l.b = builder.add(torch::zeros({1}, kFloat), 1.0, torch::zeros({1}, kFloat));
  Posterior q = builder.build();
  {
    torch::NoGradGuard no_grad;
    q.rho.copy_(torch::tensor({static_cast<float>(inverse_softplus(sigma)), -30.0f}, kFloat));
  }
  const Tensor noise = torch::full({1}, noise_var, kFloat);
  double sum = 0.0;
  for (int d = 0; d < draws; ++d) {
    if (q.mu.grad().defined()) q.mu.mutable_grad().zero_();
    const Tensor sig = q.sigma();
    Tensor loss =
        gaussian_nll(y, l.forward_train(x, q, sig.square(), gen), noise) + q.kl(sig).sum() / static_cast<double>(rows);
    loss.backward();
    sum += q.mu.grad()[0].item<double>();
  }
  return sum / draws;
}

}  // namespace spml::torch_learners
