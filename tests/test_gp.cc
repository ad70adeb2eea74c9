// The GP core against closed forms and finite differences.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "spml/gp/gp.h"

namespace {

using spml::gp::Hyper;
using spml::gp::Likelihood;

Eigen::MatrixXd random_matrix(int r, int c, unsigned seed, double scale = 1.0) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, scale);
  Eigen::MatrixXd m(r, c);
  for (int i = 0; i < r; ++i)
    for (int j = 0; j < c; ++j) m(i, j) = n(rng);
  return m;
}

Hyper some_hyper(int d, int M) {
  Hyper h;
  h.lengthscales = Eigen::VectorXd::LinSpaced(d, 0.7, 1.9);
  h.signal_var = 1.7;
  h.noise_var = 0.09;
  h.theta = Eigen::VectorXd::LinSpaced(M, -0.5, 0.8);
  return h;
}

// Plain-Eigen reference: K_ij = sf2 exp(-0.5 sum_k (x_ik - x_jk)^2 / l_k^2).
Eigen::MatrixXd reference_kernel(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Hyper& h) {
  Eigen::MatrixXd K(A.rows(), B.rows());
  for (int i = 0; i < A.rows(); ++i)
    for (int j = 0; j < B.rows(); ++j)
      K(i, j) = h.signal_var *
                std::exp(-0.5 * ((A.row(i) - B.row(j)).transpose().cwiseQuotient(h.lengthscales)).squaredNorm());
  return K;
}

TEST(GaussianProcess, GradientMatchesFiniteDifferences) {
  const int n = 40, d = 3, O = 2, M = 4;
  Likelihood lik(random_matrix(n, d, 1), random_matrix(n, O, 2, 2.0), random_matrix(O * n, M, 3));
  const Eigen::VectorXd p = spml::gp::pack(some_hyper(d, M));
  Eigen::VectorXd grad;
  lik.evaluate(p, &grad);
  ASSERT_EQ(grad.size(), d + 2 + M);
  for (int k = 0; k < p.size(); ++k) {
    const double h = 1e-6;
    Eigen::VectorXd a = p, b = p;
    a[k] += h;
    b[k] -= h;
    const double fd = (lik.evaluate(a, nullptr) - lik.evaluate(b, nullptr)) / (2 * h);
    EXPECT_NEAR(grad[k], fd, 1e-5 * std::max(1.0, std::abs(fd))) << "parameter " << k;
  }
}

TEST(GaussianProcess, LikelihoodAndPosteriorMatchClosedForm) {
  const int n = 5, d = 2;
  const Eigen::MatrixXd X = random_matrix(n, d, 4), Y = random_matrix(n, 1, 5), Xs = random_matrix(3, d, 6);
  const Hyper h = some_hyper(d, 0);
  Likelihood lik(X, Y);
  const Eigen::MatrixXd K = reference_kernel(X, X, h) + h.noise_var * Eigen::MatrixXd::Identity(n, n);
  const Eigen::MatrixXd Kinv = K.inverse();
  const double lml = -0.5 * (Y.transpose() * Kinv * Y)(0, 0) - 0.5 * std::log(K.determinant()) - 0.5 * n * std::log(2 * M_PI);
  EXPECT_NEAR(lik.evaluate(spml::gp::pack(h), nullptr), lml, 1e-10);

  const Eigen::MatrixXd Ks = reference_kernel(X, Xs, h);
  const Eigen::VectorXd mean = Ks.transpose() * Kinv * Y;
  const Eigen::VectorXd var =
      (h.signal_var + h.noise_var) * Eigen::VectorXd::Ones(3) - (Ks.transpose() * Kinv * Ks).diagonal();
  spml::gp::Posterior post(lik, h);
  Eigen::MatrixXd mu, v;
  post.predict(Xs, Eigen::MatrixXd(), &mu, &v);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(mu(i, 0), mean[i], 1e-10);
    EXPECT_NEAR(v(i, 0), var[i], 1e-10);
  }
}

TEST(GaussianProcess, SharedKernelLikelihoodIsSumOverOutputs) {
  const int n = 30, d = 2, O = 3, M = 2;
  const Eigen::MatrixXd X = random_matrix(n, d, 7), Y = random_matrix(n, O, 8), phi = random_matrix(O * n, M, 9);
  const Eigen::VectorXd p = spml::gp::pack(some_hyper(d, M));
  Likelihood shared(X, Y, phi);
  Eigen::VectorXd g_shared;
  const double total = shared.evaluate(p, &g_shared);
  double sum = 0;
  Eigen::VectorXd g_sum = Eigen::VectorXd::Zero(p.size());
  for (int o = 0; o < O; ++o) {
    Likelihood single(X, Y.col(o), phi.middleRows(o * n, n));
    Eigen::VectorXd g;
    sum += single.evaluate(p, &g);
    g_sum += g;
  }
  EXPECT_NEAR(total, sum, 1e-9 * std::abs(sum));
  EXPECT_LT((g_shared - g_sum).norm(), 1e-8 * g_sum.norm());
}

TEST(GaussianProcess, SemiParametricFitRecoversTheta) {
  // Noise-free data from a linear model (the Toy basis): the joint optimum puts theta at
  // the truth and leaves nothing for the kernel.
  const int n = 80;
  Eigen::MatrixXd X(n, 1), phi(n, 4);
  for (int i = 0; i < n; ++i) {
    const double x = 12.0 * i / (n - 1);
    X(i, 0) = x;
    phi.row(i) << std::sin(2 * x), x, 1.0, 0.09 * x * x;
  }
  const Eigen::Vector4d truth(2.0, -1.5, 3.0, 2.4);
  Likelihood lik(X, phi * truth, phi);
  Hyper start = some_hyper(1, 4);
  start.lengthscales.setOnes();
  start.signal_var = start.noise_var = 1.0;
  start.theta.setZero();
  spml::gp::FitOptions options;
  options.learn_mean = true;
  const auto r = spml::gp::fit(lik, start, options);
  EXPECT_LT((r.hyper.theta - truth).cwiseAbs().maxCoeff(), 1e-3) << r.hyper.theta.transpose() << " stop " << r.stop;
}

Hyper coarse_hyper(Hyper h, const Eigen::VectorXd& theta) {
  h.theta = theta;
  return h;
}

// A subset likelihood is the likelihood of those rows: X, Y and every output's phi block.
TEST(GaussianProcess, SubsetKeepsEveryOutputsRegressorBlock) {
  const int n = 30, O = 2, M = 3;
  Eigen::MatrixXd X = Eigen::MatrixXd::Random(n, 2), Y = Eigen::MatrixXd::Random(n, O), phi = Eigen::MatrixXd::Random(O * n, M);
  const std::vector<Eigen::Index> rows{0, 7, 8, 20, 29};
  const int m = static_cast<int>(rows.size());
  Eigen::MatrixXd Xs(m, 2), Ys(m, O), phis(O * m, M);
  for (int i = 0; i < m; ++i) {
    Xs.row(i) = X.row(rows[i]);
    Ys.row(i) = Y.row(rows[i]);
    for (int o = 0; o < O; ++o) phis.row(o * m + i) = phi.row(o * n + rows[i]);
  }
  Likelihood whole(X, Y, phi), direct(Xs, Ys, phis);
  Likelihood sub = whole.subset(rows);
  const Eigen::VectorXd p = pack(some_hyper(2, M));
  Eigen::VectorXd g1, g2;
  EXPECT_DOUBLE_EQ(sub.evaluate(p, &g1), direct.evaluate(p, &g2));
  EXPECT_LT((g1 - g2).cwiseAbs().maxCoeff(), 1e-12);
}

// The staged fit on a subset reaches the one-stage optimum where the subset determines it
// (a smooth 1-D function, 1200 rows, subset 300): LML within 0.1 % and the same length-scale.
TEST(GaussianProcess, StagedFitReachesTheOneStageOptimum) {
  const int n = 1200;
  Eigen::MatrixXd X(n, 1), Y(n, 1);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.1);
  for (int i = 0; i < n; ++i) {
    X(i, 0) = 10.0 * i / n;
    Y(i, 0) = std::sin(X(i, 0)) + noise(rng);
  }
  Hyper start = some_hyper(1, 0);
  start.lengthscales.setOnes();
  start.signal_var = start.noise_var = 1.0;
  spml::gp::FitOptions one, staged;
  staged.subset_rows = 300;
  Likelihood a(X, Y), b(X, Y);
  const auto r1 = spml::gp::fit(a, start, one);
  const auto r2 = spml::gp::fit(b, start, staged);
  EXPECT_GT(r2.subset_evaluations, 0);
  EXPECT_LE(r2.evaluations, staged.final_evals);
  EXPECT_NEAR(r2.lml, r1.lml, 1e-3 * std::abs(r1.lml));
  EXPECT_NEAR(std::log(r2.hyper.lengthscales[0]), std::log(r1.hyper.lengthscales[0]), 0.05);
  EXPECT_NEAR(std::sqrt(r2.hyper.noise_var), 0.1, 0.01);
}

// With every training row as an inducing input, Q = K and the trace term vanishes: the
// sparse posterior is the exact one, its theta the exact GLS optimum and its bound the LML.
TEST(GaussianProcess, SparsePosteriorWithAllRowsInducingIsExact) {
  const int n = 60, O = 2, M = 3, d = 2;
  Eigen::MatrixXd X = 2.0 * Eigen::MatrixXd::Random(n, d), phi = Eigen::MatrixXd::Random(O * n, M);
  Eigen::MatrixXd Y(n, O);
  const Eigen::Vector3d truth(1.0, -2.0, 0.5);
  const Eigen::VectorXd mean = phi * truth;
  for (int o = 0; o < O; ++o) Y.col(o) = mean.segment(o * n, n) + (X.col(0).array() * (o + 1.0)).sin().matrix();
  Hyper h = some_hyper(d, M);
  h.noise_var = 0.05;
  Likelihood lik(X, Y, phi);
  h.theta = lik.best_theta(pack(h));
  const spml::gp::SparsePosterior sparse(X, Y, phi, X, h);
  EXPECT_LT((sparse.theta() - h.theta).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_NEAR(sparse.bound(), lik.evaluate(pack(h), nullptr), 1e-5 * std::abs(sparse.bound()));
  const spml::gp::Posterior exact(lik, h);
  const Eigen::MatrixXd Xs = 2.5 * Eigen::MatrixXd::Random(25, d), phis = Eigen::MatrixXd::Random(O * 25, M);
  Eigen::MatrixXd m1, v1, m2, v2;
  exact.predict(Xs, phis, &m1, &v1);
  sparse.predict(Xs, phis, &m2, &v2);
  EXPECT_LT((m1 - m2).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_LT((v1 - v2).cwiseAbs().maxCoeff(), 1e-5);
  // Fewer inducing inputs: the bound lies below the LML (Titsias' bound).
  const spml::gp::SparsePosterior coarse(X, Y, phi, X.topRows(10), h);
  EXPECT_LT(coarse.bound(), lik.evaluate(pack(coarse_hyper(h, coarse.theta())), nullptr));
}

TEST(GaussianProcess, JitterLadderRescuesSingularKernel) {
  // Duplicate rows and no noise: K is singular; the ladder must add jitter, not fail.
  Eigen::MatrixXd K = Eigen::MatrixXd::Ones(4, 4);
  Eigen::MatrixXd L;
  const double jitter = spml::gp::cholesky_with_jitter(K, 0.0, 1.0, L);
  EXPECT_GT(jitter, 0.0);
  EXPECT_LE(jitter, 1e-4);
}

}  // namespace
