// Issue #9: every bad or unusual input of the report, through the command line a user runs.
// Each case checks the exit code and the message (file, place, problem) - or, where the
// input is valid but unusual, the right number.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "spml/dataset.h"
#include "spml/signal.h"

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
  expect_error(spml("import " + csv + " --x a --y y -o " + csv), 2, {"in.csv: is the input file"});
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

// ---- Issue #21: hardening, second round ----

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(Hardening, EveryFloatOptionMustBeFinite) {
  const std::string diagnose = spml("diagnose --model " + mjcf("planar_arm3.xml") + " --data " + f("arm.h5") + " --out " + f("d1") + " ");
  for (const std::string opt : {"--holdout", "--min-gain", "--still-speed", "--rollout-seconds", "--bic-threshold"})
    for (const std::string bad : {"nan", "inf", "-inf", "1e999"})
      expect_error(diagnose + opt + " " + bad, 2, {opt + ": '" + bad + "' is not a finite number"});
  expect_error(diagnose + "--holdout 0.95", 2, {"--holdout: '0.95' is outside [0.05, 0.9]"});
  expect_error(spml("plot --results " + f("none.csv") + " --out " + f("p1") + " --window nan"), 2,
               {"--window: 'nan' is not a finite number"});
  expect_error(spml("plot --results " + f("none.csv") + " --out " + f("p1") + " --window 0"), 2, {"--window: '0' is outside (0,"});
  expect_error(spml("import --text " + f("log.txt") + "=a --x a --y a --lowpass nan -o " + f("l.h5")), 2,
               {"--lowpass: 'nan' is not a finite number"});
  expect_error(spml("identify --model " + mjcf("planar_arm3.xml") + " --data " + f("arm.h5") + " --estimator consistent --prior-weight nan"), 2,
               {"--prior-weight: 'nan' is not a finite number"});
  EXPECT_FALSE(fs::exists(f("d1")));
}

// A declaration its plugin accepts (every LuGre key in range) whose force along the log is
// orders of magnitude beyond the measured torques: refused, naming the element. A review's draw
// with sigma1 = 1e300 crashed (squares of 1e299 overflowed and NaN scores read a null pointer);
// 1e12 ran to "relative error 1.17e+149 %".
TEST(Hardening, ADeclaredForceOrdersOfMagnitudeOffIsRefused) {
  std::string arm = read_file(mjcf("planar_arm3.xml"));
  const auto end = arm.rfind("</mujoco>");
  ASSERT_NE(end, std::string::npos);
  for (const std::string sigma1 : {"1e300", "1e12"}) {
    std::string text = arm;
    text.insert(end, "<custom><text name=\"spml.plugin.lugre\" data=\"type=stick_slip joints=joint1 fc=0.5 fs=0.8 vs=0.1 sigma0=1000 sigma1=" +
                         sigma1 + " sigma2=0\"/></custom>\n");
    const std::string model = f("lugre_" + sigma1 + ".xml");
    std::ofstream(model) << text;
    // (The regressor's check of the model's own inverse dynamics warns first: no expect_error.)
    const auto r = run(spml("diagnose --model " + model + " --data " + f("arm.h5") + " --out " + f("d_absurd") + " --no-plots"));
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("spml: error: " + model + ": <custom><text name=\"spml.plugin.lugre\"> (stick_slip): its force along split 'train'"),
              std::string::npos) << r.output;
    EXPECT_NE(r.output.find("the declared values are off by orders of magnitude"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(f("d_absurd")));
  }
}

// A log of one joint that ends moving: 3000 rows at 1 kHz, q = sin(w t), tau = cos(w t).
void write_sine_log(const std::string& name, double w) {
  std::ofstream log(f(name));
  log << "t,q:j,tau:j\n";
  for (int i = 0; i < 3000; ++i) log << i * 1e-3 << "," << std::sin(w * i * 1e-3) << "," << std::cos(w * i * 1e-3) << "\n";
}

// Too few samples dropped after a low-pass, from a log that ends moving: the import says how
// far the start-up transient reaches (20 Hz, order 4, at 1 kHz: 307 samples); enough dropped,
// nothing is said.
TEST(Hardening, ImportSaysHowManyEdgeSamplesTheFiltersSpoil) {
  write_sine_log("moving.csv", 8.0);
  const std::string import = spml("import " + f("moving.csv") + " --t t --x q:j --y tau:j --lowpass 20 --derive -o " + f("moving.h5") + " --drop-edges ");
  const auto few = run(import + "50");
  EXPECT_EQ(few.exit_code, 0) << few.output;
  EXPECT_NE(few.output.find("moving.csv: --drop-edges 50 keeps part of the low-pass's start-up transient"), std::string::npos) << few.output;
  EXPECT_NE(few.output.find("which reaches 307 samples (0.307 s) into each end of the log: drop at least 307"), std::string::npos) << few.output;
  const auto enough = run(import + "307");
  EXPECT_EQ(enough.exit_code, 0) << enough.output;
  EXPECT_EQ(enough.output.find("warning"), std::string::npos) << enough.output;
}

// A low-passed log kept far above its band: the import says which decimation keeps the band
// (diagnose's fits by simulation cost in proportion to the rows); decimated, nothing is said.
TEST(Hardening, ImportSuggestsTheDecimationThatKeepsTheBand) {
  write_sine_log("fast.csv", 2.0);
  const std::string import = spml("import " + f("fast.csv") + " --t t --x q:j --y tau:j --lowpass 20 --derive --drop-edges 307 -o " + f("fast.h5"));
  const auto kept = run(import);
  EXPECT_EQ(kept.exit_code, 0) << kept.output;
  EXPECT_NE(kept.output.find("fast.csv: the 20 Hz band is sampled at 1000 Hz; --decimate 5 keeps it (200 Hz)"), std::string::npos) << kept.output;
  const auto decimated = run(import + " --decimate 5");
  EXPECT_EQ(decimated.exit_code, 0) << decimated.output;
  EXPECT_EQ(decimated.output.find("note:"), std::string::npos) << decimated.output;
}

// A decimation that leaves no time step is refused with the option named, and no file written
// (a review's --decimate 40000 wrote a one-row dataset); a cut-off too low for the log is said
// (its --lowpass 1e-3 was told to drop more samples than the log had): 3000 rows at 1 kHz.
TEST(Hardening, ImportSaysWhatLeavesNoUsableRow) {
  write_sine_log("short.csv", 2.0);
  const std::string import = spml("import " + f("short.csv") + " --t t --x q:j --y tau:j --derive -o " + f("short.h5"));
  const auto one_row = run(import + " --decimate 40000");
  EXPECT_NE(one_row.exit_code, 0) << one_row.output;
  EXPECT_NE(one_row.output.find("--decimate 40000 keeps 1 row of the 3000 rows; at most 1499 keeps 3"), std::string::npos)
      << one_row.output;
  EXPECT_FALSE(fs::exists(f("short.h5")));
  EXPECT_EQ(run(import + " --decimate 1499").exit_code, 0);   // the bound itself: 3 rows
  const auto split = run(import + " --decimate 700 --split train:0:64% --split test:64%:");   // 5 rows: 3 and 2
  EXPECT_NE(split.exit_code, 0) << split.output;
  EXPECT_NE(split.output.find("split 'test': --decimate 700 leaves it 2 rows (of 5 kept); a split needs 3"), std::string::npos) << split.output;
  // A cut-off whose transient reaches past the middle is the user's to choose (a short log may
  // need it), but no drop is advised that the log cannot give: the cut-off that settles is.
  const auto slow = run(import + " --lowpass 1e-3");
  EXPECT_EQ(slow.exit_code, 0) << slow.output;
  EXPECT_NE(slow.output.find("--lowpass 0.001 Hz: its start-up transient"), std::string::npos) << slow.output;
  EXPECT_EQ(slow.output.find("drop at least"), std::string::npos) << slow.output;
  // The cut-off it names does settle within a quarter of the log (a first form scaled 1e-3 Hz
  // by a capped settling and named 0.14 Hz, whose transient outlasts the log), and the size of
  // a transient that dwarfs the signal is said as such (1e-12 Hz had overflowed to -9e18 %).
  const std::string said = "so no drop leaves a row free of it; a cut-off of ";
  const auto at = slow.output.find(said);
  ASSERT_NE(at, std::string::npos) << slow.output;
  const double named = std::stod(slow.output.substr(at + said.size()));
  EXPECT_GT(named, 0.5);
  EXPECT_LE(spml::settling_samples(spml::butterworth_lowpass(4, named, 1000)), 750);
  EXPECT_GT(spml::settling_samples(spml::butterworth_lowpass(4, 0.98 * named, 1000)), 750);
  const auto tiny = run(import + " --lowpass 1e-12");
  EXPECT_EQ(tiny.output.find("-9223372036854775808"), std::string::npos) << tiny.output;
}

// Output that never reached its file is a failure: a --json document into a full device.
TEST(Hardening, StandardOutputThatCannotBeWrittenIsAnError) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full on this machine";
  for (const std::string& cmd : {std::string("learners --json"), std::string("plugins --json"), "regressor --model " + mjcf("planar_arm3.xml") + " --json"})
    expect_error("(" + spml(cmd) + " >/dev/full)", 1, {"could not write standard output"});   // stderr stays on the pipe
}

TEST(Hardening, TextLogsEmptyNamesAndRaggedLines) {
  std::ofstream(f("log.txt")) << "1 2\n3 4\n5\n6 7 8\n";
  expect_error(spml("import --text " + f("log.txt") + "= --x a --y b -o " + f("l.h5")), 1,
               {"log.txt: no column names after '='"});
  expect_error(spml("import --text " + f("log.txt") + "=a,b --x a --y b -o " + f("l.h5")), 1,
               {"log.txt:3: 1 values, but line 1 and those after it hold 2 (a ragged log"});
  EXPECT_FALSE(fs::exists(f("l.h5")));
}

TEST(Hardening, ImportRefusesLeaksDisorderAndOddOutputs) {
  const std::string csv = f("bom.csv");
  std::ofstream(csv) << "\xEF\xBB\xBFt,a,y\n0,1,2\n0.1,2,4\n0.2,3,6\n0.3,4,8\n";
  expect_error(spml("import " + csv + " --x a --y a -o " + f("i1.h5")), 1,
               {"bom.csv: column 'a' is both an input (--x a) and a target (--y a)"});
  // The byte order mark is not part of the first name: --t t finds the column.
  auto r = run(spml("import " + csv + " --x a --y y --t t -o " + f("i2.h5")));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  std::ofstream(f("unsorted.csv")) << "t,a,y\n0,1,2\n0.2,2,4\n0.1,3,6\n0.3,4,8\n";
  expect_error(spml("import " + f("unsorted.csv") + " --x a --y y --t t -o " + f("i3.h5")), 1,
               {"unsorted.csv: column 't': rows are not in time order (line 4: t = 0.1 after t = 0.2)"});
  // -o that is a folder is named as given, not as the temporary file.
  fs::create_directories(f("outdir"));
  expect_error(spml("import " + csv + " --x a --y y -o " + f("outdir")), 1, {f("outdir") + ": is a directory"});
  r = run(spml("import " + csv + " --x a --y y -o " + f("outdir")));
  EXPECT_EQ(r.output.find(".tmp-"), std::string::npos) << r.output;
  // HDF5's own error stack is not printed before spml's message.
  r = run(spml("import " + f("toy.h5") + " --format mat --x x --y y -o " + f("i4.h5")));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output.find("HDF5-DIAG"), std::string::npos) << r.output;
  EXPECT_LT(std::count(r.output.begin(), r.output.end(), '\n'), 3) << r.output;
}

TEST(Hardening, MatFilesOfEveryIntegerTypeTiesAndTruncation) {
  const std::string mat = f("ints.mat"), truncated = f("ints_truncated.mat");
  auto r = run("/usr/bin/python3 -c \"import numpy as np, scipy.io as sio, sys; n = 6; "
               "sio.savemat(sys.argv[1], {'t': np.arange(n) * 0.1, 'i16': np.array([-3, -2, -1, 0, 1, 30000], np.int16), "
               "'u16': np.arange(n, dtype=np.uint16) * 10000, 'i64': np.arange(n, dtype=np.int64) * 2**40, "
               "'s1': np.arange(3.0), 's2': np.arange(3.0)}); "
               "d = open(sys.argv[1], 'rb').read(); open(sys.argv[2], 'wb').write(d[:len(d) - 20])\" " + mat + " " + truncated);
  if (r.exit_code != 0) GTEST_SKIP() << "no /usr/bin/python3 with scipy: " << r.output;
  // Four vectors of 6 samples (the record) and two of 3.
  r = run(spml("import " + mat + " --x a=i16,b=u16 --y c=i64 --t t -o " + f("m1.h5") + " && " + spml("info --json " + f("m1.h5"))));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  const auto& x = j["splits"][0]["X"]["columns"];
  EXPECT_EQ(x[0]["min"].get<double>(), -3.0);
  EXPECT_EQ(x[0]["max"].get<double>(), 30000.0);
  EXPECT_EQ(x[1]["max"].get<double>(), 50000.0);
  EXPECT_EQ(j["splits"][0]["Y"]["columns"][0]["max"].get<double>(), 5.0 * 1099511627776.0);
  expect_error(spml("import " + truncated + " --x a=i16 --y c=i64 -o " + f("m2.h5")), 1, {"ints_truncated.mat: truncated .mat file"});
  // A tie between record lengths takes the longer vectors, and names the others.
  r = run("/usr/bin/python3 -c \"import numpy as np, scipy.io as sio, sys; "
          "sio.savemat(sys.argv[1], {'a': np.arange(5.0), 'b': np.arange(5.0), 'x': np.arange(8.0), 'y': np.arange(8.0)})\" " + f("tie.mat"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run(spml("import " + f("tie.mat") + " --x x --y y -o " + f("m3.h5")));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("train [8 rows]"), std::string::npos) << r.output;
  expect_error(spml("import " + f("tie.mat") + " --x a --y y -o " + f("m4.h5")), 1,
               {"no column 'a' (available: x, y); vectors of another length, not columns: a (5 samples), b (5 samples)"});
}

// A full disk: tmpfs of 64 KiB in a private mount namespace (unshare -rm, which needs no
// privileges where user namespaces are allowed), or else a file size limit (RLIMIT_FSIZE via
// ulimit -f, SIGXFSZ ignored so that write() fails with EFBIG). The command's exit code and
// the folder's listing are printed from inside, where the small disk is.
struct SmallDisk {
  std::string how;
  std::string run(const std::string& folder, const std::string& cmd) const {
    const std::string body = cmd + "; echo \"rc=$?\"; ls -A " + folder;
    if (how == "tmpfs")
      return spml::test::run("unshare -rm sh -c 'mount -t tmpfs -o size=64k tmpfs " + folder + " && { " + body + "; }'").output;
    return spml::test::run("sh -c 'trap \"\" XFSZ; ulimit -f 128; " + body + "'").output;
  }
};

SmallDisk small_disk(const std::string& folder) {
  fs::create_directories(folder);
  const auto r = spml::test::run("unshare -rm sh -c 'mount -t tmpfs -o size=64k tmpfs " + folder + " && echo mounted'");
  return {r.output.find("mounted") != std::string::npos ? "tmpfs" : "fsize"};
}

TEST(Hardening, FullDiskIsAnErrorAndLeavesNoTemporaryFiles) {
  const std::string disk = f("disk");
  const SmallDisk d = small_disk(disk);
  std::cout << "small disk: " << (d.how == "tmpfs" ? "a 64 KiB tmpfs in a user namespace" : "RLIMIT_FSIZE 64 KiB") << "\n";
  std::ofstream big(f("big.csv"));
  big << "t,a,y\n";
  for (int i = 0; i < 20000; ++i) big << i * 0.01 << "," << i % 7 << "," << i % 5 << "\n";
  big.close();
  for (const std::string& cmd : {spml("generate --scenario simdyn-ll --test-stride 50 -q --out " + disk + "/arm.h5"),
                                 spml("import " + f("big.csv") + " --x a --y y --t t -o " + disk + "/big.h5"),
                                 spml("bench --data " + f("arm.h5") + " --learners LLS --reps 1 --out " + disk + "/bench")}) {
    const std::string out = d.run(disk, cmd);
    EXPECT_NE(out.find("rc=1"), std::string::npos) << cmd << "\n" << out;
    EXPECT_NE(out.find("spml: error: " + disk), std::string::npos) << cmd << "\n" << out;
    EXPECT_EQ(out.find(".tmp-"), std::string::npos) << cmd << "\n" << out;
    EXPECT_EQ(out.find("HDF5-DIAG"), std::string::npos) << cmd << "\n" << out;
  }
}

TEST(Hardening, EmbeddedModelsLiveInAPrivateFolderAndIncludeNothing) {
  const std::string arm = f("arm.h5");
  spml::Dataset ds = spml::read_dataset(arm);
  ds.model = {};
  ds.model.mjcf_xml = read_file(mjcf("planar_arm3.xml"));
  spml::write_dataset(f("arm_inline.h5"), ds);
  ds.model.mjcf_xml = "<mujoco model=\"x\"><include file=\"planar_arm3.xml\"/></mujoco>";
  spml::write_dataset(f("arm_include.h5"), ds);
  const std::string tmp = f("tmpdir");
  fs::create_directories(tmp);
  // A file planted under the old predictable name changes nothing.
  std::ofstream(tmp + "/planar_arm3.xml") << "<mujoco><worldbody/></mujoco>";
  expect_error("TMPDIR=" + tmp + " " + spml("bench --data " + f("arm_include.h5") + " --out " + f("e1") + " --learners LLS"), 1,
               {"arm_include.h5: group 'model': attribute 'mjcf_xml' includes other files"});
  auto r = run("TMPDIR=" + tmp + " " + spml("bench --data " + f("arm_inline.h5") + " --out " + f("e2") + " --learners LLS --reps 1"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_EQ(run(spml("bench --data " + arm + " --out " + f("e3") + " --learners LLS")).exit_code, 0);
  for (int o = 0; o < 3; ++o)
    EXPECT_NEAR(rmse(f("e2/results.csv"), "test_interp", "LLS", o) / rmse(f("e3/results.csv"), "test_interp", "LLS", o), 1.0, 1e-6);
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(tmp)) left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"planar_arm3.xml"});   // the private folder is gone
}

TEST(Hardening, NonUtf8PathsAreNamedBeforeAnythingIsWritten) {
  const std::string latin1 = f("caf\xe9.h5");
  fs::copy_file(f("toy.h5"), latin1, fs::copy_options::overwrite_existing);
  expect_error(spml("bench --data '" + latin1 + "' --out " + f("u1") + " --learners LLS"), 1,
               {latin1 + ": bench.json field 'data': not valid UTF-8 (byte 0xe9"});
  EXPECT_FALSE(fs::exists(f("u1")));
  expect_error(spml("info --json '" + latin1 + "'"), 1, {latin1 + ": the file name is not valid UTF-8"});
  EXPECT_EQ(run(spml("info '" + latin1 + "'")).exit_code, 0);
}

// An interrupted bench of other data must not leave a bench.json that disagrees with the
// results.csv beside it: killed at any moment, the folder holds either the old pair or the
// new bench.json without results.
TEST(Hardening, InterruptedBenchLeavesNoDisagreeingFiles) {
  const std::string out = f("agree");
  ASSERT_EQ(run(spml("bench --data " + f("toy.h5") + " --out " + out + " --learners LLS")).exit_code, 0);
  // The second run is killed as soon as its bench.json names the new data (a GP fit on 5000
  // rows takes seconds, so it is still running then).
  const std::string second = spml("bench --data " + f("arm.h5") + " --out " + out + " --learners GP --reps 1");
  const auto r = run(second + " & pid=$!; for i in $(seq 600); do grep -q arm.h5 " + out +
                     "/bench.json && break; sleep 0.1; done; kill -9 $pid; wait $pid; echo killed=$?");
  EXPECT_NE(r.output.find("killed=137"), std::string::npos) << r.output;
  const auto manifest = nlohmann::json::parse(read_file(out + "/bench.json"));
  EXPECT_EQ(manifest["data"].get<std::string>(), fs::absolute(f("arm.h5")).string());
  EXPECT_FALSE(fs::exists(out + "/results.csv"));
}

}  // namespace
