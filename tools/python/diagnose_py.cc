// spml diagnose from Python: the report.json contents as a dict (and, with out=, every file
// the command writes there except the plots).
#include <pybind11/stl.h>

#include "convert.h"
#include "spml/diagnose.h"

namespace spml::py {
namespace {

// The library's own check of the options (the command line calls the same one), as a
// ValueError: a value `spml diagnose` refuses is refused here with the same words.
void check(const DiagnoseOptions& o) {
  try {
    o.check();
  } catch (const std::invalid_argument& e) {
    throw BadArgument(std::string("diagnose: ") + e.what());
  }
}

pb::object run(const std::string& model, const std::string& data, const std::string& out, const DiagnoseOptions& settings,
               const std::vector<std::string>& plugin_path) {
  add_plugin_paths(plugin_path);
  DiagnoseOptions o = settings;
  o.model = model;
  o.data = data;
  check(o);
  DiagnoseResult r;
  {
    pb::gil_scoped_release release;
    std::vector<std::string> inputs{model, data};
    inputs.insert(inputs.end(), o.cross.begin(), o.cross.end());
    r = naming_missing_files(inputs, [&] { return diagnose(o, out); });
  }
  // report.json's own text, parsed by Python's json: the dict is exactly the file's contents.
  return pb::module_::import("json").attr("loads")(r.report.dump());
}

}  // namespace

void bind_diagnose(pb::module_& m) {
  const DiagnoseOptions d;   // the library's defaults are the module's
  m.def(
      "diagnose",
      [](const std::string& model, const std::string& data, const std::string& out, const std::string& fit_split,
         const std::string& test_split, double holdout, double bic_threshold, double min_gain, int max_causes,
         double still_speed, double rollout_seconds, int rollouts, const std::string& estimator, const std::vector<std::string>& cross,
         const std::vector<std::string>& plugin_path, int threads) {
        DiagnoseOptions o;
        o.fit_split = fit_split;
        o.test_split = test_split;
        o.holdout = holdout;
        o.bic_threshold = bic_threshold;
        o.min_gain = min_gain;
        o.max_causes = max_causes;
        o.still_speed = still_speed;
        o.rollout_seconds = rollout_seconds;
        o.rollouts = rollouts;
        o.estimator = estimator;
        o.cross = cross;
        o.threads = threads;
        return run(model, data, out, o, plugin_path);
      },
      pb::arg("model"), pb::arg("data"), pb::arg("out") = "", pb::arg("fit_split") = d.fit_split, pb::arg("test_split") = d.test_split,
      pb::arg("holdout") = d.holdout, pb::arg("bic_threshold") = d.bic_threshold, pb::arg("min_gain") = d.min_gain,
      pb::arg("max_causes") = d.max_causes, pb::arg("still_speed") = d.still_speed,
      pb::arg("rollout_seconds") = d.rollout_seconds, pb::arg("rollouts") = d.rollouts,
      pb::arg("estimator") = d.estimator, pb::arg("cross") = std::vector<std::string>{}, pb::arg("plugin_path") = std::vector<std::string>{},
      pb::arg("threads") = d.threads);
}

}  // namespace spml::py
