// spml diagnose on inputs the second hardening round (issue #21) found: one candidate plugin
// whose regressor gives NaN is skipped with a note and the diagnosis goes on; a joint whose
// name holds a space is diagnosed and the extended model loads in MuJoCo. Small runs (4 s at
// 250 Hz) of the project's arm with 3 N m of Coulomb friction hidden on the wrist (joint2;
// a declaration's joints= list cannot name a joint with a space, README "diagnose").
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <map>
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

// MJCF frictionloss is a soft constraint in MuJoCo: near zero speed its force is below the level
// (the regressor's fl*sign(qd) was off by up to fl there: 5.6 N m RMS for |qd| < 3e-3 rad/s).
// diagnose predicts MuJoCo's own constraint friction for the model as given, so data simulated
// from a model with frictionloss fit it down to the noise floor of the same run without it:
// the arm with frictionloss 5 on joint1 against the plain arm, same seed, noise and excitation
// (measured: joint1 0.959 % against 0.955 %; with ideal Coulomb before, 2.44 %, and on exact
// 1 kHz data a Stribeck cause invented). Tolerance 1.25x the floor.
TEST(DiagnoseHardening, FrictionlossDataFitTheNoiseFloorAndInventNoCause) {
  std::map<std::string, nlohmann::json> rep;
  for (const std::string fl : {"", "5"}) {
    const auto dir = spml::test::temp_dir("diagnose-frictionloss" + fl);
    std::string arm = read_text(std::string(SPML_SOURCE_DIR) + "/mjcf/planar_arm3.xml");
    if (!fl.empty()) arm = std::regex_replace(arm, std::regex("name=\"joint1\""), "name=\"joint1\" frictionloss=\"" + fl + "\"");
    std::ofstream(dir / "arm.xml") << arm;
    const auto g = run(spml::test::spml_bin() + " generate --model '" + (dir / "arm.xml").string() +
                       "' --duration 8 --rate 500 --seed 3 --derive --out '" + (dir / "d.h5").string() + "' 2>&1");
    ASSERT_EQ(g.exit_code, 0) << g.output;
    rep[fl] = diagnose(dir, "");
    std::filesystem::remove_all(dir);
  }
  const double floor = rep[""]["baseline"]["rel_error_test"]["joint1"], with = rep["5"]["baseline"]["rel_error_test"]["joint1"];
  std::printf("joint1 relative error on test: %.4g %% with frictionloss 5, %.4g %% without\n", 100 * with, 100 * floor);
  EXPECT_LT(with, 1.25 * floor);
  EXPECT_TRUE(rep["5"]["causes"].empty()) << rep["5"]["causes"].dump(1);
}

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
