// Issue #22: what diagnose finds beyond static friction, on data that look like real logs
// (forward simulation under the PD controller of `spml generate --model`, encoder-quantized
// positions, torque noise, velocities and accelerations from `spml import --lowpass --derive`):
// a delay between the torque and position logs, LuGre stick-slip friction fitted by
// simulation, and residual structure outside the vocabulary reported as `unexplained`.
#include <gtest/gtest.h>

#include <algorithm>
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
#include "diagnose_draws.h"
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
std::string measured(const Case& c, const std::string& path, unsigned seed, int delay_samples = 0, double lowpass_hz = 10) {
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
  spec.conditioning.lowpass_hz = lowpass_hz;
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
      EXPECT_TRUE(r["unexplained"].empty()) << r["unexplained"].dump();
      continue;
    }
    ASSERT_TRUE(r["delay"]["named"].get<bool>());
    EXPECT_EQ(causes.front(), "delay");
    EXPECT_NEAR(est, 1e-3 * delays_ms[k], 1e-3);
    for (const auto& n : causes) EXPECT_EQ(n, "delay") << "a cause beside the delay: " << joined(causes);
  }
}

// The RMS torque of joint j of a model along the test excitation (2 s, no noise).
double rms_torque(const std::string& model, int j) {
  MeasurementOptions probe;
  probe.duration = 2;
  probe.torque_noise = 0;
  return simulate_measured(model, probe).rms[j];
}

// LuGre friction (stick_slip) hidden on one joint of a random chain, its break-away force 1.5x
// its Coulomb level (10 % of the joint's RMS torque), a pre-sliding deflection fc/sigma0 of
// 2 mrad: `stick_slip` is named on that joint with fc and fs within 20 %. The data are
// low-passed at 20 Hz (10 Hz smears the transitions at velocity reversals: fs came out 20 %
// low on the second draw). A third draw has a deflection of 2 µrad (below the 18-bit
// encoder's 24 µrad step: no pre-sliding in the data): then LuGre is a Stribeck curve, and
// `stribeck` (fewer parameters) or `stick_slip` with sigma0 not identifiable are both right.
TEST(DiagnoseBeyond, LuGreFrictionIsNamedStickSlipWithItsLevels) {
  const auto dir = test::temp_dir("lugre");
  for (unsigned k = 0; k < 3; ++k) {
    const int joint = static_cast<int>(k % 3);
    const Case user = make_case(dir, "probe" + std::to_string(k), 0x1a9e0u + k, "", joint);
    const double deflection = k < 2 ? 2e-3 : 2e-6;
    const double fc = 0.1 * rms_torque(user.user, joint), fs = 1.5 * fc, sigma0 = fc / deflection;
    const std::string decl = "type=stick_slip joints=JOINT fc=" + test::num(fc) + " fs=" + test::num(fs) + " vs=0.1 sigma0=" +
                             test::num(sigma0) + " sigma1=" + test::num(0.05 * std::sqrt(sigma0)) + " sigma2=0";
    const Case c = make_case(dir, "l" + std::to_string(k), 0x1a9e0u + k, decl, joint);
    const auto r = diagnose_case(c, measured(c, (dir / ("l" + std::to_string(k) + ".h5")).string(), 70 + k, 0, 20));
    const auto causes = named(r);
    std::cout << "LuGre on j" << joint << " (fc " << fc << ", fs " << fs << ", sigma0 " << sigma0 << "): named " << joined(causes) << "\n";
    const std::string want = "stick_slip@j" + std::to_string(joint);
    if (k == 2) {
      // Without pre-sliding LuGre is a Stribeck curve: either name is right, the smaller one
      // is preferred (evidence per parameter), and stick_slip must say sigma0 is free.
      bool friction = false;
      for (const auto& cause : r["causes"])
        if (!cause.contains("superseded_by") && cause["joints"][0] == "j" + std::to_string(joint) &&
            (cause["effect"] == "stribeck" || cause["effect"] == "stick_slip")) {
          friction = true;
          std::cout << "  " << cause["params"].dump() << "\n";
          const auto& p = cause["params"];   // a static plugin names them per joint (j2.fc)
          const std::string pre = cause["effect"] == "stribeck" ? "j" + std::to_string(joint) + "." : "";
          EXPECT_NEAR(p[pre + "fc"].get<double>(), fc, 0.2 * fc);
          EXPECT_NEAR(p[pre + "fs"].get<double>(), fs, 0.2 * fs);
          if (cause["effect"] == "stick_slip") EXPECT_NE(cause["not_identifiable"].dump().find("sigma0"), std::string::npos);
        }
      EXPECT_TRUE(friction) << joined(causes);
      continue;
    }
    ASSERT_NE(std::find(causes.begin(), causes.end(), want), causes.end()) << joined(causes);
    for (const auto& cause : r["causes"])
      if (cause["effect"] == "stick_slip" && !cause.contains("superseded_by")) {
        std::cout << "  " << cause["params"].dump() << "\n  stderr " << cause["stderr"].dump() << "\n  not identifiable "
                  << cause["not_identifiable"].dump() << ", amplitude " << cause["amplitude"] << "\n";
        EXPECT_NEAR(cause["params"]["fc"].get<double>(), fc, 0.2 * fc);
        EXPECT_NEAR(cause["params"]["fs"].get<double>(), fs, 0.2 * fs);
        const auto& free = cause["not_identifiable"];
        EXPECT_EQ(std::find(free.begin(), free.end(), "sigma0"), free.end()) << free.dump();
      }
    std::cout << "  rollout " << r["rollout"].dump() << "\n";
  }
}

// An effect outside the vocabulary: a joint spring (MJCF stiffness) the user's model lacks,
// about 15 % of the joint's RMS torque over its stroke. No candidate is a spring: diagnose
// must not name a cause whose rollouts get worse, and must report the joint as unexplained
// with its own position as the most relevant input.
TEST(DiagnoseBeyond, AnEffectOutsideTheVocabularyIsReportedUnexplained) {
  const auto dir = test::temp_dir("unexplained");
  for (unsigned k = 0; k < 2; ++k) {
    const int joint = static_cast<int>((k + 1) % 3);
    const Case user = make_case(dir, "u" + std::to_string(k), 0x5e1f0u + k, "", joint);
    const double stiffness = 0.3 * rms_torque(user.user, joint);
    std::string xml = test::read_file(user.user);
    const std::string tag = "<joint name=\"j" + std::to_string(joint) + "\" ";
    xml.replace(xml.find(tag), tag.size(), tag + "stiffness=\"" + test::num(stiffness) + "\" ");
    Case c = user;
    c.truth = (dir / ("spring" + std::to_string(k) + ".xml")).string();
    std::ofstream(c.truth) << xml;
    const auto r = diagnose_case(c, measured(c, (dir / ("u" + std::to_string(k) + ".h5")).string(), 90 + k));
    std::cout << "spring " << stiffness << " on j" << joint << ": named " << joined(named(r)) << "\n  unexplained " << r["unexplained"].dump()
              << "\n  rollout worse on " << r["rollout"]["worse_on"].dump() << "\n";
    bool found = false;
    for (const auto& u : r["unexplained"])
      if (u["joint"] == "j" + std::to_string(joint)) {
        found = true;
        EXPECT_EQ(u["inputs"][0], "q:j" + std::to_string(joint));
      }
    EXPECT_TRUE(found);
    for (const auto& cause : r["causes"])
      if (!cause.contains("superseded_by"))
        for (const auto& j : cause["joints"])
          for (const auto& w : r["rollout"]["worse_on"]) EXPECT_NE(j, w) << cause["effect"] << " makes the rollouts on " << w << " worse";
  }
}

}  // namespace
}  // namespace spml
