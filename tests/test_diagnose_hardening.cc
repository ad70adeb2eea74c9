// spml diagnose on inputs the second hardening round (issue #21) found: one candidate plugin
// whose regressor gives NaN is skipped with a note and the diagnosis goes on; a joint whose
// name holds a space is diagnosed and the extended model loads in MuJoCo. Small runs (4 s at
// 250 Hz) of the project's arm with 3 N m of Coulomb friction hidden on the wrist (joint2;
// a declaration's joints= list cannot name a joint with a space, README "diagnose").
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include "test_util.h"

namespace {

using spml::test::run;

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Writes the arm (joint1 renamed `elbow`) and its true version with the hidden friction, and
// generates a small dataset from the true one; returns the data file.
std::string arm_data(const std::filesystem::path& dir, const std::string& elbow) {
  std::string arm = read_text(std::string(SPML_SOURCE_DIR) + "/mjcf/planar_arm3.xml");
  arm = std::regex_replace(arm, std::regex("name=\"joint1\""), "name=\"" + elbow + "\"");
  std::ofstream(dir / "arm.xml") << arm;
  std::ofstream(dir / "true.xml") << std::regex_replace(
      arm, std::regex("</mujoco>"), "<custom><text name=\"spml.plugin.hidden\" data=\"type=coulomb joints=joint2 fc=3\"/></custom></mujoco>");
  const auto g = run(spml::test::spml_bin() + " generate --model '" + (dir / "true.xml").string() + "' --duration 4 --rate 250 --seed 2 --derive --out '" +
                     (dir / "d.h5").string() + "' 2>&1");
  EXPECT_EQ(g.exit_code, 0) << g.output;
  return (dir / "d.h5").string();
}

nlohmann::json diagnose(const std::filesystem::path& dir, const std::string& extra) {
  const auto r = run(spml::test::spml_bin() + " diagnose --model '" + (dir / "arm.xml").string() + "' --data '" + (dir / "d.h5").string() +
                     "' --out '" + (dir / "out").string() + "' --no-plots --rollouts 2 " + extra + " 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  std::printf("%s", r.output.c_str());
  return nlohmann::json::parse(read_text((dir / "out" / "report.json").string()));
}

bool names_cause(const nlohmann::json& rep, const std::string& effect, const std::string& joint) {
  for (const auto& c : rep["causes"])
    if (c.value("effect", "") == effect && c["joints"] == nlohmann::json::array({joint})) return true;
  return false;
}

}  // namespace

TEST(DiagnoseHardening, ACandidateWithANanRegressorIsSkippedAndTheDiagnosisGoesOn) {
  const auto dir = spml::test::temp_dir("diagnose-nan-candidate");
  arm_data(dir, "joint1");
  const auto rep = diagnose(dir, "--plugin-path " + std::string(SPML_BROKEN_DIR) + "/force_nan_regressor.so");
  bool skipped = false;
  for (const auto& n : rep["not_tried"])
    skipped |= n.value("effect", "") == "broken_viscous" &&
               n.value("reason", "").find("skipped: plugin 'broken_viscous' gave non-finite regressor values") != std::string::npos;
  EXPECT_TRUE(skipped) << rep["not_tried"].dump(1);
  EXPECT_TRUE(names_cause(rep, "coulomb", "joint2")) << rep["causes"].dump(1);
  std::filesystem::remove_all(dir);
}

TEST(DiagnoseHardening, AJointNameWithASpaceIsDiagnosedAndTheExtendedModelLoads) {
  const auto dir = spml::test::temp_dir("diagnose-space");
  arm_data(dir, "elbow joint");
  const auto rep = diagnose(dir, "");
  EXPECT_TRUE(names_cause(rep, "coulomb", "joint2")) << rep["causes"].dump(1);
  // MuJoCo loads the written model (the regressor command compiles it).
  const auto r = run(spml::test::spml_bin() + " regressor --model '" + (dir / "out" / "extended.xml").string() + "' 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(read_text((dir / "out" / "extended.xml").string()).find("<joint name=\"elbow joint\""), std::string::npos);
  std::filesystem::remove_all(dir);
}
