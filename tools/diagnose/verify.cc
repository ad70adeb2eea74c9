// Stage 6, verification: the written model. extended.xml is written from the edits, reloaded,
// and its own inverse dynamics must reproduce the final prediction; rollouts of the model as
// given and of extended.xml under the measured torques.
#include <filesystem>
#include <unistd.h>

#include "diagnosis.h"
#include "rollout.h"
#include "spml/matrix_file.h"

namespace spml::diagnose_detail {

void Diagnosis::verify(const std::string& out_dir, MjcfEdits& edits, std::vector<std::string>& notes, const Eigen::VectorXd& final_pred_fit) {
  namespace fs = std::filesystem;
  auto t0 = Clock::now();
  nlohmann::json& R = result_.report;
  edits.comment = "extended by spml diagnose from " + opt_.model + " and " + opt_.data + " (fit split '" + opt_.fit_split + "')";
  result_.extended_mjcf = write_extended_mjcf(opt_.model, edits, notes);
  const fs::path ext_path = out_dir.empty() ? fs::temp_directory_path() / ("spml-extended-" + std::to_string(::getpid()) + ".xml")
                                            : fs::path(out_dir) / "extended.xml";
  if (!out_dir.empty()) fs::create_directories(out_dir);
  write_text_atomic(ext_path.string(), result_.extended_mjcf);
  R["extended_mjcf"] = out_dir.empty() ? "" : "extended.xml";
  {
    MjcfRegressor ext(ext_path.string());
    auto ebase = ext.base_parameters();
    const JointColumns cols(ext, fit_.split);
    const Eigen::MatrixXd A = stacked_base_regressor(ext, ebase, fit_.split.X, cols, fit_.name);
    const Eigen::VectorXd pred = A * ebase.model_values;
    R["extended_check"] = {{"max_abs_deviation", (pred - final_pred_fit).cwiseAbs().maxCoeff()},
                           {"rms_torque", std::sqrt(fit_.b.squaredNorm() / static_cast<double>(fit_.b.size()))}};
  }
  result_.timings.outputs += since(t0);
  t0 = Clock::now();
  if (opt_.rollouts > 0) {
    try {
      const RolloutResult before = rollout(opt_.model, test_.split, opt_.rollouts, opt_.rollout_seconds);
      const RolloutResult after = rollout(ext_path.string(), test_.split, opt_.rollouts, opt_.rollout_seconds);
      nlohmann::json b = nlohmann::json::object(), a = nlohmann::json::object();
      for (size_t j = 0; j < before.joints.size(); ++j) {
        b[before.joints[j]] = before.position_error[j];
        a[after.joints[j]] = after.position_error[j];
      }
      R["rollout"] = {{"split", test_name_}, {"horizon_s", opt_.rollout_seconds}, {"windows", before.windows},
                      {"position_error_before", b}, {"position_error_after", a}};
    } catch (const std::exception& e) {
      R["rollout"] = {{"skipped", e.what()}};
    }
  }
  if (out_dir.empty()) fs::remove(ext_path);
  result_.timings.rollouts += since(t0);
}

}  // namespace spml::diagnose_detail
