// GP benchmark: one log-marginal-likelihood + gradient evaluation (ARD RBF, every
// hyper-parameter at 1.0, raw targets) on the first --rows training rows of a dataset, and
// optionally a full SPGP fit (the built-in learner, through the plugin ABI) on the whole
// train split. Prints one JSON object; tools/bench/gp_sklearn_peer.py runs scikit-learn on
// the same rows and prints both side by side.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <iostream>
#include <nlohmann/json.hpp>

#include "spml/envs/parametric_model.h"
#include "spml/gp/gp.h"
#include "spml/learners/learner.h"

int main(int argc, char** argv) {
  CLI::App app{"spml GP benchmark"};
  std::string data;
  long rows = 2000;
  int output = 0, repeats = 5;
  bool spgp_fit = false;
  app.add_option("--data", data, "spml/1 dataset (train split is used)")->required()->check(CLI::ExistingFile);
  app.add_option("--rows", rows, "Rows for the likelihood evaluation")->capture_default_str();
  app.add_option("--output", output, "Output column for the likelihood evaluation")->capture_default_str();
  app.add_option("--repeats", repeats, "Timed evaluations (the median is reported)")->capture_default_str();
  bool gp_fit = false, spgp_lml = false;
  std::string sparse_split;
  app.add_option("--sparse-fit", sparse_split, "Also time SPGP-Sparse fitted on every row of this split "
                                               "(e.g. test_interp: 50 000 rows of SimDyn)");
  app.add_flag("--spgp-fit", spgp_fit, "Also time a full SPGP fit (the learner, defaults) on the whole train split");
  app.add_flag("--fit", gp_fit, "Also time a zero-mean GP fit to convergence on the --rows rows (targets / RMS), "
                                 "one stage, as scikit-learn fits (tools/bench/gp_sklearn_peer.py --fit)");
  app.add_flag("--spgp-lml", spgp_lml, "Also fit SPGP on the whole train split twice through spml::gp: staged "
                                       "(the default) and one-stage jointly from the start (before 0.3); print time and LML");
  CLI11_PARSE(app, argc, argv);
  try {
    const spml::Dataset ds = spml::read_dataset(data);
    const spml::Split& train = ds.get("train");
    const Eigen::Index n = std::min<Eigen::Index>(rows, train.rows());
    spml::gp::Likelihood lik(train.X.topRows(n), train.Y.topRows(n).col(output));
    spml::gp::Hyper h;
    h.lengthscales = Eigen::VectorXd::Ones(train.X.cols());
    const Eigen::VectorXd p = spml::gp::pack(h);
    Eigen::VectorXd grad;
    std::vector<double> times;
    double lml = 0;
    for (int r = 0; r < repeats; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      lml = lik.evaluate(p, &grad);
      times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(times.begin(), times.end());
    nlohmann::json out;
    out["rows"] = n;
    out["inputs"] = train.X.cols();
    out["lml"] = lml;
    out["grad_norm"] = grad.norm();
    out["lml_grad_seconds"] = times[times.size() / 2];

    auto seconds_since = [](std::chrono::steady_clock::time_point t0) {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    if (gp_fit) {
      Eigen::MatrixXd y = train.Y.topRows(n).col(output);
      y /= std::sqrt(y.squaredNorm() / static_cast<double>(n));
      spml::gp::Likelihood scaled(train.X.topRows(n), y);
      spml::gp::Hyper start;
      start.lengthscales = Eigen::VectorXd::Ones(train.X.cols());
      const auto t0 = std::chrono::steady_clock::now();
      const spml::gp::FitResult r = spml::gp::fit(scaled, start, spml::gp::FitOptions{});
      out["fit_seconds"] = seconds_since(t0);
      out["fit_lml"] = r.lml;
      out["fit_evaluations"] = r.evaluations;
    }
    if (spgp_lml) {   // the learner's scaling: targets / their RMS over all outputs, theta from the prior
      auto model = spml::make_parametric_model(ds, train);
      const double rms = std::sqrt(train.Y.squaredNorm() / static_cast<double>(train.Y.size()));
      spml::gp::Hyper start;
      start.lengthscales = Eigen::VectorXd::Ones(train.X.cols());
      start.theta = model->prior / rms;
      for (const bool staged : {true, false}) {
        spml::gp::Likelihood lik(train.X, Eigen::MatrixXd(train.Y / rms), model->stacked(train.X));
        spml::gp::FitOptions o;
        o.learn_mean = true;
        o.subset_rows = staged ? 1000 : 0;
        o.kernel_first = staged;
        const auto t0 = std::chrono::steady_clock::now();
        const spml::gp::FitResult r = spml::gp::fit(lik, start, o);
        const std::string key = staged ? "spgp_staged" : "spgp_one_stage";
        out[key + "_seconds"] = seconds_since(t0);
        out[key + "_lml"] = r.lml;
        out[key + "_evaluations"] = r.evaluations + r.subset_evaluations;
      }
    }
    // A learner (defaults, through the plugin ABI) fitted on every row of one split.
    auto time_learner = [&](const std::string& name, const spml::Split& split, const std::string& key) {
      spml::LearnerRegistry registry;
      registry.add_default_path();
      auto learner = registry.create(name);
      auto model = spml::make_parametric_model(ds, train);
      spml::RowMatrix X = split.X, Y = split.Y, phi = model->stacked(split.X);
      spml::LearnerData d{&X, &Y, &phi, static_cast<int>(Y.cols())};
      spml::LearnerModel m{model->param_names, model->prior, model->truth};
      const auto t0 = std::chrono::steady_clock::now();
      learner->fit(d, m, spml::LearnerConfig{});
      out[key + "_fit_rows"] = split.rows();
      out[key + "_fit_seconds"] = seconds_since(t0);
      out[key + "_fit_notes"] = learner->notes();
    };
    if (spgp_fit) time_learner("SPGP", train, "spgp");
    if (!sparse_split.empty()) time_learner("SPGP-Sparse", ds.get(sparse_split), "sparse");
    std::cout << out.dump() << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "bench_gp: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
