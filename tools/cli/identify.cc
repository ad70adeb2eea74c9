// spml regressor / spml identify: the parametric model of any MJCF and its identification.
#include <chrono>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "identify_consistent.h"
#include "spml/envs/mjcf_regressor.h"

namespace spml::cli {
namespace {

std::vector<double> vec(const Eigen::VectorXd& v) { return {v.data(), v.data() + v.size()}; }

// The rank decision both commands report (README, "Base parameters"): JSON object, and a
// warning on stderr when it is a close call.
nlohmann::json rank_decision_json(const MjcfRegressor::Base& base) {
  return {{"method", "svd"}, {"tolerance", base.tolerance}, {"smallest_kept", base.smallest_kept},
          {"largest_dropped", base.largest_dropped},
          {"ratio", base.largest_dropped > 0 ? nlohmann::json(base.gap()) : nlohmann::json(nullptr)},
          {"close_call", base.close_call()}, {"singular_values", vec(base.singular_values)}};
}
void warn_close_call(const MjcfRegressor::Base& base) {
  if (const std::string w = rank_decision_warning(base); !w.empty()) std::cerr << "spml: warning: " << w << "\n";
}

// The options both commands take: the model, its optional offset columns, JSON output, and
// where the force plugins the model declares are found beyond the shipped ones.
struct ModelArgs {
  std::string model;
  bool json = false, offsets = false;
  std::vector<std::string> plugin_paths;
};
void add_model_options(CLI::App* cmd, ModelArgs& a, const std::string& model_help) {
  cmd->add_option("--model,-m", a.model, model_help)->required();
  cmd->add_flag("--json", a.json, "print JSON");
  cmd->add_flag("--offsets", a.offsets, "add a constant-torque parameter per joint");
  cmd->add_option("--plugin-path", a.plugin_paths, "extra force-plugin library or folder (also $SPML_PLUGIN_PATH)");
}

}  // namespace

void add_regressor(CLI::App& app) {
  auto* cmd = app.add_subcommand("regressor", "Base parameters of an MJCF model's identification regressor");
  struct Args : ModelArgs { bool bench = false; };
  auto a = std::make_shared<Args>();
  add_model_options(cmd, *a, "MJCF file (hinge/slide joints)");
  cmd->add_flag("--benchmark", a->bench, "also time regressor evaluation (rows per second)");
  cmd->callback([a] {
    add_plugin_paths(a->plugin_paths);
    MjcfRegressor reg(a->model, RegressorOptions{a->offsets});
    warn_inverse_mismatches(reg, a->model);
    auto base = reg.base_parameters();
    warn_close_call(base);
    nlohmann::json j{{"model", a->model}, {"standard_parameters", reg.param_names().size()}, {"rank", base.rank},
                     {"rank_decision", rank_decision_json(base)}, {"names", base.names}, {"prior", vec(base.model_values)}};
    if (a->bench) {
      Eigen::VectorXd q = Eigen::VectorXd::Constant(reg.nv(), 0.3), qd = q, qdd = q;
      const int rows = 20000;
      auto t0 = std::chrono::steady_clock::now();
      double sink = 0;
      auto ws = reg.workspace();
      for (int r = 0; r < rows; ++r) { q[0] = 1e-5 * r; sink += reg.evaluate(ws, q, qd, qdd)(0, 0); }
      double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      j["benchmark_rows_per_second"] = rows / s;
      j["benchmark_checksum"] = sink;
    }
    if (a->json) { std::cout << json_output(j, a->model); return; }
    std::cout << a->model << ": " << reg.param_names().size() << " standard parameters, " << base.rank
              << " base parameters\n  " << rank_decision_text(base, reg.param_names().size()) << "\n";
    for (int i = 0; i < base.rank; ++i)
      std::cout << "  " << std::setw(3) << i << "  " << std::setw(12) << base.model_values[i] << "  " << base.names[i] << "\n";
    if (a->bench) std::cout << "regressor rows per second: " << j["benchmark_rows_per_second"].get<double>() << "\n";
  });
}

void add_identify(CLI::App& app) {
  auto* cmd = app.add_subcommand("identify", "Identification of an MJCF model on a dataset: base parameters by least squares, "
                                              "or every body and joint term physically consistent");
  struct Args : ModelArgs { std::string data, split = "train", estimator, write_model; double prior_weight = 1.0, tracking_hz = 0; };
  auto a = std::make_shared<Args>();
  add_model_options(cmd, *a, "MJCF file");
  cmd->add_option("--data,-d", a->data, "spml/1 dataset with q:/qd:/qdd:<joint> inputs and tau:<joint> targets")->required();
  cmd->add_option("--split", a->split, "split to identify on; every other split is scored as held out");
  cmd->add_option("--estimator", a->estimator, "ls: base parameters by least squares (default); iv: by instrumental variables, "
                  "the instruments from the model simulated along the data (noisy differentiated accelerations do not shrink "
                  "the inertias); consistent: every body's inertial realizable, joint terms >= 0, prior toward the MJCF "
                  "(default with --write-model)")
      ->check(CLI::IsMember({"ls", "iv", "consistent"}));
  cmd->add_option("--tracking-hz", a->tracking_hz, "iv: bandwidth [Hz] of the loop that keeps the simulation on the measured path (default 0: "
                  "the lowest of 1, 2, 4, ... Hz that keeps each joint within 10 % of its motion, 1 % where the dataset records a low-pass)")
      ->check(finite_number(0, 1e3));
  cmd->add_option("--prior-weight", a->prior_weight, "consistent: weight of the prior toward the MJCF (default 1)")
      ->check(finite_number(1e-6, 1e6));   // the bounds of diagnose's --prior-weight
  cmd->add_option("--write-model", a->write_model, "consistent: write the MJCF with the identified inertials and joint terms here");
  cmd->callback([a, cmd] {
    add_plugin_paths(a->plugin_paths);
    if ((a->estimator == "ls" || a->estimator == "iv") && !a->write_model.empty())
      throw CLI::ValidationError("--write-model", "needs --estimator consistent: base parameters do not define every body");
    if (a->estimator != "iv" && cmd->count("--tracking-hz")) throw CLI::ValidationError("--tracking-hz", "applies to --estimator iv only");
    const bool consistent = a->estimator == "consistent" || (a->estimator.empty() && !a->write_model.empty());
    if (!consistent && cmd->count("--prior-weight"))
      throw CLI::ValidationError("--prior-weight", "applies to --estimator consistent only");
    if (consistent)
      return identify_consistent_command({a->model, a->data, a->split, a->write_model, a->json, a->offsets, a->prior_weight});
    MjcfRegressor reg(a->model, RegressorOptions{a->offsets});
    warn_inverse_mismatches(reg, a->model);
    auto base = reg.base_parameters();
    warn_close_call(base);
    Dataset ds = read_dataset(a->data);
    IdentifyOptions io;
    io.estimator = a->estimator == "iv" ? "iv" : "ls";
    io.mjcf_path = a->model;
    io.instruments.tracking_hz = a->tracking_hz;
    Identification id = identify(reg, base, ds, a->split, io);
    nlohmann::json j{{"model", a->model}, {"data", a->data}, {"split", a->split}, {"estimator", id.estimator},
                     {"rank_decision", rank_decision_json(base)},
                     {"names", id.names},
                     {"estimate", vec(id.estimate)}, {"std_error", vec(id.std_error)}, {"prior", vec(id.prior)},
                     {"sigma", id.sigma}, {"condition_number", id.condition}};
    if (id.estimator == "iv") {
      nlohmann::json tr = nlohmann::json::object();
      for (size_t k = 0; k < id.joints.size(); ++k) tr[id.joints[k]] = id.tracking_rms[k];
      j["instruments"] = {{"tracking_hz", id.tracking_hz}, {"tracking_rms", tr}};
    }
    for (const auto& e : id.errors)
      j["errors"].push_back({{"split", e.split}, {"rows", e.rows}, {"relative_error", e.relative_error}, {"rmse", e.rmse}});
    if (a->json) { std::cout << json_output(j, a->model); return; }
    std::cout << "identified on '" << a->split << "' of " << a->data << " by "
              << (id.estimator == "iv" ? "instrumental variables" : "least squares") << " (condition number " << id.condition
              << ", residual std " << id.sigma << ")\n  base parameters: " << rank_decision_text(base, reg.param_names().size())
              << "\n";
    if (id.estimator == "iv") {
      std::cout << "  instruments: the model simulated along the data (tracking " << id.tracking_hz << " Hz); RMS position gap";
      for (size_t k = 0; k < id.joints.size(); ++k) std::cout << " " << id.joints[k] << " " << id.tracking_rms[k];
      std::cout << "\n";
    }
    std::cout << "  " << std::setw(12) << "estimate" << " " << std::setw(12) << "std err" << " " << std::setw(12) << "prior" << "  parameter\n";
    for (size_t i = 0; i < id.names.size(); ++i)
      std::cout << "  " << std::setw(12) << id.estimate[i] << " " << std::setw(12) << id.std_error[i] << " " << std::setw(12) << id.prior[i]
                << "  " << id.names[i] << "\n";
    for (const auto& e : id.errors)
      std::cout << "  " << (e.split == a->split ? "fit      " : "held out ") << e.split << ": relative error "
                << 100 * e.relative_error << " %, RMSE " << e.rmse << " (" << e.rows << " rows)\n";
  });
}

}  // namespace spml::cli
