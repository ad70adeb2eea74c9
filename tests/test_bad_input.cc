// Issue #9: every bad or unusual input of the report, through the command line a user runs.
// Each case checks the exit code and the message (file, place, problem) - or, where the
// input is valid but unusual, the right number.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>

#include "spml/learners/results.h"
#include "test_util.h"

namespace {

namespace fs = std::filesystem;
using spml::test::run;

const fs::path& dir() {
  static const fs::path d = [] {
    const fs::path p = spml::test::temp_dir("bad-input");
    const std::string spml = spml::test::spml_bin();
    auto r = run(spml + " generate --scenario toy --out " + (p / "toy.h5").string() + " && " + spml +
                 " generate --scenario simdyn-ll --test-stride 50 --out " + (p / "arm.h5").string() +
                 " && /usr/bin/python3 " SPML_TEST_PY_DIR "/make_bad_inputs.py " + (p / "toy.h5").string() + " " +
                 (p / "arm.h5").string() + " " + p.string());
    if (r.exit_code != 0) ADD_FAILURE() << r.output;
    return p;
  }();
  return d;
}

std::string f(const std::string& name) { return (dir() / name).string(); }
std::string spml(const std::string& args) { return spml::test::spml_bin() + " " + args; }
std::string mjcf(const std::string& file) { return std::string(SPML_SOURCE_DIR) + "/mjcf/" + file; }

// Runs a command that must fail with `code` and print every one of `parts`.
void expect_error(const std::string& cmd, int code, std::initializer_list<std::string> parts) {
  const auto r = run(cmd);
  EXPECT_EQ(r.exit_code, code) << cmd << "\n" << r.output;
  EXPECT_EQ(r.output.rfind("spml: error: ", 0), 0u) << cmd << "\n" << r.output;
  for (const auto& p : parts) EXPECT_NE(r.output.find(p), std::string::npos) << cmd << "\n  wants: " << p << "\n" << r.output;
}

double rmse(const std::string& results, const std::string& split, const std::string& algo, int output = 0) {
  for (const auto& r : spml::read_results(results))
    if (r.split == split && r.algo == algo && r.output == output) return r.rmse_mean;
  ADD_FAILURE() << algo << " " << split << " not in " << results;
  return 0;
}

TEST(BadInput, WideTargetsAreRefusedForModelLearners) {
  expect_error(spml("bench --data " + f("wide_y.h5") + " --out " + f("o1") + " --learners LLS,SPGP"), 1,
               {"wide_y.h5", "model 'toy' predicts the outputs y but Y has the columns y,z"});
  // A learner without the model handles two outputs.
  auto r = run(spml("bench --data " + f("wide_y.h5") + " --out " + f("o2") + " --learners GP --reps 1"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST(BadInput, TestColumnsAreMatchedByName) {
  expect_error(spml("bench --data " + f("junk_test_x.h5") + " --out " + f("o3") + " --learners LLS"), 1,
               {"junk_test_x.h5: split 'test_interp': X: columns differ from the train split's", "not in train: junk"});
  // Test columns in another order give the same numbers as the original.
  ASSERT_EQ(run(spml("bench --data " + f("arm.h5") + " --out " + f("o4") + " --learners LLS")).exit_code, 0);
  ASSERT_EQ(run(spml("bench --data " + f("arm_reordered.h5") + " --out " + f("o5") + " --learners LLS")).exit_code, 0);
  for (int o = 0; o < 3; ++o)
    EXPECT_NEAR(rmse(f("o4/results.csv"), "test_interp", "LLS", o), rmse(f("o5/results.csv"), "test_interp", "LLS", o), 1e-9);
}

TEST(BadInput, AnyMjcfIsAParametricModel) {
  expect_error(spml("bench --data " + f("arm_no_model.h5") + " --out " + f("o6") + " --learners LLS"), 1,
               {"arm_no_model.h5", "no parametric model", "--model"});
  // The MJCF regressor spans the paper's analytic regressor: LLS gives the same fit.
  auto r = run(spml("bench --data " + f("arm_no_model.h5") + " --model " + mjcf("planar_arm3.xml") + " --out " +
                    f("o7") + " --learners LLS,LLS-prior"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_EQ(run(spml("bench --data " + f("arm.h5") + " --out " + f("o8") + " --learners LLS")).exit_code, 0);
  for (int o = 0; o < 3; ++o)
    EXPECT_NEAR(rmse(f("o7/results.csv"), "test_interp", "LLS", o) / rmse(f("o8/results.csv"), "test_interp", "LLS", o),
                1.0, 1e-6);
}

TEST(BadInput, ImportNeverOverwritesItsInputNorLeaksRows) {
  const std::string csv = f("in.csv");
  std::ofstream(csv) << "a,y\n1,2\n2,4\n3,6\n4,8\n";
  expect_error(spml("import " + csv + " --x a --y y -o " + csv), 1, {"in.csv: is an input file"});
  std::ifstream in(csv);
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in)), {}), "a,y\n1,2\n2,4\n3,6\n4,8\n");
  expect_error(spml("import " + csv + " --x a --y y --split train:0:75% --split test:50%: -o " + f("o.h5")), 1,
               {"split 'test': rows [2, 4) overlap split 'train' rows [0, 3)"});
  expect_error(spml("import " + f("toy.h5") + " --x x --y y -o " + f("o.h5")), 1, {"toy.h5: is an HDF5 file, not CSV"});
  expect_error(spml("import " + csv + " --x a --y y --split train:0:2 --split train:2: -o " + f("o.h5")), 1,
               {"split 'train' is given twice"});
  EXPECT_FALSE(fs::exists(f("o.h5")));
}

TEST(BadInput, ModelsWithoutJointsAreRefused) {
  const std::string empty = f("empty.xml"), welded = f("welded.xml");
  std::ofstream(empty) << "<mujoco><worldbody/></mujoco>";
  std::ofstream(welded) << "<mujoco><worldbody><body name=\"b\"><geom size=\"0.1\"/></body></worldbody></mujoco>";
  expect_error(spml("regressor --model " + empty), 1, {"empty.xml: the model has no joints"});
  expect_error(spml("identify --model " + welded + " --data " + f("arm.h5")), 1, {"welded.xml: the model has no joints"});
}

TEST(BadInput, IdentifyRefusesWhatItCannotEstimate) {
  const std::string arm = " --model " + mjcf("planar_arm3.xml") + " --data ";
  expect_error(spml("identify" + arm + f("huge_qd.h5")), 1,
               {"huge_qd.h5: split 'train' row 10: the regressor is not finite"});
  expect_error(spml("identify" + arm + f("five_rows.h5")), 1,
               {"five_rows.h5: split 'train': 15 equations (5 rows x 3 torques) for 17 base parameters: too few rows"});
  expect_error(spml("identify" + arm + f("constant.h5")), 1,
               {"constant.h5: split 'train': the data do not excite every base parameter", "not identifiable"});
  expect_error(spml("identify" + arm + f("duplicate_column.h5")), 1,
               {"duplicate_column.h5: group 'train': dataset 'X': column name 'q:joint0' appears twice"});
  expect_error(spml("identify" + arm + f("arm.h5") + " --split nope"), 1, {"arm.h5: no split 'nope' (the file has: train"});
  // The valid file identifies with finite standard errors.
  auto r = run(spml("identify" + arm + f("arm.h5") + " --json"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("nan"), std::string::npos) << r.output;
}

TEST(BadInput, ReaderRefusesNamelessColumnsAndNonFiniteTime) {
  expect_error(spml("info " + f("empty_column.h5")), 1, {"empty_column.h5: group 'train': dataset 'X': column 1 has an empty name"});
  expect_error(spml("info " + f("nan_t.h5")), 1, {"nan_t.h5: group 'train': dataset 't': non-finite values (NaN/Inf) in 1 row(s): 3"});
}

TEST(BadInput, CommandLineValuesAreCheckedStrictly) {
  const std::string bench = spml("bench --data " + f("toy.h5") + " --out " + f("o9") + " --learners LLS ");
  expect_error(bench + "--seed -1", 2, {"--seed: '-1' is not a seed"});
  expect_error(bench + "--seed 18446744073709551616", 2, {"--seed: '18446744073709551616' is not a seed"});
  expect_error(bench + "--train-max 0", 2, {"--train-max: '0' is neither 'all' nor a whole number of rows >= 1"});
  expect_error(bench + "--train-max -1", 2, {"--train-max"});
  expect_error(bench + "--set max_evals", 2, {"--set: 'max_evals': expected key=value"});
  expect_error(bench + "--no-such-option", 2, {"--no-such-option"});
  expect_error(spml("bench --data " + f("missing.h5") + " --out " + f("o10") + " --learners LLS"), 1, {"missing.h5: no such file"});
  const auto r = run(spml("generate --scenario toy --test-stride 0 --out " + f("t.h5")));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--test-stride: '0' is not a whole number in [1, 1000000]"), std::string::npos) << r.output;
  EXPECT_LT(r.output.size(), 200u) << r.output;
  // A seed of 2^64 - 1 is a seed.
  EXPECT_EQ(run(bench + "--seed 18446744073709551615 --reps 1").exit_code, 0);
}

TEST(BadInput, SearchPathsWarnAlikeAndSkipBrokenLibraries) {
  auto r = run("SPML_LEARNER_PATH=" + f("nowhere") + " " + spml("learners"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("spml: warning: " + f("nowhere") + ": no such learner library or folder (named in $SPML_LEARNER_PATH); ignored"),
            std::string::npos) << r.output;
  r = run("SPML_PLUGIN_PATH=" + f("nowhere") + " " + spml("plugins"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("spml: warning: " + f("nowhere") + ": no such force plugin library or folder (named in $SPML_PLUGIN_PATH); ignored"),
            std::string::npos) << r.output;
  // A folder holding two broken libraries: both named, skipped, and the command still works.
  r = run("SPML_LEARNER_PATH=" SPML_TEST_LEARNER_DIR " " + spml("learners"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("wrong_abi_learner.so: learner ABI version 99"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("not_a_learner.so: missing symbol"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("LLS\t"), std::string::npos) << r.output;
  // Named explicitly, a broken library is an error.
  expect_error(spml("learners --learner-path " SPML_TEST_LEARNER_DIR "/wrong_abi_learner.so"), 1, {"wrong_abi_learner.so: learner ABI version 99"});
}

}  // namespace
