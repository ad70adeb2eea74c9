#include <cstdio>
#include <exception>
#include <iostream>

#include "commands.h"

int main(int argc, char** argv) {
  CLI::App app{"spml: semi-parametric model learning for robot dynamics"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "spml 0.1.0 (dataset format spml/1)");
  spml::cli::add_info(app);
  spml::cli::add_import(app);
  spml::cli::add_generate(app);
  spml::cli::add_regressor(app);
  spml::cli::add_identify(app);
  spml::cli::add_bench(app);
  spml::cli::add_compare(app);
  spml::cli::add_learners(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    std::fflush(stdout);
    std::cerr << "spml: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
