// The LibTorch learner library (spml/learner.h): BNN and BaMbANN. The networks live in
// bayes_net.cc; this file maps the ABI's data and config onto them.
#include <stdexcept>
#include <vector>

#include "bayes_net.h"
#include "spml/learner_adapter.h"

namespace spml::torch_learners {
namespace {

using adapter::Config;
using adapter::View;

template <bool kModelPath>
class BayesLearner : public adapter::Learner {
 public:
  void fit(const View& d, const spml_learner_model& model, const Config& config) override {
    Eigen::VectorXd prior;
    if (kModelPath) {
      adapter::require_model(d, model, "BaMbANN");
      // The paper starts from the dataset's prior coefficients, from zeros where it has none.
      prior = model.prior ? Eigen::Map<const Eigen::VectorXd>(model.prior, model.params).eval()
                          : Eigen::VectorXd::Zero(model.params);
    }
    const BayesNetOptions options = bayes_net_options(config.values, d.outputs, kModelPath, config.seed);
    net_ = std::make_unique<BayesNet>(options);
    net_->fit(d.X, d.Y, d.phi, prior, [this](double f, const char* stage) { progress(f, stage); });
    // notes are warnings (spml compare marks them): only what a user should look at.
    const Eigen::VectorXd noise = net_->noise_var();
    for (Eigen::Index o = 0; o < noise.size(); ++o)
      if (options.obs_var <= 0 && noise[o] <= net_->noise_floor_var(o))
        notes += (notes.empty() ? "" : "; ") + std::string("output ") + std::to_string(o) +
                 ": calibrated noise at its floor (the network interpolates the training rows)";
    if (kModelPath && !model.prior) notes += (notes.empty() ? "" : "; ") + std::string("theta started from zeros (the dataset has no prior)");
  }
  void predict(const View& q, double* mean, double* var) const override {
    if (!net_) throw std::runtime_error("predict before fit");
    net_->predict(q.X, q.phi, mean, var);
  }
  Eigen::VectorXd coefficients() const override { return net_ ? net_->theta_mean() : Eigen::VectorXd(); }

 private:
  std::unique_ptr<BayesNet> net_;
};

const std::vector<spml_learner>& all() {
  static const std::vector<spml_learner> list{
      adapter::make_learner<BayesLearner<false>>(
          "BNN", "Bayesian neural network (Bayes by backprop), 3 ELU layers, no model",
          SPML_LEARNER_VARIANCE | SPML_LEARNER_NONPARAMETRIC | SPML_LEARNER_PROGRESS, bayes_net_keys(false)),
      adapter::make_learner<BayesLearner<true>>(
          "BaMbANN", "BNN plus a Bayesian model layer phi(x).theta, trained jointly",
          SPML_LEARNER_VARIANCE | SPML_LEARNER_USES_MODEL | SPML_LEARNER_PROGRESS, bayes_net_keys(true))};
  return list;
}

}  // namespace
}  // namespace spml::torch_learners

SPML_EXPORT_LEARNERS(spml::torch_learners::all().data(), spml::torch_learners::all().size())
