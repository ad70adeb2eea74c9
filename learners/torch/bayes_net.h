// Bayesian neural networks trained by Bayes by backprop (Blundell et al. 2015, "Weight
// Uncertainty in Neural Networks"), optionally with a Bayesian parametric-model path
// (BaMbANN, Riedel & Stulp: output = phi(x).theta + dense(x)).
//
// This header is free of LibTorch on purpose: <torch/torch.h> is included by bayes_net.cc
// alone, so the learner library and the tests compile fast.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "spml/abi.h"
#include "spml/row_matrix.h"

namespace spml::torch_learners {

// The defaults live once, in the key table of library.cc (the host fills them in); a zero here
// only means "not set".
struct BayesNetOptions {
  std::vector<int> hidden;               // units per hidden layer (ELU), linear output
  int epochs = 0;                        // 0: as many as give `steps` optimiser steps
  int steps = 0;                         // used when epochs = 0
  int batch = 0;                         // rows per optimiser step (fewer if the data has fewer)
  double learning_rate = 0;              // Adam; beta = (0.9, 0.999), eps = 1e-7 as Keras' defaults
  double kl_weight = 0;                  // beta of the tempered ELBO: -NLL - beta KL / rows (1: exact)
  double prior_scale = 0;                // dense weights ~ N(0, prior_scale^2 / fan_in)
  double model_prior_scale = 0;          // model path: theta_j ~ N(prior_j, (model_prior_scale / a_j)^2)
  double obs_var = 0;                    // > 0: fixed observation variance (target units^2); 0: learned
  double noise_floor = 0;                // learned noise: lower bound, fraction of the target variance
  int samples = 0;                       // weight draws per prediction
  int threads = 0;                       // LibTorch intra-op threads during fit and predict
  std::uint64_t seed = 0;
  bool model_path = false;               // BaMbANN: add phi(x).theta with a Bayesian theta
  double model_warmup = 0;               // BaMbANN: fraction of the epochs that fit the model path alone
};

// The config keys of BNN (model_path false) and BaMbANN ({NULL}-ended): the one place their
// defaults live (options.cc).
const spml_config_key* bayes_net_keys(bool model_path);
// Options from key=value text; a key left out takes its table default. Throws naming a bad value.
BayesNetOptions bayes_net_options(const std::map<std::string, std::string>& values, Eigen::Index outputs,
                                  bool model_path, std::uint64_t seed);

// One fitted network. fit() and predict() take the ABI's layouts: X rows x inputs, Y rows x
// outputs, phi (outputs*rows) x params output-major (spml/learner.h).
class BayesNet {
 public:
  explicit BayesNet(BayesNetOptions options);
  ~BayesNet();
  BayesNet(const BayesNet&) = delete;
  BayesNet& operator=(const BayesNet&) = delete;

  // theta_prior: the model path's prior mean and starting point (params values). progress
  // (may be empty) hears the fraction of the work done after every epoch and after each pass
  // over the training rows that follows training; the fit is the same with or without it.
  void fit(const Eigen::Ref<const RowMatrix>& X, const Eigen::Ref<const RowMatrix>& Y,
           const Eigen::Ref<const RowMatrix>& phi, const Eigen::VectorXd& theta_prior,
           const std::function<void(double, const char*)>& progress = {});
  // mean and var: rows x outputs, row-major; var (may be null) includes the observation noise.
  void predict(const Eigen::Ref<const RowMatrix>& X, const Eigen::Ref<const RowMatrix>& phi, double* mean,
               double* var) const;

  // Posterior of theta (empty without a model path), identified by the orthogonality
  // convention: the part of the dense path the model regressor can express on the training
  // rows counts to theta (bayes_net.cc, identify_theta). Predictions are the same either way.
  Eigen::VectorXd theta_mean() const;
  Eigen::VectorXd theta_std() const;
  Eigen::VectorXd model_layer_mean() const;   // the model layer's own mean, before that
  Eigen::VectorXd noise_var() const;    // observation variance per output, target units^2
  double noise_floor_var(Eigen::Index output) const;   // noise_floor in target units^2
  int epochs_run() const;
  double final_loss() const;            // negative ELBO per row at the end, scaled units

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Closed-form KL(q || p) summed over independent Gaussians, by the code the ELBO uses.
double gaussian_kl(const std::vector<double>& mu_q, const std::vector<double>& sigma_q,
                   const std::vector<double>& mu_p, const std::vector<double>& sigma_p);

// For y = w x + noise with one Bayesian weight q(w) = N(mu, sigma^2), prior N(mu_p, sigma_p^2)
// and noise variance noise_var: d(-ELBO per row)/d mu, averaged over `draws` reparameterised
// samples by the training code's autograd path.
double negative_elbo_gradient(const std::vector<double>& x, const std::vector<double>& y, double mu, double sigma,
                              double mu_p, double sigma_p, double noise_var, int draws, std::uint64_t seed);

}  // namespace spml::torch_learners
