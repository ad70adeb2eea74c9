// spml plot: the figures of bench results (tools/plots/bench_plots.py under /usr/bin/python3,
// Debian's matplotlib). The inputs are checked here first, so a bad file is named by spml.
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include "commands.h"
#include "spml/learners/compare.h"
#include "spml/learners/results.h"
#include "spml/matrix_file.h"
#include "spml/plugin_loader.h"

namespace spml::cli {

void add_plot(CLI::App& app) {
  auto* cmd = app.add_subcommand("plot", "Draw bench results: RMSE/NLLH bars beside the paper's, predictions +-2 sigma, "
                                         "residuals against position (PNG and PDF)");
  auto results = std::make_shared<std::vector<std::string>>();
  auto predictions = std::make_shared<std::vector<std::string>>();
  auto out = std::make_shared<std::string>();
  auto learners = std::make_shared<std::string>();
  auto window = std::make_shared<double>(2.0);
  auto published = std::make_shared<std::string>(default_published_dir());
  cmd->add_option("--results", *results, "results.csv from spml bench (repeatable)")->required();
  cmd->add_option("--predictions", *predictions, "predictions.h5 from spml bench (repeatable)");
  cmd->add_option("--out", *out, "Folder for the figures")->required();
  cmd->add_option("--learners", *learners, "Learners in the prediction figures (default: LLS and the two best)");
  cmd->add_option("--window", *window, "Seconds of the test split in the prediction figures")
      ->capture_default_str()
      ->check(finite_number(0.0, 1e6, true));
  cmd->add_option("--published", *published, "Folder of the paper's tables")->capture_default_str();
  cmd->callback([=] {
    for (const auto& f : *results) read_results(f);   // throws naming the file and line
    for (const auto& f : *predictions) {
      const MatrixFile p = read_matrix_file(f);
      // Format 1 (outputs by index) is still drawn, with "output K" for a name and no units.
      const std::string format = p.attributes.count("format") ? p.attributes.at("format") : "";
      if (format != "spml-predictions/1" && format != "spml-predictions/2")
        throw std::runtime_error(f + ": not an spml bench predictions.h5 (attribute format is neither spml-predictions/2 "
                                     "nor spml-predictions/1)");
    }
    const std::string script = (std::filesystem::path(spml_share_dir()) / "plots" / "bench_plots.py").string();
    std::string command = "/usr/bin/python3 " + shell_quote(script) + " --out " + shell_quote(*out) + " --published " +
                          shell_quote(*published) + " --window " + std::to_string(*window);
    if (!learners->empty()) command += " --learners " + shell_quote(*learners);
    for (const auto& p : *predictions) command += " --predictions " + shell_quote(p);
    for (const auto& r : *results) command += " " + shell_quote(r);
    std::filesystem::create_directories(*out);
    const int rc = std::system(command.c_str());
    if (rc != 0)
      throw std::runtime_error("plotting failed (" + command + " exited with " + std::to_string(rc) +
                               "; its message is above: where it is a missing matplotlib, tools/install-deps.sh installs python3-matplotlib)");
  });
}

}  // namespace spml::cli
