// BNN and BaMbANN (learners/torch): the ELBO's pieces against closed forms, and the fitted
// networks against the noise level they were given.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "bayes_net.h"
#include "test_util.h"

using spml::RowMatrix;
using spml::torch_learners::BayesNet;
using spml::torch_learners::BayesNetOptions;
using spml::torch_learners::bayes_net_options;

namespace {

// KL(N(a, s^2) || N(b, t^2)) written out.
double kl_closed_form(double a, double s, double b, double t) {
  return std::log(t / s) + (s * s + (a - b) * (a - b)) / (2 * t * t) - 0.5;
}

TEST(BayesByBackprop, KlOfALayerMatchesTheClosedForm) {
  const std::vector<double> mu_q{0.3, -1.0, 2.0, 0.0}, sigma_q{0.5, 2.0, 0.1, 1.0};
  const std::vector<double> mu_p{0.0, 0.5, 2.0, 0.0}, sigma_p{1.0, 1.0, 0.3, 1.0};
  double expected = 0;
  for (size_t i = 0; i < mu_q.size(); ++i) expected += kl_closed_form(mu_q[i], sigma_q[i], mu_p[i], sigma_p[i]);
  // 0.363147 + 1.931853 + 0.654168 + 0 (the last weight equals its prior)
  EXPECT_NEAR(expected, 2.949168, 1e-6);
  EXPECT_NEAR(spml::torch_learners::gaussian_kl(mu_q, sigma_q, mu_p, sigma_p), expected, 1e-9);
  EXPECT_NEAR(spml::torch_learners::gaussian_kl({0.7}, {0.2}, {0.7}, {0.2}), 0.0, 1e-12);
}

// y = w x + noise: the expected gradient of -ELBO/row in the posterior mean is
// -(1/N) sum x (y - mu x) / s^2 + (mu - mu_p) / (sigma_p^2 N), whatever sigma is.
TEST(BayesByBackprop, ElboGradientHasTheSignAndSizeOfTheClosedForm) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.1);
  std::vector<double> x, y;
  for (int i = 0; i < 50; ++i) {
    x.push_back(-1.0 + 2.0 * i / 49.0);
    y.push_back(1.5 * x.back() + noise(rng));
  }
  const double s2 = 0.01, mu_p = 0.0, sigma_p = 1.0, sigma = 0.05;
  const auto closed = [&](double mu) {
    double g = 0;
    for (size_t i = 0; i < x.size(); ++i) g -= x[i] * (y[i] - mu * x[i]) / s2;
    return g / x.size() + (mu - mu_p) / (sigma_p * sigma_p * x.size());
  };
  for (double mu : {0.5, 1.2, 1.8, 3.0}) {
    const double g = spml::torch_learners::negative_elbo_gradient(x, y, mu, sigma, mu_p, sigma_p, s2, 400, 7);
    SCOPED_TRACE("mu = " + std::to_string(mu));
    EXPECT_EQ(g > 0, closed(mu) > 0);   // below the optimum (about 1.5) -ELBO falls as mu grows
    EXPECT_NEAR(g, closed(mu), 0.05 * std::abs(closed(mu)));
  }
}

struct Sample {
  RowMatrix x, y, phi;
};

// x uniform in [lo, hi]; y = f(x) + N(0, sigma^2); phi = (1, x, x^2, sin 3x) output-major.
template <class F>
Sample draw(int rows, double lo, double hi, double sigma, F f, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::normal_distribution<double> e(0.0, sigma);
  Sample s{RowMatrix(rows, 1), RowMatrix(rows, 1), RowMatrix(rows, 4)};
  for (int i = 0; i < rows; ++i) {
    const double x = u(rng);
    s.x(i, 0) = x;
    s.y(i, 0) = f(x) + e(rng);
    s.phi.row(i) << 1.0, x, x * x, std::sin(3 * x);
  }
  return s;
}

struct Scores {
  double rmse = 0, mean_std = 0, model_std = 0;   // model_std: predictive std without the observation noise
};

Scores score(const BayesNet& net, const Sample& s) {
  std::vector<double> mean(s.x.rows()), var(s.x.rows());
  net.predict(s.x, s.phi, mean.data(), var.data());
  Scores r;
  for (Eigen::Index i = 0; i < s.x.rows(); ++i) {
    r.rmse += std::pow(mean[i] - s.y(i, 0), 2);
    r.mean_std += std::sqrt(var[i]);
    r.model_std += std::sqrt(std::max(0.0, var[i] - net.noise_var()[0]));
  }
  r.rmse = std::sqrt(r.rmse / s.x.rows());
  r.mean_std /= s.x.rows();
  r.model_std /= s.x.rows();
  return r;
}

const Eigen::Vector4d kTheta(1.0, -2.0, 0.5, 1.5);
double linear_model(double x) { return kTheta.dot(Eigen::Vector4d(1.0, x, x * x, std::sin(3 * x))); }

// The BNN's std away from the data: with the default tempering (kl_weight 1e-3, chosen for
// fit: Toy-Interp 0.95 against 1.04 at 1e-2) the model std grows 1.8x from [-2, 2] to [4, 6];
// the 2x needs the less tempered kl_weight = 1e-2 (2.4x here), at no cost in fit on
// this smooth function. Both are asserted, so a change that flattens the uncertainty fails.
TEST(Bnn, FitsToTheNoiseAndIsUnsureOutsideTheData) {
  const double sigma = 0.1;
  const auto f = [](double x) { return std::sin(2 * x) + 0.5 * x; };
  const Sample train = draw(400, -2, 2, sigma, f, 1), inside = draw(400, -2, 2, sigma, f, 2),
               outside = draw(400, 4, 6, sigma, f, 3);
  for (const double kl_weight : {1e-3, 1e-2}) {
    BayesNetOptions o = bayes_net_options({}, 1, false, 0);   // the key table's defaults
    o.seed = 1;
    o.kl_weight = kl_weight;
    BayesNet net(o);
    net.fit(train.x, train.y, RowMatrix(0, 0), Eigen::VectorXd());
    const Scores in = score(net, inside), out = score(net, outside);
    std::printf("BNN kl_weight %g: test RMSE %.4f (noise %.2f), predictive std inside %.4f, outside %.4f, noise std "
                "%.4f, model std inside %.4f outside %.4f (%.2fx)\n",
                kl_weight, in.rmse, sigma, in.mean_std, out.mean_std, std::sqrt(net.noise_var()[0]), in.model_std,
                out.model_std, out.model_std / in.model_std);
    SCOPED_TRACE("kl_weight " + std::to_string(kl_weight));
    EXPECT_LE(in.rmse, 1.15 * sigma);
    EXPECT_GE(in.rmse, 0.85 * sigma);   // not below the noise either: that would mean a broken test split
    // The observation noise is the same everywhere; the model's own uncertainty must grow.
    EXPECT_GE(out.model_std, (kl_weight > 5e-3 ? 2.0 : 1.5) * in.model_std);
  }
}

// Data from the model alone: theta (identified by the orthogonality convention, see
// BayesNet::theta_mean) within 3 posterior std of the truth, and that std of the size of
// least squares' standard errors, not inflated. The model layer's own mean, before the dense
// path's share in the regressor's span is counted to it, is off by 0.26 in the constant: the
// identification is what this test guards.
TEST(BaMbANN, RecoversTheModelCoefficients) {
  const double sigma = 0.1;
  const Sample train = draw(400, -2, 2, sigma, linear_model, 4), test = draw(400, -2, 2, sigma, linear_model, 5);
  BayesNetOptions o = bayes_net_options({}, 1, true, 0);   // the key table's defaults
  o.seed = 2;
  BayesNet net(o);
  net.fit(train.x, train.y, train.phi, Eigen::VectorXd::Zero(4));   // started from zeros, as the paper's Toy
  const Eigen::VectorXd theta = net.theta_mean(), std = net.theta_std(), layer = net.model_layer_mean();
  const Eigen::MatrixXd cov = sigma * sigma * (train.phi.transpose() * train.phi).inverse();
  for (int j = 0; j < 4; ++j) {
    std::printf("theta_%d = %.4f +- %.4f (true %.2f, least-squares s.e. %.4f; model layer alone %.4f)\n", j, theta[j],
                std[j], kTheta[j], std::sqrt(cov(j, j)), layer[j]);
    EXPECT_LE(std::abs(theta[j] - kTheta[j]), 3 * std[j]) << "coefficient " << j;
    EXPECT_LE(std[j], 5 * std::sqrt(cov(j, j))) << "coefficient " << j;
  }
  EXPECT_LE(score(net, test).rmse, 1.15 * sigma);
}

// A residual the model cannot express (0.5 cos 5x): the network learns it to near the noise
// floor (0.127 for noise 0.1 in the default 3000 steps, 0.104-0.126 in 5000; the model-only
// least squares leaves 0.373).
TEST(BaMbANN, LearnsAHiddenSmoothResidual) {
  const double sigma = 0.1;
  const auto f = [](double x) { return linear_model(x) + 0.5 * std::cos(5 * x); };
  const Sample train = draw(400, -2, 2, sigma, f, 6), test = draw(400, -2, 2, sigma, f, 7);
  BayesNetOptions o = bayes_net_options({}, 1, true, 0);   // the key table's defaults
  o.seed = 3;
  BayesNet net(o);
  net.fit(train.x, train.y, train.phi, Eigen::VectorXd::Zero(4));
  const double rmse = score(net, test).rmse;
  const Eigen::VectorXd ls = train.phi.colPivHouseholderQr().solve(train.y.col(0));
  const double ls_rmse = std::sqrt((test.phi * ls - test.y.col(0)).squaredNorm() / test.x.rows());
  std::printf("BaMbANN with a hidden residual: test RMSE %.4f, model-only least squares %.4f, noise %.2f\n", rmse,
              ls_rmse, sigma);
  EXPECT_GE(ls_rmse, 3 * sigma);    // the residual is there
  EXPECT_LE(rmse, 1.3 * sigma);     // and learnt to near the noise floor
}

TEST(Bnn, SameSeedSameNumbersOtherSeedOtherNumbers) {
  const auto f = [](double x) { return std::sin(2 * x); };
  const Sample train = draw(100, -2, 2, 0.1, f, 8), query = draw(20, -3, 3, 0.1, f, 9);
  auto predict = [&](std::uint64_t seed) {
    BayesNetOptions o = bayes_net_options({}, 1, false, 0);   // the key table's defaults
    o.steps = 200;
    o.hidden = {16, 16};
    o.seed = seed;
    BayesNet net(o);
    net.fit(train.x, train.y, RowMatrix(0, 0), Eigen::VectorXd());
    std::vector<double> mean(20), var(20);
    net.predict(query.x, query.phi, mean.data(), var.data());
    mean.insert(mean.end(), var.begin(), var.end());
    return mean;
  };
  const auto a = predict(11), b = predict(11), c = predict(12);
  EXPECT_EQ(a, b);   // bit for bit
  EXPECT_NE(a, c);
}

TEST(Bnn, RefusesBadData) {
  BayesNet net(bayes_net_options({}, 1, false, 0));
  RowMatrix x(3, 1), y(3, 1);
  x << 0, 1, 2;
  y << 0, NAN, 1;
  EXPECT_THROW(net.fit(x, y, RowMatrix(0, 0), Eigen::VectorXd()), std::runtime_error);
  std::vector<double> m(3);
  EXPECT_THROW(net.predict(x, RowMatrix(0, 0), m.data(), nullptr), std::runtime_error);   // before fit
}

// Through the plugin host: listed, composed with LLS as the paper's LLS-BNN, and each
// repetition a new seed (std over repetitions is not 0).
TEST(TorchLearners, ListedComposedAndRepeatedWithNewSeeds) {
  namespace fs = std::filesystem;
  auto r = spml::test::run(spml::test::spml_bin() + " learners");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("BNN\t"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("BaMbANN\t"), std::string::npos) << r.output;
  const fs::path dir = spml::test::temp_dir("torch-bench");
  r = spml::test::run(spml::test::spml_bin() + " generate --scenario toy --out " + (dir / "toy.h5").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = spml::test::run(spml::test::spml_bin() + " bench --data " + (dir / "toy.h5").string() + " --out " +
                      (dir / "b").string() + " --learners LLS-BNN,BaMbANN --reps 2 --set steps=300");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream csv(dir / "b" / "results.csv");
  auto fields = [](const std::string& line) {
    std::stringstream ss(line);
    std::vector<std::string> f;
    for (std::string c; std::getline(ss, c, ',');) f.push_back(c);
    return f;
  };
  std::string line;
  std::getline(csv, line);
  const std::vector<std::string> header = fields(line);
  auto at = [&](const char* name) { return static_cast<size_t>(std::find(header.begin(), header.end(), name) - header.begin()); };
  const size_t rmsestd = at("rmsestd"), nllhmean = at("nllhmean"), fits = at("fits");
  ASSERT_LT(fits, header.size()) << line;
  int rows = 0;
  while (std::getline(csv, line)) {
    if (line.find(",LLS-BNN,") == std::string::npos && line.find(",BaMbANN,") == std::string::npos) continue;
    ++rows;
    const std::vector<std::string> f = fields(line);
    ASSERT_GT(f.size(), fits) << line;
    EXPECT_GT(std::stod(f[rmsestd]), 0.0) << "rmse std over two seeds: " << line;
    EXPECT_TRUE(std::isfinite(std::stod(f[nllhmean]))) << "nllh: " << line;
    EXPECT_EQ(f[fits], "2") << line;
  }
  EXPECT_EQ(rows, 4);   // two learners x two test splits
}

}  // namespace
