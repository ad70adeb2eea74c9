// The reviewer's findings on the installed tool (outputs over inputs, units of slide joints,
// error texts), each through the command line: exit code and message, or the right value.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "test_util.h"

namespace {

namespace fs = std::filesystem;
using spml::test::run;

// A hinge joint j0 carrying a slide joint j1 (the reviewer's sl.xml).
const char* kSlideModel = R"(<mujoco model="m2">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <default><joint type="hinge" axis="0 -1 0" armature="0.1" damping="0.5"/><geom type="capsule" size="0.03" contype="0" conaffinity="0"/></default>
  <worldbody>
    <body name="l0"><joint name="j0"/>
      <inertial pos="0.25 0 0" mass="2" diaginertia="0.01 0.05 0.05"/><geom fromto="0 0 0 0.5 0 0"/>
      <body name="l1" pos="0.5 0 0"><joint name="j1" type="slide" axis="1 0 0"/>
        <inertial pos="0.2 0 0" mass="1" diaginertia="0.01 0.02 0.02"/><geom fromto="0 0 0 0.4 0 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
)";

const fs::path& dir() {
  static const fs::path d = [] {
    const fs::path p = spml::test::temp_dir("cli-guards");
    std::ofstream(p / "sl.xml") << kSlideModel;
    const auto r = run("cd " + p.string() + " && " + spml::test::spml_bin() +
                       " generate --model sl.xml --duration 2 --out sl.csv && " + spml::test::spml_bin() +
                       " import sl.csv --t t --x q:j0,q:j1 --y tau:j0,tau:j1 --lowpass 20 --derive --drop-edges 50"
                       " --split train:0:70% --split test:70%: --out sl.h5");
    if (r.exit_code != 0) ADD_FAILURE() << r.output;
    return p;
  }();
  return d;
}

// Runs spml with `args` in dir().
spml::test::RunResult spml(const std::string& args) { return run("cd " + dir().string() + " && " + spml::test::spml_bin() + " " + args); }

std::string text(const fs::path& f) {
  std::ifstream in(f, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

void expect_error(const spml::test::RunResult& r, int code, std::initializer_list<std::string> parts) {
  EXPECT_EQ(r.exit_code, code) << r.output;
  EXPECT_EQ(r.output.rfind("spml: error: ", 0), 0u) << r.output;
  for (const auto& p : parts) EXPECT_NE(r.output.find(p), std::string::npos) << "wants: " << p << "\n" << r.output;
}

TEST(CliGuards, GenerateNeverWritesOverItsInputs) {
  fs::copy_file(dir() / "sl.xml", dir() / "victim.xml", fs::copy_options::overwrite_existing);
  const std::string model = text(dir() / "victim.xml"), log = text(dir() / "sl.csv");
  // Same file spelt differently: compared by identity, not by text.
  expect_error(spml("generate --model victim.xml --duration 1 --out ./victim.xml"), 2,
               {"./victim.xml: is the input file victim.xml", "choose another --out"});
  expect_error(spml("generate --model sl.xml --excitation file:sl.csv --out ../" + dir().filename().string() + "/sl.csv"), 2,
               {"/sl.csv: is the input file sl.csv"});
  EXPECT_EQ(text(dir() / "victim.xml"), model);
  EXPECT_EQ(text(dir() / "sl.csv"), log);
  fs::create_symlink(dir() / "sl.csv", dir() / "link.csv");
  expect_error(spml("import sl.csv --t t --x q:j0 --y tau:j0 --out link.csv"), 2, {"link.csv: is the input file sl.csv"});
  EXPECT_EQ(text(dir() / "sl.csv"), log);
}

TEST(CliGuards, BenchNeverWritesOverInputsInsideOut) {
  for (const char* f : {"b5/predictions.h5", "b6/bench.json", "b1/results.csv", "b2/units/LLS/rep0.h5"}) {
    fs::create_directories((dir() / f).parent_path());
    fs::copy_file(dir() / (std::string(f).find(".h5") != std::string::npos ? "sl.h5" : "sl.xml"), dir() / f,
                  fs::copy_options::overwrite_existing);
  }
  const std::string data = text(dir() / "sl.h5"), model = text(dir() / "sl.xml");
  expect_error(spml("bench --data b5/predictions.h5 --model sl.xml --out b5 --learners LLS --reps 1"), 2,
               {"b5/predictions.h5: is one of the files written into --out b5", "would be overwritten"});
  expect_error(spml("bench --data sl.h5 --model b6/bench.json --out b6/ --learners LLS --reps 1"), 2, {"b6/bench.json: is one of"});
  expect_error(spml("bench --data sl.h5 --model ./b1/results.csv --out b1 --learners LLS --reps 1"), 2, {"./b1/results.csv: is one of"});
  expect_error(spml("bench --data b2/units/LLS/rep0.h5 --out b2 --learners LLS --reps 1"), 2, {"b2/units/LLS/rep0.h5: is one of"});
  expect_error(spml("bench --data sl.h5 --plugin-path b2/units/LLS/rep0.h5 --out b2 --learners LLS --reps 1"), 2,
               {"b2/units/LLS/rep0.h5: is one of"});
  EXPECT_EQ(text(dir() / "b5/predictions.h5"), data);
  EXPECT_EQ(text(dir() / "b6/bench.json"), model);
  EXPECT_EQ(text(dir() / "b1/results.csv"), model);
  // An input elsewhere in the folder is read, not refused.
  const auto r = spml("bench --data b5/predictions.h5 --model sl.xml --out b5/run --learners LLS --reps 1 -q");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

// The units of a slide joint's columns follow its type where the model is known (results.csv,
// predictions.h5, diagnose's notes); without a model every joint counts as a hinge.
TEST(CliGuards, SlideJointUnitsFollowTheModel) {
  auto r = spml("bench --data sl.h5 --model sl.xml --out units --learners LLS --reps 1 -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string csv = text(dir() / "units/results.csv");
  EXPECT_NE(csv.find(",tau:j0,0,N·m,LLS,"), std::string::npos) << csv;
  EXPECT_NE(csv.find(",tau:j1,1,N,LLS,"), std::string::npos) << csv;
  r = run("/usr/bin/python3 -c \"import h5py, sys; f = h5py.File(sys.argv[1]); print(f.attrs['units'], f.attrs['input_units'])\" " +
          (dir() / "units/predictions.h5").string());
  EXPECT_EQ(r.output, "N·m,N rad,m,rad/s,rad/s²,m/s,m/s²\n");
  r = spml("bench --data sl.h5 --out nomodel --learners GP --reps 1 --train-max 100 --test-max 100 -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(text(dir() / "nomodel/results.csv").find(",tau:j1,1,N·m,GP,"), std::string::npos);
  // The stroke of the slide joint is a length.
  r = spml("diagnose --model sl.xml --data sl.h5 --out dsl --no-plots --rollouts 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string report = text(dir() / "dsl/report.json");
  EXPECT_NE(report.find("\"the stroke (0.07"), std::string::npos) << report;
  EXPECT_NE(report.find(" m) spans fewer than 3 periods"), std::string::npos) << report;
  EXPECT_EQ(report.find(" rad) spans"), std::string::npos) << report;
}

// Error messages name the file, the element and the problem.
TEST(CliGuards, MessagesNameFileElementAndProblem) {
  // A Latin-1 joint name: --json names the model, the field and the byte.
  std::string latin1 = kSlideModel;
  latin1.replace(latin1.find("name=\"j1\""), 9, "name=\"j\xe9\"");
  std::ofstream(dir() / "nu.xml") << latin1;
  expect_error(spml("regressor --model nu.xml --json"), 1, {"nu.xml: --json field 'names': '", "is not valid UTF-8 (byte 0xe9 at offset"});
  // A plugin folder with a non-UTF-8 name.
  const fs::path odd = dir() / "p\xff";
  fs::create_directories(odd);
  fs::copy_file(fs::path(SPML_BROKEN_DIR) / "force_none.so", odd / "force_none.so", fs::copy_options::overwrite_existing);
  expect_error(spml("plugins --json --plugin-path 'p\xff'"), 1, {"plugins --json: --json field 'file': '", "is not valid UTF-8 (byte 0xff"});
  expect_error(spml("check-plugin --json 'p\xff/force_none.so'"), 1, {"check-plugin --json: ", "is not valid UTF-8 (byte 0xff"});
  // A repeated time stamp, by its line in the file.
  std::ofstream(dir() / "dup.csv") << "t,q:j0,tau:j0\n0.001,0.1,1\n0.002,0.2,2\n0.002,0.2,2\n0.003,0.3,3\n0.004,0.4,4\n";
  expect_error(spml("import dup.csv --t t --x q:j0 --y tau:j0 --derive --out dup.h5"), 1,
               {"dup.csv: column 't': time stamps must increase; line 4 repeats t = 0.002 of line 3"});
  // An unnamed free joint: its type, not only its index.
  std::string free = kSlideModel;
  free.replace(free.find("<body name=\"l0\">"), 0, "<body name=\"fb\" pos=\"0 0 2\"><freejoint/><inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"0.1 0.1 0.1\"/></body>");
  std::ofstream(dir() / "free.xml") << free;
  expect_error(spml("generate --model free.xml --duration 1 --out free.csv"), 1,
               {"free.xml: joint 0 (free, unnamed, in body 'fb') is a ball or free joint"});
  EXPECT_FALSE(fs::exists(dir() / "free.csv"));
}

TEST(CliGuards, ImportAndBenchOptionsThatCannotWork) {
  std::ofstream(dir() / "semi.csv") << "# logger v1\nt;a;y\n0;1,5;2\n";
  expect_error(spml("import semi.csv --delimiter ';' --comment '' --x a --y y --out semi.h5"), 2, {"--comment: is empty"});
  expect_error(spml("import semi.csv --delimiter ';' --comment ';' --x a --y y --out semi.h5"), 2,
               {"--comment: ';' holds the cell delimiter ';'"});
  expect_error(spml("import semi.csv --delimiter ';' --comment '#' --x a --y y --out semi.h5"), 1,
               {"semi.csv:3: column 'a': '1,5' is not a finite number (decimal commas are not read"});
  EXPECT_FALSE(fs::exists(dir() / "semi.h5"));
  expect_error(spml("import semi.csv --delimiter ';' --comment '#' --x a --y y --no-anti-alias --out semi.h5"), 2,
               {"--no-anti-alias: applies to --decimate K with K >= 2"});
  // A record of a few rows (import --decimate 700 of 2000 left 3) once crashed diagnose: an
  // empty held-out part.
  const std::string arm = std::string(SPML_SOURCE_DIR) + "/mjcf/planar_arm3.xml";
  ASSERT_EQ(spml("generate -q --model " + arm + " --duration 0.03 --rate 200 --derive -o tiny.h5").exit_code, 0);
  expect_error(spml("diagnose -m " + arm + " -d tiny.h5 -o tinyout --no-plots"), 1,
               {"tiny.h5: split 'train' has 2 rows; diagnose needs at least 10"});
  expect_error(spml("bench --data sl.h5 --out dupset --learners GP --set max_evals=5 --set max_evals=6"), 2,
               {"--set: 'max_evals' is given twice (max_evals=5 and max_evals=6)"});
  EXPECT_FALSE(fs::exists(dir() / "dupset"));
}

}  // namespace
