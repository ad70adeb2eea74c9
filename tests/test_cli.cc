// The spml binary end to end: info on files written by an independent program (h5py), every
// kind of bad input rejected with a message naming it and a non-zero exit, import.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <utility>
#include <nlohmann/json.hpp>

#include "spml/signal.h"
#include "test_util.h"

using spml::test::run;
using spml::test::spml_bin;

namespace {

std::filesystem::path fixtures() {
  static std::filesystem::path dir = [] {
    auto d = spml::test::temp_dir("h5py");
    auto r = run("/usr/bin/python3 " SPML_TEST_PY_DIR "/make_h5py_fixtures.py " + d.string());
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return d;
  }();
  return dir;
}

void expect_rejected(const std::string& file, const std::string& message) {
  auto path = (fixtures() / file).string();
  auto r = run(spml_bin() + " info " + path);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("spml: error: " + path + ": " + message), std::string::npos)
      << "expected '" << message << "' in:\n" << r.output;
}

}  // namespace

TEST(CliInfo, ReadsFileWrittenByH5py) {
  auto r = run(spml_bin() + " info --json " + (fixtures() / "good.h5").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto j = nlohmann::json::parse(r.output);
  ASSERT_EQ(j["splits"].size(), 1u);
  const auto& cols = j["splits"][0]["X"]["columns"];
  EXPECT_EQ(cols[0]["name"], "q:j0");
  EXPECT_DOUBLE_EQ(cols[0]["mean"].get<double>(), 4.5);            // mean of 0..9
  EXPECT_DOUBLE_EQ(cols[1]["max"].get<double>(), 81.0);            // 9^2
  EXPECT_NEAR(cols[0]["std"].get<double>(), 3.0276503540974917, 1e-12);
  EXPECT_EQ(j["model"]["name"], "custom");
  EXPECT_EQ(j["provenance"]["scenario"], "h5py-fixture");
  auto text = run(spml_bin() + " info " + (fixtures() / "good.h5").string());
  EXPECT_EQ(text.exit_code, 0);
  EXPECT_NE(text.output.find("split 'train': 10 rows"), std::string::npos) << text.output;
}

TEST(CliInfo, RejectsNonHdf5) { expect_rejected("not_hdf5.h5", "not an HDF5 file (or truncated / corrupt)"); }
TEST(CliInfo, RejectsTruncated) { expect_rejected("truncated.h5", ""); }
TEST(CliInfo, RejectsMissingFormat) { expect_rejected("no_format.h5", "root attribute 'format' is missing"); }
TEST(CliInfo, RejectsUnknownVersion) { expect_rejected("bad_version.h5", "format version 'spml/2' is not supported"); }
TEST(CliInfo, RejectsMissingX) { expect_rejected("missing_x.h5", "group 'train': dataset 'X' is missing"); }
TEST(CliInfo, RejectsMissingY) { expect_rejected("missing_y.h5", "group 'train': dataset 'Y' is missing"); }
TEST(CliInfo, RejectsRowMismatch) { expect_rejected("rows_differ.h5", "group 'train': X has 10 rows but Y has 9"); }
TEST(CliInfo, RejectsColumnCountMismatch) {
  expect_rejected("columns_mismatch.h5", "group 'train': dataset 'X': attribute 'columns' names 3 columns but the dataset has 2");
}
TEST(CliInfo, RejectsNonFiniteNamingRows) {
  expect_rejected("nonfinite.h5", "group 'train': dataset 'X': non-finite values (NaN/Inf) in 2 row(s): 3, 7");
  auto r = run(spml_bin() + " info --allow-nonfinite " + (fixtures() / "nonfinite.h5").string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
}
TEST(CliInfo, RejectsEmptySplit) { expect_rejected("empty_split.h5", "group 'train': split is empty (0 rows)"); }
TEST(CliInfo, TruncatedMessageSaysSo) {
  auto r = run(spml_bin() + " info " + (fixtures() / "truncated.h5").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("truncated"), std::string::npos) << r.output;
}

TEST(CliGenerate, H5pyReadsWhatSpmlWrites) {
  auto dir = spml::test::temp_dir("gen-h5py");
  auto file = (dir / "toy.h5").string();
  auto g = run(spml_bin() + " generate --scenario toy --seed 3 -q --out " + file);
  ASSERT_EQ(g.exit_code, 0) << g.output;
  auto r = run("/usr/bin/python3 " SPML_TEST_PY_DIR "/read_spml_with_h5py.py " + file);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("h5py read OK"), std::string::npos) << r.output;
  std::filesystem::remove_all(dir);
}

TEST(CliGenerate, UnknownScenarioIsAnError) {
  auto r = run(spml_bin() + " generate --scenario nope --out " + (spml::test::temp_dir("cli-gen") / "x.h5").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("nope"), std::string::npos) << r.output;
}

// Issue #21: mj_id2name gives NULL for an unnamed joint; SimDyn's arm files (found through
// $SPML_MJCF_DIR) with an unnamed or a free joint are refused naming index and type.
TEST(CliGenerate, SimDynArmWithUnnamedOrFreeJointIsRefused) {
  namespace fs = std::filesystem;
  const fs::path dir = spml::test::temp_dir("cli-gen-joints");
  for (const char* f : {"planar_arm3.xml", "planar_arm3_ll.xml", "planar_arm3_prior.xml"})
    fs::copy_file(fs::path(SPML_SOURCE_DIR) / "mjcf" / f, dir / f, fs::copy_options::overwrite_existing);
  std::ifstream in(dir / "planar_arm3.xml");
  const std::string arm((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  struct Case {
    std::string joint, replacement, message;
  };
  const std::string cmd = "SPML_MJCF_DIR=" + dir.string() + " " + spml_bin() + " generate --scenario simdyn-ll -q --out " +
                          (dir / "x.h5").string();
  for (const Case& c : {Case{"<joint name=\"joint1\"/>", "<joint/>", "joint 1 (hinge) has no name"},
                        Case{"<joint name=\"joint0\"/>", "<freejoint name=\"joint0\"/>",
                             "joint 0 'joint0' (free) is not a hinge or slide joint"}}) {
    std::string changed = arm;
    ASSERT_NE(changed.find(c.joint), std::string::npos);
    changed.replace(changed.find(c.joint), c.joint.size(), c.replacement);
    std::ofstream(dir / "planar_arm3.xml") << changed;
    const auto r = run(cmd);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("spml: error: " + (dir / "planar_arm3_ll.xml").string() + ": " + c.message), std::string::npos)
        << r.output;
  }
  EXPECT_FALSE(fs::exists(dir / "x.h5"));
}

TEST(CliImport, CsvRoundTripThroughInfo) {
  auto dir = spml::test::temp_dir("import");
  std::ofstream((dir / "d.csv").string()) << "time,angle,torque\n0,0.1,1\n0.01,0.2,2\n0.02,0.3,3\n0.03,0.4,4\n";
  auto out = (dir / "d.h5").string();
  auto r = run(spml_bin() + " import " + (dir / "d.csv").string() + " --x q:j=angle --y tau:j=torque --t time "
               "--split train:0:3 --split test:3: -o " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto info = run(spml_bin() + " info --json " + out);
  auto j = nlohmann::json::parse(info.output);
  EXPECT_EQ(j["splits"][0]["rows"], 3);
  EXPECT_EQ(j["splits"][1]["rows"], 1);
  EXPECT_DOUBLE_EQ(j["splits"][1]["Y"]["columns"][0]["mean"].get<double>(), 4.0);
  auto bad = run(spml_bin() + " import " + (dir / "d.csv").string() + " --x nothere --y torque -o " + out + ".2");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("no column 'nothere' (available: time, angle, torque)"), std::string::npos) << bad.output;
  EXPECT_FALSE(std::filesystem::exists(out + ".2"));
  std::filesystem::remove_all(dir);
}

// --decimate low-passes first unless --no-anti-alias; the dataset says which (provenance).
TEST(CliImport, DecimationIsRecordedWithItsAntiAliasFilter) {
  auto dir = spml::test::temp_dir("import-decimate");
  std::ofstream csv((dir / "d.csv").string());
  csv << "t,angle,torque\n";
  for (int i = 0; i < 400; ++i) csv << 0.001 * i << "," << std::sin(0.01 * i) << "," << std::cos(0.01 * i) << "\n";
  csv.close();
  for (const std::string extra : {"", " --no-anti-alias"}) {
    const auto out = (dir / ("d" + std::to_string(extra.size()) + ".h5")).string();
    auto r = run(spml_bin() + " import " + (dir / "d.csv").string() + " --x q:j=angle --y tau:j=torque --t t --derive --decimate 4" + extra +
                 " -o " + out);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const auto j = nlohmann::json::parse(run(spml_bin() + " info --json " + out).output);
    const std::string rec = j["provenance"]["decimation"];
    if (extra.empty()) {
      const auto d = spml::parse_decimation_record(rec);
      ASSERT_TRUE(d && d->keep == 4 && d->anti_alias) << rec;
      EXPECT_NEAR(d->anti_alias->cutoff_hz, 0.8 * 0.5 * 1000 / 4, 1e-6);   // 0.8 of the new Nyquist frequency
      EXPECT_EQ(d->anti_alias->order, 8);
    } else {
      EXPECT_EQ(rec, "keep=4 plain");
    }
    EXPECT_EQ(j["splits"][0]["rows"], 100);
  }
}

// Real measurements from ../shared (never committed): MATLAB v5 import via matio.
TEST(CliImport, EmpsMatFile) {
  const char* env = std::getenv("SPML_EMPS_DIR");
  std::filesystem::path dir = env ? env : SPML_SOURCE_DIR "/../shared/data/emps";
  auto mat = dir / "DATA_EMPS.mat";
  if (!std::filesystem::exists(mat)) GTEST_SKIP() << "EMPS data not found at " << mat << " (set SPML_EMPS_DIR)";
  auto tmp = spml::test::temp_dir("emps");
  auto out = (tmp / "emps.h5").string();
  auto r = run(spml_bin() + " import " + mat.string() + " --x q:carriage=qm --y force:carriage=vir*gtau --t t -o " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto info = nlohmann::json::parse(run(spml_bin() + " info --json " + out).output);
  EXPECT_EQ(info["splits"][0]["rows"], 24841);   // the benchmark's documented record length
  // Force = 35.15 N/V * controller output, within the drive's +-10 V saturation.
  double fmax = info["splits"][0]["Y"]["columns"][0]["max"].get<double>();
  EXPECT_GT(fmax, 0.0);
  EXPECT_LE(fmax, 351.5 + 1e-9);
  std::filesystem::remove_all(tmp);
}

TEST(CliRegressor, ArmHasSeventeenBaseParameters) {
  auto r = run(spml_bin() + " regressor --json -m " SPML_SOURCE_DIR "/mjcf/planar_arm3.xml");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j["rank"], 17);
  EXPECT_EQ(j["standard_parameters"], 39);
  // ZZR1 of the paper: link 0's inertia about its joint plus armature and the outer masses.
  bool found = false;
  for (size_t i = 0; i < j["names"].size(); ++i)
    if (j["names"][i] == "Iyy:link0 + m:link1 + m:link2 + armature:joint0") {
      found = true;
      EXPECT_NEAR(j["prior"][i].get<double>(), 9.43, 1e-9);
    }
  EXPECT_TRUE(found) << r.output;
}

TEST(CliIdentify, NamesMissingJointColumn) {
  auto dir = spml::test::temp_dir("identify");
  auto file = (dir / "toy.h5").string();
  ASSERT_EQ(run(spml_bin() + " generate -s toy -q -o " + file).exit_code, 0);
  auto r = run(spml_bin() + " identify -m " SPML_SOURCE_DIR "/mjcf/planar_arm3.xml -d " + file);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("split 'train': no input column 'q:joint0' for model joint 'joint0'"), std::string::npos) << r.output;
  std::filesystem::remove_all(dir);
}

// #20 item 2c: identify --estimator iv on a measured run whose q-dot/q-dot-dot are raw
// differences (generate --derive): the JSON says which estimator ran and how closely the
// instruments' simulation followed; the shoulder inertia is the MJCF's (least squares halves it).
TEST(CliIdentify, InstrumentalVariablesOnRawDifferences) {
  auto dir = spml::test::temp_dir("identify_iv");
  const std::string model = SPML_SOURCE_DIR "/mjcf/planar_arm3.xml", file = (dir / "raw.h5").string();
  ASSERT_EQ(run(spml_bin() + " generate --model " + model + " --duration 20 --encoder-bits 16 --derive --seed 3 -q -o " + file).exit_code, 0);
  auto shoulder = [&](const std::string& estimator) {
    auto r = run(spml_bin() + " identify -m " + model + " -d " + file + " --estimator " + estimator + " --json");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    const auto j = nlohmann::json::parse(r.output);
    EXPECT_EQ(j["estimator"], estimator);
    for (size_t i = 0; i < j["names"].size(); ++i)
      if (j["names"][i] == "Iyy:link0 + m:link1 + m:link2 + armature:joint0") return std::pair{j["estimate"][i].get<double>(), j};
    ADD_FAILURE() << r.output;
    return std::pair{0.0, j};
  };
  const auto [ls, jl] = shoulder("ls");
  const auto [iv, ji] = shoulder("iv");
  EXPECT_LT(ls, 0.5 * 9.43);
  EXPECT_NEAR(iv, 9.43, 0.05 * 9.43);
  EXPECT_GT(ji["instruments"]["tracking_hz"].get<double>(), 0);
  for (const auto& [joint, gap] : ji["instruments"]["tracking_rms"].items()) EXPECT_LT(gap.get<double>(), 0.01) << joint;
  // A loop faster than a tenth of the sampling rate is not stable between the samples.
  auto fast = run(spml_bin() + " identify -m " + model + " -d " + file + " --estimator iv --tracking-hz 200 --json");
  EXPECT_EQ(fast.exit_code, 1);
  EXPECT_NE(fast.output.find("above a tenth of the sampling rate"), std::string::npos) << fast.output;
  auto bad = run(spml_bin() + " identify -m " + model + " -d " + file + " --tracking-hz 2");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("--estimator iv"), std::string::npos) << bad.output;
}

// #23 item 4: diagnose --model takes a URDF as regressor and identify do: MuJoCo's loader
// reads it and diagnose works on the MJCF it compiles to, saved beside the outputs. The data
// come from the same URDF, so the model as given explains them to the noise (0.1 % torque
// noise, raw central differences: below 1 %), the URDF's damping included.
TEST(CliDiagnose, ReadsUrdfThroughMuJoCosLoader) {
  namespace fs = std::filesystem;
  const fs::path dir = spml::test::temp_dir("diagnose-urdf");
  std::ofstream(dir / "arm.urdf") << R"(<?xml version="1.0"?>
<!-- two links, one hinge about z -->
<robot name="arm">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="link1"><inertial><origin xyz="0.2 0 0"/><mass value="2"/>
    <inertia ixx="0.02" iyy="0.03" izz="0.04" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="link1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="100" velocity="10"/><dynamics damping="0.4"/></joint>
</robot>)";
  const std::string spml = spml::test::spml_bin();
  auto r = spml::test::run(spml + " generate --model " + (dir / "arm.urdf").string() + " --duration 4 --derive --encoder-bits 0 "
                           "--torque-noise 0.001 --out " + (dir / "d.h5").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = spml::test::run(spml + " diagnose --model " + (dir / "arm.urdf").string() + " --data " + (dir / "d.h5").string() +
                      " --rollouts 2 --no-plots --out " + (dir / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("diagnosing the MJCF it compiles to"), std::string::npos) << r.output;
  std::ifstream mjcf(dir / "out" / "arm.from-urdf.xml");
  const std::string text((std::istreambuf_iterator<char>(mjcf)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("<mujoco"), std::string::npos) << text;
  EXPECT_NE(text.find("damping=\"0.4\""), std::string::npos) << text;
  EXPECT_TRUE(fs::exists(dir / "out" / "extended.xml"));
  std::ifstream in(dir / "out" / "report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_LT(report["baseline"]["rel_error_test_all"].get<double>(), 0.01) << report["baseline"].dump();
}
