// Issue #22: what diagnose finds beyond static friction, on data that look like real logs
// (forward simulation under the PD controller of `spml generate --model`, encoder-quantized
// positions, torque noise, velocities and accelerations from `spml import --lowpass --derive`):
// a delay between the torque and position logs, LuGre stick-slip friction fitted by
// simulation, and residual structure outside the vocabulary reported as `unexplained`.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <map>
#include <random>

#include "spml/dataset.h"
#include "spml/diagnose.h"
#include "spml/envs/measured_run.h"
#include "spml/import.h"
#include "test_util.h"

namespace spml {
namespace {

struct Case {
  std::string user, truth;   // model paths: what the user has, what made the data
  int joints = 3;
};

// A random 3-joint chain (seeded), and the same chain with `declaration` (a plugin text with
// JOINT standing for the joint name) hidden on joint `joint`.
Case make_case(const std::filesystem::path& dir, const std::string& tag, unsigned seed, const std::string& declaration, int joint) {
  std::mt19937_64 rng(seed);
  Case c;
  const std::string xml = test::random_chain(rng, c.joints, 0);
  c.user = (dir / ("user_" + tag + ".xml")).string();
  c.truth = (dir / ("true_" + tag + ".xml")).string();
  std::ofstream(c.user) << xml;
  std::string text = declaration;
  if (const auto at = text.find("JOINT"); at != std::string::npos) text.replace(at, 5, "j" + std::to_string(joint));
  std::ofstream(c.truth) << (declaration.empty() ? xml : test::with_declarations(xml, {text}));
  return c;
}

// 10 s at 1 kHz under the PD controller, 1 % torque noise, 18-bit encoders; the torque log
// delayed by `delay_samples` ticks (it reads the torque of that many ticks before); imported
// with a 10 Hz low-pass, derived, decimated to 200 Hz, 70/30 split.
std::string measured(const Case& c, const std::string& path, unsigned seed, int delay_samples = 0) {
  MeasurementOptions o;
  o.duration = 10;
  o.rate = 1000;
  o.torque_noise = 0.01;
  o.encoder_bits = 18;
  o.seed = seed;
  o.excitation.seed = seed + 17;
  MeasuredRun run = simulate_measured(c.truth, o);
  if (delay_samples > 0) {
    const Eigen::MatrixXd tau = run.tau;
    for (Eigen::Index i = 0; i < tau.rows(); ++i) run.tau.row(i) = tau.row(std::max<Eigen::Index>(0, i - delay_samples));
  }
  ImportSpec spec;
  for (const auto& j : run.joints) spec.x.push_back("q:" + j), spec.y.push_back("tau:" + j);
  spec.t = "t";
  spec.conditioning.derive = true;
  spec.conditioning.lowpass_hz = 10;
  spec.conditioning.drop_edges = 200;
  spec.conditioning.decimate = 5;
  spec.splits = {parse_split_range("train:0:70%"), parse_split_range("test:70%:")};
  write_dataset(path, table_to_dataset(measured_table(run, path), spec));
  return path;
}

nlohmann::json diagnose_case(const Case& c, const std::string& data) {
  DiagnoseOptions opt;
  opt.model = c.user;
  opt.data = data;
  opt.rollouts = 5;
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json r = diagnose(opt, "").report;
  std::cout << "  " << data << ": " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s\n";
  return r;
}

std::vector<std::string> named(const nlohmann::json& r) {
  std::vector<std::string> out;
  for (const auto& c : r["causes"])
    if (!c.contains("superseded_by")) out.push_back(c["effect"].get<std::string>() + (c["effect"] == "delay" || c["effect"] == "parameters" ? "" : "@" + c["joints"][0].get<std::string>()));
  return out;
}

std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : " ") + x;
  return s.empty() ? "nothing" : s;
}

// Delays of 2-10 ms between torque and position logs (a sub-sample offset at the 200 Hz the
// data are decimated to): `delay` within 1 ms, and no friction cause; clean data: no delay.
TEST(DiagnoseBeyond, DelayIsNamedWithinAMillisecondAndCleanDataHaveNone) {
  const auto dir = test::temp_dir("delay");
  const std::vector<int> delays_ms = {0, 2, 6, 10};
  for (size_t k = 0; k < delays_ms.size(); ++k) {
    const Case c = make_case(dir, "d" + std::to_string(k), 0xde1a0u + static_cast<unsigned>(k), "", 0);
    const auto r = diagnose_case(c, measured(c, (dir / ("d" + std::to_string(k) + ".h5")).string(), 40 + static_cast<unsigned>(k), delays_ms[k]));
    const auto causes = named(r);
    const double est = r["delay"]["seconds"], se = r["delay"]["stderr"];
    std::cout << "hidden delay " << delays_ms[k] << " ms: estimated " << 1e3 * est << " ± " << 1e3 * se << " ms, named " << joined(causes) << "\n";
    if (delays_ms[k] == 0) {
      // (Other causes on clean forward-simulated data are issue #20's; here: no delay.)
      EXPECT_FALSE(r["delay"]["named"].get<bool>());
      for (const auto& n : causes) EXPECT_NE(n, "delay");
      continue;
    }
    ASSERT_TRUE(r["delay"]["named"].get<bool>());
    EXPECT_EQ(causes.front(), "delay");
    EXPECT_NEAR(est, 1e-3 * delays_ms[k], 1e-3);
    for (const auto& n : causes) EXPECT_EQ(n, "delay") << "a cause beside the delay: " << joined(causes);
  }
}

}  // namespace
}  // namespace spml
