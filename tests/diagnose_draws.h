// Shared by the diagnose tests (random_chain, num, with_declarations are in test_util.h):
// reading a file, the noise scale of a model, an exact dataset.
#pragma once

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "spml/envs/mjcf_regressor.h"
#include "test_util.h"

namespace spml::test {

inline std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// RMS per joint of a model's torques along a typical trajectory, times 1 %, plus 0.002: the
// noise scale of the draws.
inline std::vector<double> torque_scale(const std::string& path, int J) {
  MjcfRegressor reg(path);
  auto ws = reg.workspace();
  std::vector<double> s(static_cast<size_t>(J), 0.0);
  for (int i = 0; i < 200; ++i) {
    Eigen::VectorXd q(J), qd(J), qdd(J);
    for (int j = 0; j < J; ++j) q[j] = std::sin(0.1 * i + j), qd[j] = std::cos(0.13 * i + j), qdd[j] = 2 * std::sin(0.17 * i);
    const Eigen::VectorXd tau = reg.evaluate(ws, q, qd, qdd) * reg.model_params();
    for (int j = 0; j < J; ++j) s[static_cast<size_t>(j)] += tau[reg.model()->jnt_dofadr[j]] * tau[reg.model()->jnt_dofadr[j]] / 200;
  }
  for (auto& v : s) v = 0.01 * std::sqrt(v) + 0.002;
  return s;
}

}  // namespace spml::test

#include <filesystem>
#include <iostream>

#include "spml/dataset.h"
#include "spml/diagnose.h"

namespace spml::test {

// A dataset of a model along a multi-sine per joint with exact q, qd, qdd (train: the first
// 70 % of rows, test: the rest, time stamps every 5 ms) and white torque noise sigma.
inline Dataset exact_dataset(const std::string& model_path, const std::vector<std::string>& joints, int N, double sigma, unsigned seed) {
  MjcfRegressor reg(model_path);
  const int J = static_cast<int>(joints.size());
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> amp(0.3, 0.6), freq(0.2, 0.6), phase(0, 2 * M_PI);
  std::normal_distribution<double> noise(0, sigma);
  std::vector<double> a(static_cast<size_t>(2 * J)), w(a.size()), p(a.size());
  for (size_t k = 0; k < a.size(); ++k) a[k] = amp(rng), w[k] = 2 * M_PI * freq(rng), p[k] = phase(rng);
  Split all;
  for (const char* pre : {"q:", "qd:", "qdd:"})
    for (const auto& j : joints) all.x_columns.push_back(pre + j);
  for (const auto& j : joints) all.y_columns.push_back("tau:" + j);
  all.X.resize(N, 3 * J);
  all.Y.resize(N, J);
  all.t.resize(N);
  auto ws = reg.workspace();
  Eigen::VectorXd q(J), qd(J), qdd(J);
  for (int i = 0; i < N; ++i) {
    const double t = 0.005 * i;
    all.t[i] = t;
    for (int j = 0; j < J; ++j) {
      q[j] = qd[j] = qdd[j] = 0;
      for (int k = 2 * j; k < 2 * j + 2; ++k) {
        const auto u = static_cast<size_t>(k);
        q[j] += a[u] * std::sin(w[u] * t + p[u]);
        qd[j] += a[u] * w[u] * std::cos(w[u] * t + p[u]);
        qdd[j] -= a[u] * w[u] * w[u] * std::sin(w[u] * t + p[u]);
      }
      all.X(i, j) = q[j], all.X(i, J + j) = qd[j], all.X(i, 2 * J + j) = qdd[j];
    }
    const Eigen::VectorXd tau = reg.evaluate(ws, q, qd, qdd) * reg.model_params();
    for (int j = 0; j < J; ++j) all.Y(i, j) = tau[reg.model()->jnt_dofadr[j]] + (sigma > 0 ? noise(rng) : 0.0);
  }
  Dataset ds;
  const int k = N * 7 / 10;
  ds.splits = {all.slice(0, k, "train"), all.slice(k, N, "test")};
  return ds;
}

// A log of the model `truth` made as a user makes one (spml generate with the options
// `generate`, spml import with the options `import`), diagnosed on the model `given` in `dir`,
// `rollouts` of the confirmation in simulation (0: none). Prints the summary; returns report.json.
// A log of the model at `true_model` as a user makes one: `spml generate --model TRUE <generate>`
// into dir/NAME.csv, then `spml import <import>` into dir/NAME.h5 (returned).
inline std::string generated_log(const std::filesystem::path& dir, const std::string& true_model, const std::string& generate,
                                 const std::string& import, const std::string& name = "log") {
  const std::string csv = (dir / (name + ".csv")).string(), h5 = (dir / (name + ".h5")).string(), bin = spml_bin();
  EXPECT_EQ(run(bin + " generate --model '" + true_model + "' " + generate + " -q -o '" + csv + "' 2>&1").exit_code, 0);
  EXPECT_EQ(run(bin + " import '" + csv + "' " + import + " --out '" + h5 + "' 2>&1").exit_code, 0);
  return h5;
}

inline nlohmann::json diagnose_generated(const std::filesystem::path& dir, const std::string& given, const std::string& truth,
                                        const std::string& generate, const std::string& import, int rollouts = 0) {
  const std::string user = (dir / "user.xml").string(), true_model = (dir / "true.xml").string();
  std::ofstream(user) << given;
  std::ofstream(true_model) << truth;
  DiagnoseOptions o;
  o.model = user;
  o.data = generated_log(dir, true_model, generate, import);
  o.rollouts = rollouts;
  DiagnoseResult r = diagnose(o, "");
  std::cout << r.summary;
  return std::move(r.report);
}

}  // namespace spml::test
