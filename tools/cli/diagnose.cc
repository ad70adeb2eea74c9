// spml diagnose: what an MJCF gets wrong on measured data, the cause, the extended model, the gain.
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include <fstream>
#include <unistd.h>

#include "commands.h"
#include "spml/diagnose.h"
#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"
#include "spml/plugin_loader.h"

namespace spml::cli {
namespace {

// True when the file's first element is <robot> (a URDF): comments, the <?xml?> declaration
// and a doctype before it are skipped.
bool is_urdf(const std::string& path) {
  std::ifstream in(path);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (size_t i = text.find('<'); i != std::string::npos; i = text.find('<', i + 1)) {
    if (text.compare(i, 4, "<!--") == 0) {
      i = text.find("-->", i);
      if (i == std::string::npos) return false;
      continue;
    }
    if (text.compare(i, 2, "<?") == 0 || text.compare(i, 2, "<!") == 0) continue;
    return text.compare(i, 6, "<robot") == 0 && (i + 6 >= text.size() || !std::isalnum(static_cast<unsigned char>(text[i + 6])));
  }
  return false;
}

// A URDF is read by MuJoCo's own loader, as `regressor` and `identify` read it, and saved as
// the MJCF it compiles to, OUT/<stem>.from-urdf.xml (written atomically); diagnose works on
// that file, and extended.xml extends it. An MJCF is used as given.
std::string mjcf_of(const std::string& model, const std::string& out) {
  if (!std::filesystem::exists(model) || !is_urdf(model)) return model;
  const ModelPtr m = load_mjcf(model);
  std::filesystem::create_directories(out);
  const std::string mjcf = (std::filesystem::path(out) / (std::filesystem::path(model).stem().string() + ".from-urdf.xml")).string();
  const std::string tmp = mjcf + ".tmp-" + std::to_string(::getpid());
  char error[1000] = {0};
  if (!mj_saveLastXML(tmp.c_str(), m.get(), error, sizeof error)) {
    std::filesystem::remove(tmp);
    throw std::runtime_error(model + ": MuJoCo read the URDF but could not save it as MJCF (" + mjcf + "): " + error);
  }
  std::filesystem::rename(tmp, mjcf);
  std::cerr << "read the URDF " << model << " with MuJoCo's loader; diagnosing the MJCF it compiles to, " << mjcf << "\n";
  return mjcf;
}

}  // namespace

void add_diagnose(CLI::App& app) {
  auto* cmd = app.add_subcommand("diagnose", "Name what a model gets wrong on measured data, write the extended MJCF, measure the gain");
  auto o = std::make_shared<DiagnoseOptions>();
  auto out = std::make_shared<std::string>();
  auto paths = std::make_shared<std::vector<std::string>>();
  auto no_plots = std::make_shared<bool>(false);
  auto datas = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--model,-m", o->model, "MJCF or URDF of the robot (hinge/slide joints)")->required();
  cmd->add_option("--data,-d", *datas, "spml/1 dataset with q:/qd:/qdd:<joint> inputs and tau:<joint> targets; repeat for several records of one robot (fitted together, each record's test part held out)")
      ->required()->take_all();
  cmd->add_option("--fit-split", o->fit_split, "split the causes are fitted on")->capture_default_str();
  cmd->add_option("--test-split", o->test_split,
                  "split the gain is measured on (default: the first other split; with one split, its last --holdout rows)");
  cmd->add_option("--holdout", o->holdout, "fraction held out (time-ordered) when the dataset has one split")
      ->capture_default_str()->check(finite_number(0.05, 0.9));
  cmd->add_option("--cross", o->cross, "another dataset (e.g. a validation record) scored before, after each cause and after all; repeatable");
  cmd->add_option("--out,-o", *out, "output folder: report.json, report.md, extended.xml, series.csv, rollouts.csv, plots/")->required();
  cmd->add_option("--plugin-path", *paths, "extra force-plugin library or folder: its plugins are candidates too (also $SPML_PLUGIN_PATH)");
  cmd->add_option("--bic-threshold", o->bic_threshold, "evidence a cause needs on the fit split (Delta BIC)")
      ->capture_default_str()->check(finite_number(0.0, 1e9));
  cmd->add_option("--min-gain", o->min_gain, "relative drop of its joints' test residual sum of squares a cause needs")
      ->capture_default_str()->check(finite_number(0.0, 1.0));
  cmd->add_option("--max-causes", o->max_causes, "stop after this many causes")->capture_default_str()->check(CLI::Range(1, 1000));
  cmd->add_option("--still-speed", o->still_speed, "a joint whose |qd| never exceeds this does not move")->capture_default_str()->check(finite_number(0.0, 1e9));
  cmd->add_option("--rollout-seconds", o->rollout_seconds, "length of each rollout")->capture_default_str()->check(finite_number(1e-3, 10.0));
  cmd->add_option("--rollouts", o->rollouts, "number of rollouts (0: none)")->capture_default_str()->check(CLI::Range(0, 10000));
  cmd->add_option("--min-ripple-periods", o->min_ripple_periods, "ripple is searched only at wavenumbers whose periods the stroke spans this often")
      ->capture_default_str()->check(finite_number(0.0, 1e6));
  cmd->add_option("--ripple-gear", o->ripple_gear, "the drive's gear ratio: ripple is searched at this wavenumber only (0: search)")
      ->capture_default_str()->check(finite_number(0.0, 1e9));
  cmd->add_option("--estimator", o->estimator, "base parameters whose contradiction of the MJCF names `parameters`: iv (instrumental "
                  "variables, instruments from the model simulated along the data; default) or ls (least squares)")
      ->check(CLI::IsMember({"iv", "ls"}));
  cmd->add_option("--prior-weight", o->prior_weight, "weight of the prior toward the MJCF in the consistent fit extended.xml states when parameters are named")
      ->capture_default_str()->check(finite_number(1e-6, 1e6));
  cmd->add_option("--threads", o->threads, "threads for the searches (0: the machine's cores, at most 4); the report does not depend on it")
      ->capture_default_str()->check(CLI::Range(0, 256));
  cmd->add_flag("--no-plots", *no_plots, "do not draw plots/ (needs /usr/bin/python3 with matplotlib)");
  cmd->callback([=] {
    o->data = datas->front();
    o->more_data.assign(datas->begin() + 1, datas->end());
    add_plugin_paths(*paths);
    for (const auto& w : force_plugins().warnings()) std::cerr << "spml: warning: " << w << "\n";
    o->check();
    o->model = mjcf_of(o->model, *out);
    auto plots = [&](const std::string& staged) {
      if (*no_plots) return;
      const std::string script = (std::filesystem::path(spml_share_dir()) / "plots" / "diagnose_plots.py").string();
      const std::string command = "/usr/bin/python3 " + shell_quote(script) + " " + shell_quote(staged);
      if (std::system(command.c_str()) != 0)
        std::cerr << "spml: warning: plots not drawn (" << command << " failed; its message is above: where it is a missing matplotlib, tools/install-deps.sh installs python3-matplotlib)\n";
    };
    const DiagnoseResult r = diagnose(*o, *out, plots);
    std::cout << r.summary;
    const auto& t = r.report["timings_s"];
    std::cout << "  time: search " << t["search"].get<double>() << " s, refits " << t["refits"].get<double>() << " s, rollouts "
              << t["rollouts"].get<double>() << " s, load " << t["load"].get<double>() << " s, outputs " << t["outputs"].get<double>() << " s\n";
    const bool traced = r.report.contains("rollout") && r.report["rollout"].contains("traced");   // rollouts.csv written
    std::cout << "  wrote " << *out << "/report.json, report.md, extended.xml, series.csv" << (traced ? ", rollouts.csv" : "")
              << (*no_plots ? "" : ", plots/") << "\n";
  });
}

}  // namespace spml::cli
