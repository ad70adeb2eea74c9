#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <malloc.h>
#include <new>

#include <mujoco/mujoco.h>

#include "commands.h"
#include "spml/force_plugin.h"
#include "spml/learner.h"
#include "spml/version.h"

namespace {

// Every failure leaves as "spml: error: <file>: <where>: <problem>" with a non-zero exit:
// 2 for a command line that does not parse, 1 for everything else.
int fail(const std::string& message, int code) {
  std::fflush(stdout);
  std::cerr << "spml: error: " << message << "\n";
  return code;
}

}  // namespace

// MuJoCo prints its warnings on stdout (and into MUJOCO_LOG.TXT in the working directory):
// stdout may be a --json document, so they go to stderr instead.
void mujoco_warning_to_stderr(const char* msg) { std::cerr << "spml: MuJoCo warning: " << msg << "\n"; }

int main(int argc, char** argv) {
  mju_user_warning = mujoco_warning_to_stderr;
  // Designs of tens of MB are made and dropped hundreds of times (diagnose's searches on 10^5
  // rows): above glibc's mmap threshold each one is fresh pages the kernel must fault in and
  // zero (15 of 90 s on the undecimated Panda). Kept in the heap they are reused.
  mallopt(M_MMAP_THRESHOLD, 1 << 30);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  CLI::App app{"spml: semi-parametric model learning for robot dynamics"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "spml " SPML_VERSION " (dataset format spml/1, learner ABI " +
                                        std::to_string(SPML_LEARNER_ABI_VERSION) + ", force-plugin ABI " +
                                        std::to_string(SPML_FORCE_PLUGIN_ABI_VERSION) + ")");
  spml::cli::add_info(app);
  spml::cli::add_import(app);
  spml::cli::add_generate(app);
  spml::cli::add_regressor(app);
  spml::cli::add_identify(app);
  spml::cli::add_bench(app);
  spml::cli::add_merge(app);
  spml::cli::add_compare(app);
  spml::cli::add_plot(app);
  spml::cli::add_learners(app);
  spml::cli::add_plugins(app);
  spml::cli::add_diagnose(app);
  spml::cli::add_check_plugin(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {   // --help, --help-all, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    return fail(std::string(e.what()) + " (see spml " + (argc > 1 ? std::string(argv[1]) + " " : "") + "--help)", 2);
  } catch (const std::filesystem::filesystem_error& e) {
    std::string where = e.path1().string();
    if (!e.path2().empty()) where += " -> " + e.path2().string();
    return fail(where + ": " + e.code().message(), 1);
  } catch (const std::bad_alloc&) {
    return fail("out of memory (is the input far larger than expected? see --train-max / --test-max)", 1);
  } catch (const std::exception& e) {
    return fail(e.what(), 1);
  }
  // A --json document or table that did not reach its file is a failure (a full disk, a
  // closed pipe), not a silent success.
  std::cout.flush();
  if (!std::cout || std::fflush(stdout) != 0 || std::ferror(stdout))
    return fail("could not write standard output (a full disk, or a closed pipe?)", 1);
  return 0;
}
