// spml generate --model: a measured run of any MJCF. Each check has a closed form: the encoder
// count, the noise level (sampling error of a standard deviation), MuJoCo's own inverse
// dynamics on the simulated states, the joint ranges, and bit-identical reruns.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <set>

#include "spml/dataset.h"
#include "spml/envs/measured_run.h"
#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"
#include "test_util.h"

namespace spml {
namespace {

// A hinge, a limited slide and a limited hinge in a spatial chain; hidden Coulomb friction
// on the first and a position actuator the generator must switch off.
const char* kArm = R"(<mujoco model="gen">
  <compiler angle="radian"/>
  <option gravity="0 -3 -9"/>
  <worldbody>
    <body name="a">
      <joint name="h0" type="hinge" axis="0 0.6 0.8" damping="0.2" armature="0.02"/>
      <inertial pos="0.2 0 0" mass="2" diaginertia="0.02 0.03 0.025"/>
      <body name="b" pos="0.4 0 0">
        <joint name="s1" type="slide" axis="1 0 0" range="-0.1 0.15" limited="true"/>
        <inertial pos="0.05 0.02 0" mass="1" diaginertia="0.01 0.01 0.01"/>
        <body name="c" pos="0.2 0 0">
          <joint name="h2" type="hinge" axis="1 0 1" range="-0.5 1.2" limited="true"/>
          <inertial pos="0.1 0 0.05" mass="0.5" diaginertia="0.004 0.005 0.006"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator><position joint="h0" kp="100"/></actuator>
  <custom><text name="spml.plugin.fric" data="type=coulomb joints=h0 fc=0.8"/></custom>
</mujoco>
)";

std::string arm_path() {
  static const std::string path = [] {
    const auto p = (test::temp_dir("generate") / "arm.xml").string();
    std::ofstream(p) << kArm;
    return p;
  }();
  return path;
}

MeasurementOptions small(double duration = 4) {
  MeasurementOptions o;
  o.duration = duration;
  return o;
}

TEST(Generate, PositionsAreWholeEncoderCounts) {
  MeasurementOptions o = small();
  o.encoder_bits = 16;
  const MeasuredRun run = simulate_measured(arm_path(), o);
  for (int j = 0; j < 3; ++j) {
    const double count = (j == 1 ? 1.0 : 2 * M_PI) / 65536.0;   // slide: per metre
    std::set<long long> counts;
    double worst = 0;
    for (Eigen::Index i = 0; i < run.q.rows(); ++i) {
      const double c = run.q(i, j) / count;
      worst = std::max(worst, std::fabs(c - std::round(c)));
      counts.insert(std::llround(c));
      EXPECT_LE(std::fabs(run.q(i, j) - run.q_true(i, j)), 0.5 * count * (1 + 1e-9));
    }
    EXPECT_LT(worst, 1e-6) << "joint " << j;
    // A smooth motion passes through neighbouring counts: the smallest step is one count.
    long long smallest = 1LL << 40;
    for (auto it = std::next(counts.begin()); it != counts.end(); ++it) smallest = std::min(smallest, *it - *std::prev(it));
    EXPECT_EQ(smallest, 1) << "joint " << j;
  }
}

TEST(Generate, TorqueNoiseIsTheRequestedFractionOfEachJointsRms) {
  MeasurementOptions o = small(10);
  o.torque_noise = 0.02;
  const MeasuredRun run = simulate_measured(arm_path(), o);
  const double n = static_cast<double>(run.tau.rows());
  for (int j = 0; j < 3; ++j) {
    const Eigen::VectorXd e = run.tau.col(j) - run.tau_true.col(j);
    const double ratio = std::sqrt(e.squaredNorm() / n) / run.rms[j];
    // The sample std of n Gaussian draws has relative error 1/sqrt(2n); allow four of them.
    EXPECT_NEAR(ratio, 0.02, 4 * 0.02 / std::sqrt(2 * n)) << "joint " << j;
    EXPECT_GT(run.rms[j], 0);
  }
}

// MuJoCo's inverse dynamics (plugins attached, actuators off as in the run) on every tick's
// state and acceleration gives back the torque the controller applied, closed loop or open
// (where gravity drives the limited joints into their limits: constraint forces included).
void check_inverse_dynamics(const std::string& controller) {
  MeasurementOptions o = small();
  o.torque_noise = 0;
  o.encoder_bits = 0;
  o.controller = controller;
  const MeasuredRun run = simulate_measured(arm_path(), o);
  EXPECT_NE(run.plugins.find("type=coulomb joints=h0 fc=0.8"), std::string::npos) << run.plugins;
  ModelPtr m = load_mjcf(arm_path());
  m->opt.disableflags |= mjDSBL_ACTUATION;
  m->opt.timestep = run.sim_timestep;
  ForceEffects fx(m.get(), arm_path());
  fx.attach();
  DataPtr d = make_data(m.get());
  double worst = 0;
  for (Eigen::Index k = 0; k < run.tick_tau.rows(); ++k) {
    for (int j = 0; j < 3; ++j) d->qpos[j] = run.tick_qpos(k, j), d->qvel[j] = run.tick_qvel(k, j), d->qacc[j] = run.tick_qacc(k, j);
    mj_inverse(m.get(), d.get());
    for (int j = 0; j < 3; ++j) worst = std::max(worst, std::fabs(d->qfrc_inverse[j] - run.tick_tau(k, j)) / run.rms[j]);
  }
  fx.detach();
  EXPECT_LT(worst, 1e-9) << controller;
  // The logged samples (no jitter) are the ticks' positions and torques.
  for (Eigen::Index i = 0; i < run.q.rows(); i += 97)
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(run.q(i, j), run.tick_qpos(i + 1, j), 1e-9);   // d->time sums sub-steps: rounding
      EXPECT_EQ(run.tau(i, j), run.tick_tau(i + 1, j));
    }
}

TEST(Generate, ForwardSimulationReproducesMujocoInverseDynamics) {
  check_inverse_dynamics("pd");
  check_inverse_dynamics("torque");
}

TEST(Generate, ReferenceStaysInsideJointRangesAndTracks) {
  for (const char* kind : {"multisine", "chirp"}) {
    MeasurementOptions o = small(8);
    o.excitation.kind = kind;
    const MeasuredRun run = simulate_measured(arm_path(), o);
    EXPECT_GE(run.q_true.col(1).minCoeff(), -0.1) << kind;
    EXPECT_LE(run.q_true.col(1).maxCoeff(), 0.15) << kind;
    EXPECT_GE(run.q_true.col(2).minCoeff(), -0.5) << kind;
    EXPECT_LE(run.q_true.col(2).maxCoeff(), 1.2) << kind;
    // It moves: every joint spans a good part of its allowed excursion.
    EXPECT_GT(run.q_true.col(0).maxCoeff() - run.q_true.col(0).minCoeff(), 0.4) << kind;
    EXPECT_GT(run.q_true.col(1).maxCoeff() - run.q_true.col(1).minCoeff(), 0.05) << kind;
  }
}

TEST(Generate, JitteredInstantsAreStampedAndOrdered) {
  MeasurementOptions o = small();
  o.rate = 500;
  o.jitter = 2e-4;
  const MeasuredRun run = simulate_measured(arm_path(), o);
  Eigen::VectorXd e(run.t.size());
  for (Eigen::Index i = 0; i < run.t.size(); ++i) e[i] = run.t[i] - static_cast<double>(i + 1) / 500;
  const double sd = std::sqrt(e.squaredNorm() / static_cast<double>(e.size()));
  EXPECT_NEAR(sd, 2e-4, 4 * 2e-4 / std::sqrt(2.0 * static_cast<double>(e.size())));
  for (Eigen::Index i = 1; i < run.t.size(); ++i) ASSERT_GT(run.t[i], run.t[i - 1]);
}

TEST(Generate, SameSeedSameFileOtherSeedOtherFile) {
  const auto dir = test::temp_dir("generate-seed");
  auto gen = [&](int seed, const std::string& name) {
    const auto out = (dir / name).string();
    const auto r = test::run(test::spml_bin() + " generate --model " + arm_path() + " --duration 2 --seed " + std::to_string(seed) + " --out " + out);
    EXPECT_EQ(r.exit_code, 0) << r.output;
    std::ifstream in(out, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string a = gen(5, "a.csv"), b = gen(5, "b.csv"), c = gen(6, "c.csv");
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  // The spml/1 output too, compared by content.
  gen(5, "a.h5");
  gen(5, "b.h5");
  gen(6, "c.h5");
  const Dataset da = read_dataset((dir / "a.h5").string()), db = read_dataset((dir / "b.h5").string()),
                dc = read_dataset((dir / "c.h5").string());
  EXPECT_TRUE(da.get("train").X == db.get("train").X && da.get("train").Y == db.get("train").Y);
  EXPECT_FALSE(da.get("train").Y == dc.get("train").Y);
  EXPECT_EQ(da.get("train").x_columns, (std::vector<std::string>{"q:h0", "q:s1", "q:h2"}));
}

// The round trip a user makes: a CSV log, spml import --lowpass --derive, velocities close to
// the simulation's (the filter error, not the encoder noise, dominates).
TEST(Generate, CsvLogImportsWithDerivedVelocities) {
  const auto dir = test::temp_dir("generate-import");
  const std::string log = (dir / "log.csv").string(), ds = (dir / "log.h5").string();
  auto r = test::run(test::spml_bin() + " generate --model " + arm_path() + " --duration 6 --torque-noise 0 --out " + log);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Printed with the binary that ran (build/bin/spml is not on PATH here), so that the
  // command runs as printed.
  const auto next = r.output.find("next: ");
  ASSERT_NE(next, std::string::npos) << r.output;
  std::string cmd = r.output.substr(next + 6);
  cmd = cmd.substr(0, cmd.find('\n'));
  ASSERT_NE(cmd.find(" import "), std::string::npos) << cmd;
  cmd.replace(cmd.find("DATA.h5"), 7, ds);
  r = test::run(cmd);
  ASSERT_EQ(r.exit_code, 0) << cmd << "\n" << r.output;
  const Dataset d = read_dataset(ds);
  const Split& s = d.get("train");
  ASSERT_GE(s.x_index("qdd:h2"), 0);
  // Compare qd:h0 with the exact velocity of an identical run (same seed: same trajectory).
  MeasurementOptions o = small(6);
  o.torque_noise = 0;
  const MeasuredRun run = simulate_measured(arm_path(), o);
  const int c = s.x_index("qd:h0");
  double err = 0, ref = 0;
  for (Eigen::Index i = 0; i < s.rows(); ++i) {
    const auto tick = static_cast<Eigen::Index>(std::llround(s.t[i] * 1000));
    err += std::pow(s.X(i, c) - run.tick_qvel(tick, 0), 2);
    ref += std::pow(run.tick_qvel(tick, 0), 2);
  }
  EXPECT_LT(std::sqrt(err / ref), 0.01);
}

TEST(Generate, BadInputIsRefusedWithAClearMessage) {
  const auto dir = test::temp_dir("generate-bad");
  const std::string ball = (dir / "ball.xml").string(), spml = test::spml_bin();
  std::ofstream(ball) << "<mujoco><worldbody><body><joint name=\"b\" type=\"ball\"/><geom size=\"0.1\"/></body></worldbody></mujoco>";
  auto r = test::run(spml + " generate --model " + ball + " --out " + (dir / "x.csv").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("joint 0 (ball, 'b', in body #1) is a ball or free joint"), std::string::npos) << r.output;
  r = test::run(spml + " generate --model " + arm_path() + " --derive --out " + (dir / "x.csv").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--derive"), std::string::npos) << r.output;
  r = test::run(spml + " generate --model " + arm_path() + " --excitation square --out " + (dir / "x.h5").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("excitation 'square'"), std::string::npos) << r.output;
  r = test::run(spml + " generate --model " + arm_path() + " --excitation file:" + (dir / "none.csv").string() + " --out " + (dir / "x.h5").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("none.csv"), std::string::npos) << r.output;
  r = test::run(spml + " generate --model " + arm_path() + " --rate -5 --out " + (dir / "x.h5").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--rate"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "x.h5"));
  EXPECT_FALSE(std::filesystem::exists(dir / "x.csv"));
}

// A recorded trajectory as the excitation: the run follows the file.
TEST(Generate, FileExcitationIsFollowed) {
  const auto dir = test::temp_dir("generate-file");
  const std::string ref = (dir / "ref.csv").string();
  {
    std::ofstream f(ref);
    f << "t,q:h0,q:s1,q:h2\n";
    for (int i = 0; i <= 300; ++i) {
      const double t = 0.01 * i;
      f << t << "," << 0.5 * std::sin(2 * t) << "," << 0.05 * std::sin(3 * t) << "," << 0.3 + 0.4 * std::sin(1.5 * t) << "\n";
    }
  }
  MeasurementOptions o = small(3);
  o.excitation.kind = "file:" + ref;
  EXPECT_DOUBLE_EQ(reference_file_duration(ref), 3.0);
  const MeasuredRun run = simulate_measured(arm_path(), o);
  double worst = 0;
  for (Eigen::Index i = 0; i < run.t.size(); ++i) worst = std::max(worst, std::fabs(run.q_true(i, 2) - (0.3 + 0.4 * std::sin(1.5 * run.t[i]))));
  EXPECT_LT(worst, 0.05);   // a 4 Hz PD's tracking error on a 0.24 Hz, 0.4 rad sine
}

}  // namespace
}  // namespace spml
