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

}  // namespace
