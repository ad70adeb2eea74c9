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
#include <functional>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <tuple>
#include <cstdlib>

#include "spml/csv.h"
#include "spml/dataset.h"
#include "spml/diagnose.h"
#include "spml/envs/measured_run.h"
#include "spml/envs/mjcf_regressor.h"
#include "spml/envs/mujoco_model.h"
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

// A model text of `joints` joints written to dir/given.xml, both what the user has and what
// made the data (`truth`: another model text for the data, when given).
Case given_case(const std::filesystem::path& dir, const std::string& xml, int joints, const std::string& truth = "") {
  Case c;
  c.joints = joints;
  c.user = c.truth = (dir / "given.xml").string();
  std::ofstream(c.user) << xml;
  if (!truth.empty()) {
    c.truth = (dir / "true.xml").string();
    std::ofstream(c.truth) << truth;
  }
  return c;
}

// How one draw is measured: 10 s at 1 kHz under the PD controller, torque noise (a fraction
// of each joint's RMS torque), encoders of `bits`; the torque log delayed by `delay_samples`
// ticks (it reads the torque of that many ticks before); imported with a low-pass, derived,
// decimated to 200 Hz, 70/30 split.
struct Measurement {
  double torque_noise = 0.01;
  int bits = 18;
  int delay_samples = 0;
  double lowpass_hz = 10;
  int drop_edges = 200;   // samples dropped at each end after the import's filter (SPML_BEYOND_DROP)
  int decimate = 5;       // the import's decimation (1: the log kept at 1 kHz; SPML_BEYOND_DECIMATE)
  double duration = 10;   // seconds logged (SPML_BEYOND_DURATION)
  double f_high = 0;   // the excitation's top frequency [Hz] (0: the default band, 0.1-1 Hz; its bottom stays 0.1 Hz)
  std::string reference;   // a CSV of q:<joint> against t the controller tracks instead (ExcitationOptions "file:")
  std::string kind;        // the excitation's kind where not the default (ExcitationOptions: "chirp")
  int excitation_seed = -1;   // the excitation's seed (-1: the draw's seed + 17; `spml generate --seed S` uses S)
  // A torque outside the plugin vocabulary, added to the logged torque of joint `extra_joint`
  // as a function of its true position and velocity: a robot with that force needs exactly
  // this much more torque along the motion it made (inverse dynamics is additive).
  int extra_joint = -1;
  std::function<double(double q, double qd)> extra;
  // A torque on the same joint that follows time, not the state (a load or a temperature the
  // log does not hold).
  std::function<double(double t)> drift;
};

std::string measured(const Case& c, const std::string& path, unsigned seed, const Measurement& m) {
  MeasurementOptions o;
  o.duration = m.duration;
  o.rate = 1000;
  o.torque_noise = m.torque_noise;
  o.encoder_bits = m.bits;
  o.seed = seed;
  o.excitation.seed = m.excitation_seed >= 0 ? static_cast<unsigned>(m.excitation_seed) : seed + 17;
  if (m.f_high > 0) o.excitation.f_high = m.f_high, o.excitation.f_low = std::min(o.excitation.f_low, 0.5 * m.f_high);
  if (!m.kind.empty()) o.excitation.kind = m.kind;
  if (!m.reference.empty()) o.excitation.kind = "file:" + m.reference;
  MeasuredRun run = simulate_measured(c.truth, o);
  if (m.extra && m.extra_joint >= 0)
    for (Eigen::Index i = 0; i < run.tau.rows(); ++i)   // no jitter: sample i is tick i
      run.tau(i, m.extra_joint) += m.extra(run.tick_qpos(i, m.extra_joint), run.tick_qvel(i, m.extra_joint));
  if (m.drift && m.extra_joint >= 0)
    for (Eigen::Index i = 0; i < run.tau.rows(); ++i) run.tau(i, m.extra_joint) += m.drift(static_cast<double>(i) / o.rate);
  if (m.delay_samples > 0) {
    const Eigen::MatrixXd tau = run.tau;
    for (Eigen::Index i = 0; i < tau.rows(); ++i) run.tau.row(i) = tau.row(std::max<Eigen::Index>(0, i - m.delay_samples));
  }
  ImportSpec spec;
  for (const auto& j : run.joints) spec.x.push_back("q:" + j), spec.y.push_back("tau:" + j);
  spec.t = "t";
  spec.conditioning.derive = true;
  spec.conditioning.lowpass_hz = m.lowpass_hz;
  spec.conditioning.drop_edges = m.drop_edges;
  spec.conditioning.decimate = m.decimate;
  spec.splits = {parse_split_range("train:0:70%"), parse_split_range("test:70%:")};
  write_dataset(path, table_to_dataset(measured_table(run, path), spec));
  return path;
}

std::string measured(const Case& c, const std::string& path, unsigned seed, int delay_samples = 0, double lowpass_hz = 10) {
  Measurement m;
  m.delay_samples = delay_samples;
  m.lowpass_hz = lowpass_hz;
  return measured(c, path, seed, m);
}

nlohmann::json diagnose_case(const Case& c, const std::string& data, int rollouts = 5) {
  DiagnoseOptions opt;
  opt.model = c.user;
  opt.data = data;
  opt.rollouts = rollouts;   // (the command's default is 20; SPML_BEYOND_ROLLOUTS for the seed table)
  if (const char* r = std::getenv("SPML_BEYOND_ROLLOUTS")) opt.rollouts = std::stoi(r);
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json r = diagnose(opt, "").report;
  std::cout << "  " << data << ": " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s\n";
  return r;
}

// The causes named (not superseded), as effect@joint; with `written_only`, those extended.xml
// holds (not rejected in simulation either).
std::vector<std::string> named(const nlohmann::json& r, bool written_only = false) {
  std::vector<std::string> out;
  for (const auto& c : r["causes"])
    if (!c.contains("superseded_by") && !(written_only && c.contains("rejected")))
      out.push_back(c["effect"].get<std::string>() + (c["effect"] == "delay" || c["effect"] == "parameters" ? "" : "@" + c["joints"][0].get<std::string>()));
  return out;
}

std::vector<std::string> written(const nlohmann::json& r) { return named(r, true); }

std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : " ") + x;
  return s.empty() ? "nothing" : s;
}

// The RMS torque of joint j of a model along the test excitation (2 s, no noise).
double rms_torque(const std::string& model, int j) {
  MeasurementOptions probe;
  probe.duration = 2;
  probe.torque_noise = 0;
  return simulate_measured(model, probe).rms[j];
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

// The same chains and a 6 ms lag, imported without a low-pass (raw central differences,
// decimated to 200 Hz by import's anti-aliased decimation): interpolating noisy columns lowers
// the residual by itself (a spurious -2.5 ms on clean draws), so the offset is measured,
// withheld and said in the notes, never named; a clean draw gets no delay either way.
TEST(DiagnoseBeyond, DelayOnRawDifferencesIsMeasuredAndWithheld) {
  const auto dir = test::temp_dir("delay-raw");
  for (int lag : {0, 6}) {
    const Case c = make_case(dir, "r" + std::to_string(lag), 0xde1a0u + 2, "", 0);
    const auto r = diagnose_case(c, measured(c, (dir / ("r" + std::to_string(lag) + ".h5")).string(), 42, lag, 0));
    const auto causes = named(r);
    std::cout << "raw differences, lag " << lag << " ms: estimated " << 1e3 * r["delay"]["seconds"].get<double>() << " ms, withheld "
              << r["delay"]["withheld"] << ", named " << joined(causes) << "\n";
    EXPECT_FALSE(r["delay"]["named"].get<bool>());
    for (const auto& n : causes) EXPECT_NE(n, "delay");
    if (lag == 0) continue;
    EXPECT_TRUE(r["delay"]["withheld"].get<bool>()) << r["delay"].dump();
    bool said = false;
    for (const auto& n : r["notes"]) said |= n.get<std::string>().find("appear to lag the states") != std::string::npos;
    EXPECT_TRUE(said) << r["notes"].dump();
  }
}

// LuGre friction (stick_slip) hidden on one joint of a random chain, its break-away force 1.5x
// its Coulomb level (10 % of the joint's RMS torque), a pre-sliding deflection fc/sigma0 of
// 2 mrad: `stick_slip` is named on that joint with fc and fs within 20 %. The data are
// low-passed at 20 Hz (10 Hz smears the transitions at velocity reversals: fs came out 20 %
// low on the second draw). A third draw has a deflection of 2 µrad (below the 18-bit
// encoder's 24 µrad step: no pre-sliding in the data): then LuGre is a Stribeck curve, and
// `stribeck` (fewer parameters) or `stick_slip` with sigma0 not identifiable are both right.
TEST(DiagnoseBeyond, LuGreFrictionIsNamedStickSlipWithItsLevels) {
  SPML_SKIP_UNDER_SANITIZERS();
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
          if (cause["effect"] == "stick_slip") {
            EXPECT_NE(cause["not_identifiable"].dump().find("sigma0"), std::string::npos);
          }
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

}  // namespace
}  // namespace spml

namespace spml {
namespace {

// One seeded draw of a kind: "clean", "delay" (the torque log SPML_BEYOND_DELAY_MS / `delay_ms`
// late), "delay_coulomb" (and Coulomb friction of 10 % of its RMS torque on another joint),
// "lugre" (LuGre friction of random levels on a random joint), "lugre_delay" (both: the
// torque log late and LuGre, whose lag the delay search's static nuisance does not hold),
// "cubic" (cubic damping of 20 % of the joint's RMS torque), "stop" (a one-sided end stop over
// the top fifth of the joint's stroke, 0.6 of its RMS torque at the far end), "sine" (a torque
// a sin(2 (q - q_mid)) of its position, a fifth of its RMS torque: near its middle a spring):
// the last three are outside the vocabulary.
struct Draw {
  Case c;
  Measurement m;
  int joint = 0, other = 0;
  double fc = 0, fs = 0, vs = 0, sigma0 = 0;   // lugre: the true levels, Stribeck speed and bristle stiffness
  std::string what;
};

// sigma0_scale stiffens a LuGre draw's bristles (1: pre-sliding of 1-3 mrad).
Draw make_draw(const std::filesystem::path& dir, const std::string& kind, int s, double delay_ms, Measurement m, double sigma0_scale = 1) {
  Draw d;
  const auto seed = static_cast<unsigned>(0x7ab1e00 + s);
  std::mt19937_64 rng(seed);
  d.joint = static_cast<int>(rng() % 3), d.other = (d.joint + 1 + static_cast<int>(rng() % 2)) % 3;
  const std::string tag = kind + std::to_string(s);
  d.c = make_case(dir, tag, seed, "", d.joint);
  const double rms = rms_torque(d.c.user, d.joint);
  std::string decl;
  d.what = kind;
  if (kind == "delay" || kind == "delay_coulomb" || kind == "lugre_delay") m.delay_samples = static_cast<int>(std::lround(delay_ms));   // 1 kHz: 1 tick = 1 ms
  if (kind == "delay_coulomb") decl = "type=coulomb joints=j" + std::to_string(d.other) + " fc=" + test::num(0.1 * rms_torque(d.c.user, d.other));
  if (kind == "lugre" || kind == "lugre_delay" || kind == "stribeck") {
    std::uniform_real_distribution<double> u(0, 1);
    d.fc = (0.06 + 0.09 * u(rng)) * rms, d.fs = (1.2 + 0.8 * u(rng)) * d.fc;
    const double sigma0 = d.sigma0 = d.fc / (1e-3 + 2e-3 * u(rng)) * sigma0_scale;
    d.vs = 0.03 + 0.2 * u(rng);
    // The static curve of the same seed's LuGre draw, without its bristles: the pair the
    // selection must tell apart (LuGre's steady state is this curve).
    if (kind == "stribeck")
      decl = "type=stribeck joints=JOINT fc=" + test::num(d.fc) + " fs=" + test::num(d.fs) + " vs=" + test::num(d.vs);
    else
      decl = "type=stick_slip joints=JOINT fc=" + test::num(d.fc) + " fs=" + test::num(d.fs) + " vs=" + test::num(d.vs) + " sigma0=" +
             test::num(sigma0) + " sigma1=" + test::num(0.05 * std::sqrt(sigma0)) + " sigma2=0";
  }
  if (kind == "cubic" || kind == "stop" || kind == "sine") {
    MeasurementOptions probe;   // the same excitation as the draw's (measured() seeds it alike)
    probe.duration = m.duration;
    probe.torque_noise = 0;
    probe.seed = seed + 100;
    probe.excitation.seed = seed + 117;
    const MeasuredRun run = simulate_measured(d.c.user, probe);
    const Eigen::VectorXd q = run.tick_qpos.col(d.joint), v = run.tick_qvel.col(d.joint);
    if (kind == "cubic") {
      const double cc = 0.2 * rms / std::sqrt(v.array().pow(6).mean());
      m.extra = [cc](double, double qd) { return cc * qd * qd * qd; };
      d.what += " c=" + test::num(cc);
    } else if (kind == "sine") {
      const double mid = 0.5 * (q.maxCoeff() + q.minCoeff()), a = 0.2 * std::sqrt(2.0) * rms;
      m.extra = [mid, a](double qq, double) { return a * std::sin(2 * (qq - mid)); };
      d.what += " a=" + test::num(a) + " mid=" + test::num(mid) + " stroke=" + test::num(q.maxCoeff() - q.minCoeff());
    } else {
      std::vector<double> sorted(q.data(), q.data() + q.size());
      std::sort(sorted.begin(), sorted.end());
      const double lim = sorted[sorted.size() * 8 / 10], k = 0.6 * rms / (sorted.back() - lim);
      m.extra = [lim, k](double qq, double) { return qq > lim ? -k * (qq - lim) : 0.0; };
      d.what += " lim=" + test::num(lim) + " k=" + test::num(k);
    }
    m.extra_joint = d.joint;
  }
  if (kind == "drift") {   // a slow sine in time, a fifth of the joint's RMS torque
    const double a = 0.2 * std::sqrt(2.0) * rms, period = 0.45 * m.duration;
    m.drift = [a, period](double t) { return a * std::sin(2 * M_PI * t / period); };
    m.extra_joint = d.joint;
    d.what += " a=" + test::num(a);
  }
  if (!decl.empty()) {
    d.c = make_case(dir, tag, seed, decl, d.joint);
    d.what += " " + decl;
  }
  d.m = m;
  return d;
}

// The drawn joint's true damping set to `damping` (the model's stays random_chain's 0.5): an
// MJCF error that `parameters` should name.
void with_true_damping(Draw& d, const std::string& damping) {
  std::ifstream in(d.c.truth);
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string given = "damping=\"0.5\"";
  const auto at = xml.find(given, xml.find("name=\"j" + std::to_string(d.joint) + "\""));
  ASSERT_NE(at, std::string::npos) << d.c.truth;
  xml.replace(at, given.size(), "damping=\"" + damping + "\"");
  std::ofstream(d.c.truth) << xml;
  d.what += " true_damping=" + damping;
}

nlohmann::json run_draw(const std::filesystem::path& dir, const Draw& d, int s, int rollouts = 5) {
  return diagnose_case(d.c, measured(d.c, (dir / (d.what.substr(0, d.what.find(' ')) + std::to_string(s) + ".h5")).string(),
                                     static_cast<unsigned>(0x7ab1e00 + s) + 100, d.m), rollouts);
}

Measurement noise_level(double torque_noise, int bits) {
  Measurement m;
  m.torque_noise = torque_noise;
  m.bits = bits;
  return m;
}

// Clean draws of the seed table (1 kHz, 18 bit, 1 % torque noise, 10 Hz import): the torque
// held over each tick puts the states -0.25 to -0.42 ms ahead of it. Not named (below the 1 ms
// floor), but left in, it read the inertias' torque as damping (0.49 for 0.5 on every joint,
// beyond three standard errors) and `parameters` was named on 5 of 8 draws. Resolved offsets
// are now corrected without a name: seeds 3 and 6 (-0.40 +- 0.04 and -0.35 +- 0.03 ms) name
// nothing.
TEST(DiagnoseBeyond, TheLoggersHalfTickIsCorrectedWithoutAName) {
  const auto dir = test::temp_dir("halftick");
  for (int s : {3, 6}) {
    const Draw d = make_draw(dir, "clean", s, 0, noise_level(0.01, 18));
    const auto r = run_draw(dir, d, s);
    EXPECT_TRUE(named(r).empty()) << "seed " << s << ": " << joined(named(r));
    EXPECT_FALSE(r["delay"]["named"].get<bool>());
    EXPECT_TRUE(r["delay"]["corrected"].get<bool>()) << r["delay"].dump();
    EXPECT_LT(r["delay"]["seconds"].get<double>(), -2e-4) << r["delay"].dump();
  }
}

// The same half tick where the data do not resolve it (clean draw 2: -0.24 +- 0.13 ms, under
// three standard errors, so not corrected). Held at the search's estimate it read as damping
// 0.493 and 0.492 for 0.5 and `parameters` was named; with the offset free beside the base
// parameters (decide_parameters) nothing is. (Where another CPU's rounding has it corrected,
// nothing must be named either.)
TEST(DiagnoseBeyond, AnUnresolvedHalfTickIsNotReadAsDamping) {
  const auto dir = test::temp_dir("halftick_unresolved");
  const Draw d = make_draw(dir, "clean", 2, 0, Measurement{});
  const auto r = run_draw(dir, d, 2);
  if (r["delay"]["corrected"].get<bool>()) std::cout << "note: the offset was corrected here, the draw does not test an unresolved one\n";
  EXPECT_LT(r["delay"]["seconds"].get<double>(), -1e-4) << r["delay"].dump();
  EXPECT_TRUE(named(r).empty()) << joined(named(r));
}

// Each of a clean 3-joint chain's 22 base parameters is a test of the MJCF; at three standard
// errors each, `parameters` was named on 9 of 160 clean draws, on largest deviations of 3.1-3.9
// standard errors (seed 206 at 1 %/18 bit, seeds 233 and 238 at 2 %/16 bit among them). With the
// bar raised for 22 tests at once (Sidak: 3.84), nothing.
TEST(DiagnoseBeyond, CleanDrawsAreJudgedWithTheBarOfAllTheirParameters) {
  const auto dir = test::temp_dir("familywise");
  for (const auto& [s, noise, bits] : {std::tuple{206, 0.01, 18}, std::tuple{233, 0.02, 16}, std::tuple{238, 0.02, 16}}) {
    const Draw d = make_draw(dir, "clean", s, 0, noise_level(noise, bits));
    const auto r = run_draw(dir, d, s);
    EXPECT_TRUE(named(r).empty()) << "seed " << s << ": " << joined(named(r));
    EXPECT_NEAR(r["statistics"]["parameters_z"].get<double>(), 3.840, 0.01) << "seed " << s;   // 22 base parameters
  }
}

// The reviewer's first finding: a 5 ms delay on data where another joint has Coulomb friction
// the model lacks (10 % of its RMS torque) was missed (0.20 ± 0.52 ms) and `parameters` named:
// the held-out test of the delay refitted the base parameters without the friction nuisance,
// so the friction's residual swamped the gain. Now: `delay` within 1 ms, no `parameters`, and
// no cause on a joint without friction. (The estimate sits 0.3-0.4 ms below the truth on these
// draws, as clean draws read -0.2 to -0.4 ms: central differences of semi-implicit Euler
// positions put the velocity half a tick ahead of the logged torque.) Draws 2 and 9 read 4.11
// and 3.30 ms with `parameters` beside them while the rows where the Coulomb joint sticks were
// in the search (sliding_rows); 4.66 and 4.70 ms, nothing beside, without them.
TEST(DiagnoseBeyond, DelayIsFoundBesideStaticFriction) {
  const auto dir = test::temp_dir("delay_coulomb");
  for (int s : {1, 3, 2, 9}) {
    const Draw d = make_draw(dir, "delay_coulomb", s, 5, Measurement{});
    const auto r = run_draw(dir, d, s);
    const auto causes = named(r);
    std::cout << "5 ms delay, Coulomb on j" << d.other << ": estimated " << 1e3 * r["delay"]["seconds"].get<double>() << " ± "
              << 1e3 * r["delay"]["stderr"].get<double>() << " ms, named " << joined(causes) << "\n";
    ASSERT_TRUE(r["delay"]["named"].get<bool>()) << r["delay"].dump();
    EXPECT_NEAR(r["delay"]["seconds"].get<double>(), 5e-3, 1e-3);
    for (const auto& n : causes)
      if (n != "delay") {
        EXPECT_EQ(n.substr(n.find('@') + 1), "j" + std::to_string(d.other)) << "a cause beside the delay: " << joined(causes);
      }
  }
}

// A Coulomb friction under the controller on a friction experiment (kind delay_coulomb with no
// delay, 0.1-0.3 Hz, 2 % torque noise, 16-bit encoders): the joint sticks at each slow
// reversal, and its friction there is whatever torque holds it, not the fc sign(qd) of the
// delay search's nuisance. With those rows in the search, -4.0, -4.2, -9.0 and -5.1 ms were
// named on draws 0, 1, 2 and 6 (estimates -1 to -33 ms over 16 draws); left out
// (sliding_rows), no delay, and the friction named on its joint (draw 1 reads -9.0 +- 1.7 ms,
// not named, and has `parameters` named beside it: the stick phases' torque, which no static
// cause holds, taken by an inertial combination).
TEST(DiagnoseBeyond, ACoulombFrictionsStickPhasesAreNoDelay) {
  const auto dir = test::temp_dir("stick_no_delay");
  Measurement m = noise_level(0.02, 16);
  m.f_high = 0.3;
  for (int s : {0, 1, 2, 6}) {
    const Draw d = make_draw(dir, "delay_coulomb", s, 0, m);
    const auto r = run_draw(dir, d, s);
    const auto causes = named(r);
    std::cout << d.what << ": offset " << 1e3 * r["delay"]["seconds"].get<double>() << " ± " << 1e3 * r["delay"]["stderr"].get<double>()
              << " ms, named " << joined(causes) << "\n";
    EXPECT_FALSE(r["delay"]["named"].get<bool>()) << r["delay"].dump();
    EXPECT_NE(std::find(causes.begin(), causes.end(), "coulomb@j" + std::to_string(d.other)), causes.end()) << joined(causes);
  }
}

// What a LuGre draw's report must say of its break-away force fs.
enum class BreakAway {
  within_20_percent,       // the log holds break-away: fs within 20 % and determined
  within_20_either_way,    // fs within 20 %, whether reported determined or not
  within_20_or_said_free,  // fs within 20 %, or reported not identifiable
  said_free,               // fs reported not identifiable (the log holds no break-away)
};

// The cause of `effect` a report names and does not supersede (on `joint`, where given).
const nlohmann::json* live_cause(const nlohmann::json& r, const std::string& effect, const std::string& joint = "") {
  for (const auto& c : r["causes"])
    if (c["effect"] == effect && !c.contains("superseded_by") && (joint.empty() || c["joints"][0] == joint)) return &c;
  return nullptr;
}

// LuGre draw s of make_draw's family, its excitation's top frequency f_high (0: the default
// band, 0.1-1 Hz): `stick_slip` named on its joint, fc within 20 %, fs as `fs` says. Returns
// the report. `lowpass_hz`: the import's band.
nlohmann::json expect_stick_slip(const std::filesystem::path& dir, int s, double f_high, BreakAway fs, double lowpass_hz = 10) {
  Measurement m;
  m.f_high = f_high;
  m.lowpass_hz = lowpass_hz;
  const Draw d = make_draw(dir, "lugre", s, 0, m);
  const auto r = run_draw(dir, d, s);
  const auto causes = named(r);
  const std::string joint = "j" + std::to_string(d.joint);
  std::cout << d.what << " on " << joint << ": named " << joined(causes) << "\n  held out, relative error on " << joint << ": "
            << r["baseline"]["rel_error_test"][joint] << " as given, " << r["final"]["rel_error_test"][joint]
            << " written (extended.xml); rollouts worse on " << r["rollout"]["worse_on"].dump() << " "
            << r["rollout"]["position_error_before"].dump() << " -> " << r["rollout"]["position_error_after"].dump() << "\n";
  EXPECT_NE(std::find(causes.begin(), causes.end(), "stick_slip@" + joint), causes.end()) << joined(causes);
  // The written model, extended.xml with its declared LuGre force simulated along the held-out
  // split: the friction is 6-15 % of the joint's RMS torque and the noise 1 %, so it must take
  // most of the joint's relative error away (measured: 3-10 % of it is left), and its rollouts
  // on the joint must not end farther from the measured positions than the model as given's.
  EXPECT_LT(r["final"]["rel_error_test"][joint].get<double>(), 0.25 * r["baseline"]["rel_error_test"][joint].get<double>());
  for (const auto& w : r["rollout"]["worse_on"]) EXPECT_NE(w, joint) << "rollouts of extended.xml worse on the LuGre joint";
  if (const nlohmann::json* named_here = live_cause(r, "stick_slip", joint)) {
    const nlohmann::json& cause = *named_here;
    const auto& free = cause["not_identifiable"];
    const bool said_free = std::find(free.begin(), free.end(), "fs") != free.end();
    const double fs_error = std::fabs(cause["params"]["fs"].get<double>() - d.fs) / d.fs;
    std::cout << "  " << cause["params"].dump() << "\n  not identifiable " << free.dump() << "\n";
    EXPECT_NEAR(cause["params"]["fc"].get<double>(), d.fc, 0.2 * d.fc);
    // Written with its amplitude refitted against the parameters extended.xml states
    // (refit_written_effects): every magnitude by one factor, near 1 here, the Stribeck speed
    // as fitted.
    EXPECT_TRUE(cause.contains("params_written")) << cause.dump();
    if (cause.contains("params_written")) {
      const auto &p = cause["params"], &w = cause["params_written"];
      const double a = w["fc"].get<double>() / p["fc"].get<double>();
      EXPECT_NEAR(a, 1, 0.2);
      for (const char* k : {"fs", "sigma0", "sigma1"}) EXPECT_NEAR(w[k].get<double>(), a * p[k].get<double>(), 1e-9 * a * p[k].get<double>()) << k;
      EXPECT_EQ(w["vs"].get<double>(), p["vs"].get<double>());
    }
    if (fs == BreakAway::within_20_percent) {
      EXPECT_LE(fs_error, 0.2);
      EXPECT_FALSE(said_free) << free.dump();
    }
    if (fs == BreakAway::within_20_either_way) {
      EXPECT_LE(fs_error, 0.2);
    }
    if (fs == BreakAway::within_20_or_said_free) {
      EXPECT_TRUE(fs_error <= 0.2 || said_free) << "fs off by " << fs_error;
    }
    if (fs == BreakAway::said_free) {
      EXPECT_TRUE(said_free) << free.dump();
    }
  }
  return r;
}

// LuGre on a random joint of a random spatial 3-joint chain, random levels (fc 6-15 % of the
// joint's RMS torque, fs 1.2-2 fc, vs 0.03-0.23 rad/s, pre-sliding 1-3 mrad), positions only,
// 1 % torque noise, 18-bit encoders, derivatives through the usual 10 Hz low-pass: `stick_slip`
// on that joint with fc within 20 %. Draw 3 was `coulomb` before the stateful fit started from
// the static fits and was compared with them held out. At the default excitation (0.1-1 Hz)
// the reversals are fast, and whether the bristles climb the Stribeck hump before the joint
// slips depends on the draw: fs within 20 % or reported not identifiable.
TEST(DiagnoseBeyond, LuGreIsNamedOnRealisticDataAgainstTheStaticCandidates) {
  const auto dir = test::temp_dir("lugre10");
  for (int s : {3, 0}) expect_stick_slip(dir, s, 0, BreakAway::within_20_or_said_free);
}

// LuGre humps the 10 Hz import does not resolve, seed-table draws. 222 and 228 (Stribeck speeds
// 0.084 and 0.036 rad/s, crossed at the reversals in 26 and 14 ms): fits at fs = fc with vs
// 11-16 times the truth, fs (0.63 and 0.58 of the truth) read determined - the profile point
// with fs half as high again was polished from that wide hump and stayed 24-110 chi-square
// units off; each profile point now scans the shape keys first. 204: a hump narrower and taller
// than the truth (vs 0.28, fs 1.60 of it), crossed in 11 ms, "determined"; a speed key crossed
// in less than a quarter period of the filter's cut-off is not. 210: vs loose at 13 times the
// truth and fs 0.52 of it determined; where the width is loose, so is the height. Each: fs
// within 20 % or reported not identifiable.
TEST(DiagnoseBeyond, ABreakAwayTheLowPassHidesIsNotStatedAsDetermined) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("lugre_hidden_break");
  for (int s : {222, 228, 204, 210}) expect_stick_slip(dir, s, 0, BreakAway::within_20_or_said_free);
}

// What the import's band does to LuGre's break-away (the seed table's 30 draws, 1 kHz
// decimated to 200 Hz: fc and fs within 20 % on 18 through the 10 Hz import, 2 of them named
// `coulomb`; on 22 through 20 Hz and 25 through 40 Hz, none missed). Draw 202 through 10 Hz:
// fs 0.77 of the truth and vs 0.11 of it, both not identifiable, and the cause's `resolution`
// says which Stribeck speeds the band resolves and which import resolves more; the same draw
// through 40 Hz: fs within 20 % and determined, no such note.
TEST(DiagnoseBeyond, ABreakAwayTheBandSmearsSaysWhichBandResolvesIt) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto r10 = expect_stick_slip(test::temp_dir("lugre_band10"), 202, 0, BreakAway::said_free);
  const nlohmann::json* c10 = live_cause(r10, "stick_slip");
  ASSERT_NE(c10, nullptr);
  ASSERT_TRUE(c10->contains("resolution")) << c10->dump();
  const std::string note = (*c10)["resolution"].get<std::string>();
  std::cout << "  10 Hz: " << note << "\n";
  EXPECT_NE(note.find("through the 10 Hz low-pass the import applied"), std::string::npos) << note;
  EXPECT_NE(note.find("re-imported with --lowpass 40 --decimate 2 (from the log at 1000 Hz)"), std::string::npos) << note;
  const auto r40 = expect_stick_slip(test::temp_dir("lugre_band40"), 202, 0, BreakAway::within_20_either_way, 40);
  const nlohmann::json* c40 = live_cause(r40, "stick_slip");
  ASSERT_NE(c40, nullptr);
  // Through 40 Hz fs is within 20 % (above). Whether the profile also calls fs and vs determined
  // there lies on the edge: on one machine's processor it does (no note), on another's it leaves
  // them loose, fs 1.428 with a local standard error of 4 %, vs 12 % (stop 56). Where the note
  // stands, it is the 40 Hz band's and never the 10 Hz band's advice.
  if (c40->contains("resolution")) {
    const std::string note40 = (*c40)["resolution"].get<std::string>();
    std::cout << "  40 Hz: " << note40 << "\n";
    EXPECT_NE(note40.find("through the 40 Hz low-pass the import applied"), std::string::npos) << note40;
    EXPECT_EQ(note40.find("--lowpass 40 "), std::string::npos) << note40;
  }
}

// `spml import --lowpass 150 --decimate 5` at 1 kHz: the decimation's anti-alias keeps 80 Hz,
// and the dataset records the 150 Hz low-pass, which cannot run at 200 Hz. Read as the band,
// it left every column unfiltered: draw 206 (a review's trap) was named `coulomb`, and fs was
// reported not identifiable on the seed table's first 8 draws. Read as the decimation's band,
// the accelerations' noise in it is found and filtered: `stick_slip`, fs within 20 %.
TEST(DiagnoseBeyond, ALowPassAboveWhatTheDecimationKeptIsReadAsItsBand) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto r = expect_stick_slip(test::temp_dir("lugre_lowpass150"), 206, 0, BreakAway::within_20_percent, 150);
  EXPECT_EQ(r["parallel_filter"]["source"], "detected") << r["parallel_filter"].dump();
  EXPECT_TRUE(r["parallel_filter"]["applied"].get<bool>()) << r["parallel_filter"].dump();
  bool said = false;
  for (const auto& n : r["notes"]) said = said || n.get<std::string>().find("above the band its decimation to 200 Hz kept (its anti-alias at 80 Hz)") != std::string::npos;
  EXPECT_TRUE(said) << r["notes"].dump();
}

// Seed-table draws whose LuGre fit ran to an end: 202's Stribeck speed to the bottom of its
// range, 226's fs to fc with both levels determined. Each was refused for that and `coulomb`
// named, whose written model predicts the joint several times worse. Such keys are not
// identifiable, and the fit is named when it rolls out closer than every static friction on
// the joint (paired t 2.3 and 2.0 over 60 windows): `stick_slip`, fs reported not
// identifiable (0.77 and 0.50 of the truth).
TEST(DiagnoseBeyond, ALuGreFitAtAnEndIsNamedWhenItRollsOutCloser) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("lugre_at_end");
  for (int s : {202, 226}) expect_stick_slip(dir, s, 0, BreakAway::within_20_or_said_free);
}

// A friction experiment: the same draws excited at 0.1-0.3 Hz, slow reversals along which the
// friction climbs to its break-away force (a reversal at deceleration a climbs it when a is
// below about sigma0 vs^2 / fs): fc and fs within 20 %, fs determined. At the default band
// these draws' fs had come out 42, 34 and 27 % low, the friction of the true curve simulated
// along draw 6's log peaking at 0.61 for fs 0.76. Draw 6 was `coulomb` until the bristles started a
// split at their steady state: from rest, a split that began in motion opened with a transient
// of sigma1 v (-6 N m against a friction of 0.56), and LuGre lost the held-out test.
TEST(DiagnoseBeyond, LuGreOnAFrictionExperimentIsNamedWithItsBreakAway) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("lugre_slow");
  for (int s : {2, 4, 6}) expect_stick_slip(dir, s, 0.3, BreakAway::within_20_percent);
}

// The logger's half tick (the states -0.25 to -0.42 ms ahead of the torque held over each
// tick, TheLoggersHalfTickIsCorrectedWithoutAName) searched beside LuGre: the delay search's
// static nuisance does not hold the bristles' lag, and draws 5 and 7 of the default band read
// the offset as 0.86 +- 0.55 and 0.06 +- 0.26 ms, not resolved. Left in, it read the inertias'
// torque as damping (0.488 and 0.488 for 0.5 on j0) and `parameters` was named beside
// `stick_slip` (6 of 24 draws). Now it is searched again beside the stateful cause chosen
// (offset_beside), corrected, and the causes chosen again: `stick_slip` alone.
TEST(DiagnoseBeyond, TheLoggersHalfTickIsFoundBesideLuGre) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("halftick_lugre");
  for (int s : {5, 7}) {
    const auto r = expect_stick_slip(dir, s, 0, BreakAway::within_20_or_said_free);
    EXPECT_EQ(named(r).size(), 1u) << joined(named(r));
    EXPECT_TRUE(r["delay"]["corrected"].get<bool>()) << r["delay"].dump();
    EXPECT_FALSE(r["delay"]["named"].get<bool>());
    EXPECT_NEAR(r["delay"]["seconds"].get<double>(), -0.35e-3, 0.15e-3) << r["delay"].dump();
  }
}

// A 5 ms delay beside LuGre (seed-table kind lugre_delay): the first search, with only static
// friction beside the shift, read draws 5 and 7 as 5.87 +- 0.57 and 5.08 +- 0.24 ms, and on
// data so corrected the inertias' torque was read as damping and `parameters` was named beside
// `stick_slip`. Searched again beside the LuGre force chosen (offset_beside) they read 4.73 ms,
// like a delay alone (4.6-4.8 ms: the torque held over each tick); named both times, the
// causes chosen stand, and on the data corrected anew they are the delay and `stick_slip` on
// its joint alone (`parameters` is decided there).
TEST(DiagnoseBeyond, ADelayBesideLuGreIsSearchedAgainBesideIt) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("lugre_delay");
  for (int s : {5, 7}) {
    const Draw d = make_draw(dir, "lugre_delay", s, 5, Measurement{});
    const auto r = run_draw(dir, d, s);
    std::cout << d.what << ": delay " << 1e3 * r["delay"]["seconds"].get<double>() << " ± " << 1e3 * r["delay"]["stderr"].get<double>()
              << " ms, named " << joined(named(r)) << "\n  " << r["delay"]["why"] << "\n";
    ASSERT_TRUE(r["delay"]["named"].get<bool>()) << r["delay"].dump();
    EXPECT_NEAR(r["delay"]["seconds"].get<double>(), 5e-3, 0.5e-3);
    EXPECT_EQ(joined(named(r)), "delay stick_slip@j" + std::to_string(d.joint));
    // Its amplitude is refitted with the written model and folded into the keys written (the
    // named delay once shifted report.json's causes by one from the effects they describe).
    for (const auto& c : r["causes"])
      if (c["effect"] == "stick_slip") {
        EXPECT_TRUE(c.contains("params_written") && c["params_written"].is_object()) << c.dump();
        const std::string decl = c.value("declaration", "");
        const auto at = decl.find(" fc=");
        ASSERT_NE(at, std::string::npos) << decl;
        EXPECT_DOUBLE_EQ(std::stod(decl.substr(at + 4)), c["params_written"].value("fc", 0.0)) << c.dump();
      }
  }
}

// The skeptic's check of a stateful diagnosis: extended.xml, with the LuGre force it declares,
// predicts fresh logs of the same robot that the fit never saw - another friction experiment
// and a log at the default band (faster reversals than it was fitted on). Scored as diagnose
// scores any model as given (inverse dynamics plus its declared stateful forces simulated
// along the log): on the LuGre joint it must leave at most a quarter of the user's model's
// relative error (the friction is 6-15 % of the RMS torque, the noise 1 %), and diagnosing the
// fresh log against it names no friction on that joint.
TEST(DiagnoseBeyond, LuGreWrittenModelPredictsFreshLogs) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("lugre_fresh");
  const int s = 4;
  Measurement slow;
  slow.f_high = 0.3;
  const Draw d = make_draw(dir, "lugre", s, 0, slow);
  const std::string joint = "j" + std::to_string(d.joint);
  DiagnoseOptions opt;
  opt.model = d.c.user;
  opt.data = measured(d.c, (dir / "fit.h5").string(), static_cast<unsigned>(0x7ab1e00 + s) + 100, d.m);
  opt.rollouts = 0;
  const auto out = dir / "out";
  std::filesystem::create_directories(out);
  const auto fitted = diagnose(opt, out.string()).report;
  ASSERT_EQ(joined(named(fitted)), "stick_slip@" + joint);
  // report.md says which keys the data leave loose (one of equally good fits), without an error:
  // a review found them printed to four figures with a standard error like any other.
  std::ifstream md(out / "report.md");
  const std::string text((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  for (const auto& cause : fitted["causes"])
    for (const auto& k : cause.value("not_identifiable", nlohmann::json::array())) {
      const auto at = text.find("   - " + k.get<std::string>() + " ");
      ASSERT_NE(at, std::string::npos) << k << " not in report.md";
      const std::string line = text.substr(at, text.find('\n', at) - at);
      EXPECT_NE(line.find("(not identifiable)"), std::string::npos) << line;
      EXPECT_EQ(line.find("±"), std::string::npos) << line;
    }
  Case written = d.c;
  written.user = (out / "extended.xml").string();
  for (double f_high : {0.3, 0.0}) {
    Measurement m = slow;
    m.f_high = f_high;
    const std::string fresh = measured(d.c, (dir / ("fresh" + std::to_string(f_high) + ".h5")).string(), 977, m);
    const auto as_given = diagnose_case(d.c, fresh), extended = diagnose_case(written, fresh);
    double before = 0, after = 0;
    for (const char* split : {"rel_error_fit", "rel_error_test"}) {   // both unseen here
      before = as_given["baseline"][split][joint].get<double>(), after = extended["baseline"][split][joint].get<double>();
      std::cout << "fresh log, excitation to " << (f_high > 0 ? f_high : 1.0) << " Hz, " << split << " on " << joint << ": " << before
                << " the user's model, " << after << " extended.xml; extended.xml's diagnosis names " << joined(named(extended)) << "\n";
      EXPECT_LT(after, 0.25 * before) << split;
    }
    for (const auto& n : named(extended)) EXPECT_NE(n.substr(n.find('@') + 1), joint) << "a cause on the LuGre joint: " << n;
  }
}

// Draw 16 at the default band: the Stribeck speed of its LuGre fit ran to the top of its
// range, determined there (1.36 +- 0.10 rad/s for a truth of 0.065): the data push it beyond
// the effect's physics, not onto it, and what they show of the effect is its levels. Named
// then: the static friction of its level, Coulomb's fc within 20 % of LuGre's, and
// `stick_slip` on that joint in `not_tried` with why. The draw is borderline: on another CPU
// (other OpenBLAS kernels) the same commit fits fs = fc with vs loose at 0.019 rad/s and names
// `stick_slip`, fc within 0.2 %, fs and vs said not identifiable. Either is a right answer;
// what must not happen is a `stick_slip` whose Stribeck speed is stated as determined where the
// data pushed it. (A key that runs to an end while the data leave it loose has drifted there
// and rejects nothing: draw 6, whose vs had, is `stick_slip` now, its written model leaving
// 0.0044 of the joint's held-out relative error where Coulomb's left 0.028.)
TEST(DiagnoseBeyond, LuGreWhoseStribeckSpeedRunsOutOfRangeIsItsStaticFriction) {
  const auto dir = test::temp_dir("lugre_end");
  const int s = 16;
  const Draw d = make_draw(dir, "lugre", s, 0, Measurement{});
  const auto r = run_draw(dir, d, s);
  const std::string joint = "j" + std::to_string(d.joint);
  std::cout << d.what << " on " << joint << ": named " << joined(named(r)) << "\n  not tried " << r["not_tried"].dump() << "\n";
  bool coulomb = false, said = false, stick_slip = false;
  for (const auto& cause : r["causes"]) {
    if (cause.contains("superseded_by") || cause["joints"][0] != joint) continue;
    if (cause["effect"] == "coulomb") {
      coulomb = true;
      EXPECT_NEAR(cause["params"][joint + ".fc"].get<double>(), d.fc, 0.2 * d.fc);
    }
    if (cause["effect"] == "stick_slip") {
      stick_slip = true;
      std::cout << "  " << cause["params"].dump() << ", not identifiable " << cause["not_identifiable"].dump() << "\n";
      EXPECT_NEAR(cause["params"]["fc"].get<double>(), d.fc, 0.2 * d.fc);
      const auto& free = cause["not_identifiable"];
      const double vs = cause["params"]["vs"].get<double>();
      EXPECT_TRUE(std::find(free.begin(), free.end(), "vs") != free.end() || (vs > d.vs / 5 && vs < 5 * d.vs))
          << "vs " << vs << " stated as determined for a truth of " << d.vs;
    }
  }
  for (const auto& n : r["not_tried"])
    said = said || (n["effect"] == "stick_slip" && n.value("joint", "") == joint &&
                    n["reason"].get<std::string>().find("a static friction") != std::string::npos);
  EXPECT_TRUE(coulomb != stick_slip) << "one friction on the joint: " << joined(named(r));
  if (coulomb) {
    EXPECT_TRUE(said) << r["not_tried"].dump();
  }
}


// The fit by simulation runs on the machine's cores where the plugin's library flags its
// instances independent (force-plugin ABI revision 1; the shipped effects are): each thread
// walks its own instance, and the choices are made in the order of the serial loops, so one
// thread and four give the same report, number for number - a LuGre log with a 5 ms lag, whose
// delay is searched again beside the stateful fit.
TEST(DiagnoseBeyond, OneThreadAndFourGiveTheSameReport) {
  const auto dir = test::temp_dir("lugre_threads");
  const int s = 3;
  const Draw d = make_draw(dir, "lugre_delay", s, 5, Measurement{});
  const std::string data = measured(d.c, (dir / "lugre_delay.h5").string(), static_cast<unsigned>(0x7ab1e00 + s) + 100, d.m);
  nlohmann::json report[2];
  double seconds[2];
  for (int i = 0; i < 2; ++i) {
    DiagnoseOptions opt;
    opt.model = d.c.user;
    opt.data = data;
    opt.rollouts = 5;
    opt.threads = i ? 4 : 1;
    const auto t0 = std::chrono::steady_clock::now();
    report[i] = diagnose(opt, "").report;
    seconds[i] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    report[i].erase("timings_s");   // wall times: the one of the consistent fit of `parameters` too
    for (auto& cause : report[i]["causes"])
      if (cause.contains("written") && cause["written"].is_object()) cause["written"].erase("seconds");
  }
  std::cout << d.what << ": named " << joined(named(report[0])) << "; " << seconds[0] << " s on one thread, " << seconds[1] << " s on up to four\n";
  const auto causes = named(report[0]);
  EXPECT_TRUE(std::any_of(causes.begin(), causes.end(), [](const std::string& c) { return c.rfind("stick_slip@", 0) == 0; }))
      << "the stateful fit must have run: " << joined(causes);
  EXPECT_EQ(report[0].dump(1), report[1].dump(1));
}

// Draws 2 and 15 at the default band: the reversals are too fast for the bristles to climb the
// Stribeck hump, and equally good fits leave fs, vs and the bristles' sigma0 and sigma1 each
// 50 % apart. They had `coulomb` named (a stateful fit with no shape key determined was taken
// for its levels), whose written model left 27 and 30 % of the model as given's held-out
// relative error on the joint; LuGre, fitted as well as the data allow, leaves 4.8 and 7.2 %.
// Now `stick_slip`, fc within 20 %, fs reported not identifiable, and the written model under
// a tenth of the model as given's error, which no static friction reaches on these draws.
// Draw 12 had `coulomb` named too: its fit sits at fs = fc (no hump), its finite differences
// were refused on one side, and both levels read "not determined". Coulomb's written model
// left 0.018 of the joint's held-out relative error, LuGre's leaves 0.0023.
TEST(DiagnoseBeyond, LuGreWithoutBreakAwayInItsLogIsNamedWithFsNotIdentifiable) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("lugre_nobreak");
  for (int s : {2, 15, 12}) {
    const auto r = expect_stick_slip(dir, s, 0, BreakAway::said_free);
    for (const auto& cause : r["causes"])
      if (cause["effect"] == "stick_slip") {
        const std::string joint = cause["joints"][0];
        EXPECT_LT(r["final"]["rel_error_test"][joint].get<double>(), 0.1 * r["baseline"]["rel_error_test"][joint].get<double>()) << joint;
      }
  }
}

// A hidden Coulomb friction through the 10 Hz import (kind delay_coulomb, no delay), draws 8
// and 10: LuGre fits it with fs = fc, both determined, the plugin refusing fs below fc, and a
// bristle damping sigma1 of 35-72 - a damping at the reversals the low-pass rounds off. The
// edge of what the effect accepts binds there, as the end of a range does: `coulomb`, not
// `stick_slip` (named on both while a fit at that edge was let through). Draw 61 with a 5 ms
// delay, 2 % torque noise and 16-bit encoders (a review's draw): fs = fc loose, and every
// shape key loose too - Coulomb friction with bristles the data do not show - had beaten
// Coulomb held out by the tenth an unshaped fit needs. Draws 10 and 17 with a 5 ms delay (the
// seed table's): a fit at the edge or with fs 2 % above fc, each joining only by rolling out
// closer than the static frictions; 17's rolled out 1 % closer on the mean of 20 windows
// (paired t 0.07) and was named; over 60 windows beyond two standard errors it is not.
TEST(DiagnoseBeyond, CoulombWhoseLuGreFitRunsToTheEdgeIsCoulomb) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("coulomb_edge");
  for (const auto& [s, delay_ms, m] : {std::tuple{8, 0.0, Measurement{}}, std::tuple{10, 0.0, Measurement{}}, std::tuple{61, 5.0, noise_level(0.02, 16)},
                                       std::tuple{10, 5.0, Measurement{}}, std::tuple{17, 5.0, Measurement{}}}) {
    const Draw d = make_draw(dir, "delay_coulomb", s, delay_ms, m);
    const auto r = run_draw(dir, d, s);
    std::cout << d.what << ": named " << joined(named(r)) << "\n";
    const auto causes = named(r);
    EXPECT_NE(std::find(causes.begin(), causes.end(), "coulomb@j" + std::to_string(d.other)), causes.end()) << joined(causes);
    for (const auto& n : causes) EXPECT_EQ(n.find("stick_slip"), std::string::npos) << joined(causes);
  }
}

// A large hidden Coulomb friction (1.06 N m, 45 % of its joint's held-out error) on a friction
// experiment (0.1-0.3 Hz, 2 % torque noise, 16-bit encoders; a review's draw 200): LuGre fitted
// it with sigma1 at the top of its range and a Coulomb level fc that equally good fits leave
// apart (the profile), and beat Coulomb held out by more than the tenth an unshaped fit needs.
// It was named `stick_slip` beside `parameters` on inertia combinations, and the small joints'
// held-out errors doubled and tripled. A stateful fit whose principal level the profile leaves
// loose is not that effect (profile_once): `coulomb`, alone.
TEST(DiagnoseBeyond, ALuGreFitWithALooseCoulombLevelIsNotNamed) {
  const auto dir = test::temp_dir("loose_fc");
  Measurement m = noise_level(0.02, 16);
  m.f_high = 0.3;
  const Draw d = make_draw(dir, "delay_coulomb", 200, 0, m);
  const auto r = run_draw(dir, d, 200);
  EXPECT_EQ(joined(named(r)), "coulomb@j" + std::to_string(d.other));
}

// `parameters` beside LuGre on a friction experiment (0.1-0.3 Hz). The bristle damping sigma1
// acts as a damping at each slow reversal, and a joint's damping beside it is only as certain
// as the data leave it with the stateful keys free too (decide_parameters: the keys'
// derivatives as further columns). Held at the keys' fit, draws 11, 17 and 18 read the LuGre
// joint's damping as contradicted (0.24 for 0.5 on draw 18, its sigma1 3.8 times the truth)
// and named `parameters` with nothing wrong in the MJCF. Where the MJCF is wrong (the joint's
// true damping 0.35, draws 0 and 3) `parameters` is named with the damping within 5 %.
TEST(DiagnoseBeyond, TheBristlesDampingIsNotReadAsTheJointsDamping) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("lugre_damping");
  Measurement slow;
  slow.f_high = 0.3;
  for (int s : {11, 17, 18}) {
    const Draw d = make_draw(dir, "lugre", s, 0, slow);
    const auto r = run_draw(dir, d, s);
    std::cout << d.what << ": named " << joined(named(r)) << "\n";
    EXPECT_EQ(joined(named(r)), "stick_slip@j" + std::to_string(d.joint));
  }
  for (int s : {0, 3}) {
    Draw d = make_draw(dir, "lugre", s, 0, slow);
    with_true_damping(d, "0.35");
    const auto r = run_draw(dir, d, s);
    std::cout << d.what << ": named " << joined(named(r)) << "\n";
    const std::string joint = "j" + std::to_string(d.joint);
    bool stated = false;
    for (const auto& cause : r["causes"])
      if (cause["effect"] == "parameters" && cause["params"].contains("damping:" + joint)) {
        stated = true;
        EXPECT_NEAR(cause["params"]["damping:" + joint].get<double>(), 0.35, 0.05 * 0.35) << cause["params"].dump();
      }
    EXPECT_TRUE(stated) << joined(named(r));
    const auto causes = named(r);
    EXPECT_NE(std::find(causes.begin(), causes.end(), "stick_slip@" + joint), causes.end()) << joined(causes);
  }
}

// A review's 2-joint arm with LuGre friction on its elbow (fc 0.3, fs 0.5, vs 0.05, sigma0 150,
// sigma1 1.5), 31 s at 1 kHz under the PD controller, 1 % torque noise, 18-bit encoders,
// positions only, imported through a 10 Hz low-pass (decimated `decimate` times), diagnosed on
// the exact MJCF. Returns the report.
nlohmann::json diagnose_arm2_lugre(const std::filesystem::path& dir, int seed, int decimate) {
  const std::string arm = R"(<mujoco model="arm2">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81" integrator="Euler"><flag contact="disable"/></option>
  <default><joint type="hinge" axis="0 -1 0" armature="0.05" damping="0.4"/><geom type="capsule" size="0.03" contype="0" conaffinity="0"/></default>
  <worldbody>
    <body name="upper"><joint name="sh"/><inertial pos="0.3 0 0" mass="3.2" diaginertia="0.005 0.11 0.11"/><geom fromto="0 0 0 0.6 0 0"/>
      <body name="fore" pos="0.6 0 0"><joint name="el" armature="0.02" damping="0.15"/>
        <inertial pos="0.2 0 0.01" mass="1.3" diaginertia="0.002 0.025 0.024"/><geom fromto="0 0 0 0.45 0 0"/></body>
    </body>
  </worldbody>
</mujoco>
)";
  return test::diagnose_generated(dir, arm, test::with_declarations(arm, {"type=stick_slip joints=el fc=0.3 fs=0.5 vs=0.05 sigma0=150 sigma1=1.5 sigma2=0"}),
                                 "--seed " + std::to_string(seed) + " --duration 31 --torque-noise 0.01 --encoder-bits 18",
                                 "--t t --x q:sh,q:el --y tau:sh,tau:el --lowpass 10 --derive --drop-edges 612" +
                                     (decimate > 1 ? " --decimate " + std::to_string(decimate) : std::string()),
                                 20);
}

// `stick_slip` alone on the elbow, fc within 20 %, fs within 20 % or reported not identifiable.
void expect_arm2_stick_slip(const nlohmann::json& r) {
  ASSERT_EQ(joined(named(r)), "stick_slip@el");
  const auto& c = r["causes"][0];
  const auto& free = c["not_identifiable"];
  EXPECT_NEAR(c["params"]["fc"].get<double>(), 0.3, 0.2 * 0.3);
  EXPECT_TRUE(std::fabs(c["params"]["fs"].get<double>() / 0.5 - 1) <= 0.2 || std::find(free.begin(), free.end(), "fs") != free.end())
      << c["params"].dump() << " not identifiable " << free.dump();
}

// A LuGre log kept at 1 kHz (the import not decimating: 20 800 fit rows) is fitted as it is at
// 200 Hz. The stateful polish had its evaluations cut in proportion beyond 8000 rows, 115 per
// key here where 300 reach the optimum: the fit stopped at fs = fc with its levels at the edge,
// was refused, and `coulomb` was named beside `parameters` with the elbow's armature and damping
// 11 and 12 standard errors off the exact MJCF (a review's draw, seed 201). Now `stick_slip`
// alone (this log's reversals hide the break-away: fs is reported not identifiable, as it is
// decimated to 200 Hz).
TEST(DiagnoseBeyond, ALuGreLogKeptAtOneKilohertzIsFittedAsDecimated) {
  SPML_SKIP_UNDER_SANITIZERS();
  expect_arm2_stick_slip(diagnose_arm2_lugre(test::temp_dir("lugre_1khz"), 201, 1));
}

// A review's 3-joint robot (a yaw hinge, a shoulder hinge, a slide) with Coulomb friction of
// 0.6 N m hidden on its shoulder, 31 s at 1 kHz, 1 % torque noise, 18-bit encoders, positions
// only through the 10 Hz import, decimated to 200 Hz, seed 51; `true_damping`: the shoulder's
// true damping (the MJCF's is 0.25). Returns the report of diagnose on the MJCF.
nlohmann::json diagnose_rev3_coulomb(const std::filesystem::path& dir, const std::string& true_damping) {
  const std::string given = R"(<mujoco model="rev3arm">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <worldbody>
    <body name="base" pos="0 0 0.5">
      <joint name="yaw" type="hinge" axis="0 0 1" damping="0.4" armature="0.05"/>
      <inertial pos="0.02 0.01 0.05" mass="3.2" diaginertia="0.031 0.027 0.012"/>
      <body name="upper" pos="0 0 0.12">
        <joint name="shoulder" type="hinge" axis="0 1 0" damping="0.25" armature="0.03"/>
        <inertial pos="0.18 0 0.01" mass="1.7" diaginertia="0.004 0.021 0.019"/>
        <body name="slider" pos="0.35 0 0">
          <joint name="ext" type="slide" axis="1 0 0" damping="3.0" armature="0.2"/>
          <inertial pos="0.06 0 0" mass="0.65" diaginertia="0.0009 0.0021 0.0019"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";
  std::string truth = test::with_declarations(given, {"type=coulomb joints=shoulder fc=0.6"});
  truth.replace(truth.find("damping=\"0.25\""), 15, "damping=\"" + true_damping + "\"");
  return test::diagnose_generated(dir, given, truth, "--seed 51 --duration 31 --torque-noise 0.01 --encoder-bits 18",
                                 "--t t --x q:yaw,q:shoulder,q:ext --y tau:yaw,tau:shoulder,tau:ext --lowpass 10 --derive --drop-edges 612 --decimate 5",
                                 20);
}

// Through the import's low-pass, a Coulomb friction's switch at each reversal, and its stick
// phases, are what its sign(qd) column holds least well; the mismatch correlates with the
// reversal's accelerations and velocities. On the exact MJCF it read as the shoulder's inertia
// sum, 0.1134 for 0.1107, 7 standard errors off, and `parameters` was named before `coulomb`
// (a review's draw). The base parameters must contradict the MJCF on the rows away from the
// reversals too: `coulomb` alone. With the shoulder's true damping 0.35 beside the friction,
// `parameters` is named with that damping (0.347), and the inertia sum that only the
// reversals contradict is not listed.
TEST(DiagnoseBeyond, ACoulombFrictionsReversalsAreNotReadAsInertia) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto exact = diagnose_rev3_coulomb(test::temp_dir("rev3_exact"), "0.25");
  EXPECT_EQ(joined(named(exact)), "coulomb@shoulder");
  const auto damped = diagnose_rev3_coulomb(test::temp_dir("rev3_damped"), "0.35");
  ASSERT_EQ(joined(named(damped)), "parameters coulomb@shoulder");
  const auto& p = damped["causes"][0]["params"];
  EXPECT_EQ(p.size(), 1u) << p.dump();
  ASSERT_TRUE(p.contains("damping:shoulder")) << p.dump();
  EXPECT_NEAR(p["damping:shoulder"].get<double>(), 0.35, 0.02 * 0.35);
}

// A torque held over each sample leads the states by half a sample: 2.5 ms at 200 Hz, above
// the smallest delay named, and clean logs of `spml generate` had it named `delay` (-2.48 ms).
// It is measured and reported, not named.
TEST(DiagnoseBeyond, HalfASampleOfHeldTorqueIsNoDelay) {
  const auto dir = test::temp_dir("hold");
  const std::string arm = std::string(SPML_SOURCE_DIR) + "/mjcf/planar_arm3.xml", data = (dir / "arm.h5").string();
  const auto g = test::run(test::spml_bin() + " generate -q --model '" + arm + "' --duration 3 --rate 200 --derive -o '" + data + "'");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  const auto r = test::run(test::spml_bin() + " diagnose --model '" + arm + "' --data '" + data + "' --no-plots --rollouts 0 --out '" +
                           (dir / "d").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto rep = nlohmann::json::parse(test::read_file((dir / "d" / "report.json").string()));
  std::cout << "delay " << rep["delay"]["seconds"] << " s: " << rep["delay"]["why"] << "\n";
  EXPECT_FALSE(rep["delay"]["named"].get<bool>()) << rep["delay"].dump();
}

// Clean data at realistic noise (0.5 %, 1 %, 2 % torque noise with 20-, 18-, 16-bit encoders,
// derived velocities and accelerations): no `unexplained` entry. Draw 3 at 1 % had one through
// qdd:j1 with share 0.66 before the noise margin (a GP predicts part of the derivative errors).
TEST(DiagnoseBeyond, CleanJointsHaveNoUnexplainedStructure) {
  const auto dir = test::temp_dir("clean_unexplained");
  const std::vector<std::tuple<int, double, int>> draws = {{3, 0.01, 18}, {1, 0.005, 20}, {2, 0.02, 16}};
  for (const auto& [s, noise, bits] : draws) {
    const Draw d = make_draw(dir, "clean", s, 0, noise_level(noise, bits));
    const auto r = run_draw(dir, d, s);
    std::cout << "clean draw " << s << " at " << 100 * noise << " % noise: unexplained " << r["unexplained"].dump() << "\n";
    EXPECT_TRUE(r["unexplained"].empty()) << r["unexplained"].dump();
    EXPECT_TRUE(r["left_unexplained"].empty()) << r["left_unexplained"].dump();
  }
}

// A torque that follows time, not the state (a slow sine of a fifth of the joint's RMS torque:
// a load or a temperature the log does not hold) left 14-34 % of the joint's held-out torque
// on 8 seed-table draws with nothing named and, on 7, no `unexplained` entry either (the GP
// over the states cannot predict the later test split) - as a fifteenth review's rigid joint
// limit left 26.6 %. Such a joint is listed in `left_unexplained`, and only it.
TEST(DiagnoseBeyond, ATorqueTheStatesDoNotPredictIsLeftUnexplained) {
  const auto dir = test::temp_dir("drift");
  for (const int s : {200, 204}) {
    const Draw d = make_draw(dir, "drift", s, 0, Measurement{});
    const auto r = run_draw(dir, d, s);
    const std::string joint = "j" + std::to_string(d.joint);
    std::cout << d.what << " on " << joint << ": named " << joined(named(r)) << "; left_unexplained " << r["left_unexplained"].dump() << "\n";
    ASSERT_EQ(r["left_unexplained"].size(), 1u) << r["left_unexplained"].dump();
    EXPECT_EQ(r["left_unexplained"][0]["joint"], joint);
    EXPECT_NEAR(r["left_unexplained"][0]["rel_error_test"].get<double>(), r["final"]["rel_error_test"][joint].get<double>(), 1e-12);
  }
}

// Effects outside the vocabulary: cubic damping and a one-sided end stop. No cause named whose
// rollouts get worse; an `unexplained` entry on the effect's joint with the right input first
// (qd: for the damping, q: for the stop), and none on the clean joints (draw 3 gave one on a
// clean j0 with share 0.14 before the noise margin).
TEST(DiagnoseBeyond, CubicDampingAndAnEndStopAreReportedUnexplainedOnTheirInput) {
  const auto dir = test::temp_dir("outside");
  for (const auto& [kind, s, input] : std::vector<std::tuple<std::string, int, std::string>>{{"cubic", 3, "qd:"}, {"stop", 0, "q:"}}) {
    const Draw d = make_draw(dir, kind, s, 0, Measurement{});
    const auto r = run_draw(dir, d, s);
    const std::string joint = "j" + std::to_string(d.joint);
    std::cout << d.what << " on " << joint << ": named " << joined(named(r)) << "\n  unexplained " << r["unexplained"].dump() << "\n";
    bool found = false;
    for (const auto& u : r["unexplained"]) {
      EXPECT_EQ(u["joint"], joint) << "unexplained on a clean joint";
      if (u["joint"] != joint) continue;
      found = true;
      EXPECT_EQ(u["inputs"][0], input + joint);
    }
    EXPECT_TRUE(found);
    for (const auto& cause : r["causes"])
      if (!cause.contains("superseded_by"))
        for (const auto& j : cause["joints"])
          for (const auto& w : r["rollout"]["worse_on"]) {
            EXPECT_NE(j, w) << cause["effect"] << " makes the rollouts on " << w << " worse";
          }
  }
}

// The same effects where `parameters` takes them in: cubic damping read as the joints' damping
// (seed 201) and an end stop on a base joint read as its links' mass moments beside an offset
// (seed 215). Written, those parameters predicted the other joints' held-out torque worse, by
// 5.9 and 2.6 times over the joints (geometric mean of each joint's sum of squares relative to
// its own as given), while the sum in N m^2, which the base joint holds, was better. The
// held-out guard also judges with one variance per joint: the written model is never worse
// over the joints, and the effect is still reported unexplained on its joint.
TEST(DiagnoseBeyond, TheWrittenModelDoesNotTradeSmallJointsForALargeOne) {
  const auto dir = test::temp_dir("no_trade");
  for (const auto& [kind, s, input] : std::vector<std::tuple<std::string, int, std::string>>{{"cubic", 201, "qd:"}, {"stop", 215, "q:"}}) {
    const Draw d = make_draw(dir, kind, s, 0, Measurement{});
    const auto r = run_draw(dir, d, s);
    double log_ratio = 0;
    for (const auto& [j, given] : r["baseline"]["rmse_test"].items())
      log_ratio += 2 * std::log(r["final"]["rmse_test"][j].get<double>() / given.get<double>());
    EXPECT_LE(log_ratio, 1e-6) << kind << " " << s << ": named " << joined(named(r));
    bool found = false;
    for (const auto& u : r["unexplained"]) found |= u["joint"] == "j" + std::to_string(d.joint) && u["inputs"][0] == input + "j" + std::to_string(d.joint);
    EXPECT_TRUE(found) << kind << " " << s << ": " << r["unexplained"].dump();
  }
}

// The issue: sigma0 reported not identifiable where the data hold no pre-sliding. The same
// LuGre draw (seed 202, the issue's 6000 x 3: 30 s decimated to 200 Hz, 20 Hz import) with
// its own bristles (pre-sliding 2.4 mrad) and 100 times stiffer ones (24 urad, one count of the
// 18-bit encoder): the stiff fit stated sigma0 1.34 times the truth and sigma1 2.6 times as
// determined. Now the transient they shape (5 ms wide, under two 5 ms rows) marks both not
// identifiable, with a note; the soft one's (about 26 ms) leaves sigma0 determined, within 5 %.
TEST(DiagnoseBeyond, BristlesStifferThanTheRowsResolveAreNotIdentifiable) {
  const auto dir = test::temp_dir("stiff");
  Measurement m;
  m.lowpass_hz = 20, m.drop_edges = 307, m.duration = 30;
  for (const double scale : {1.0, 100.0}) {
    const Draw d = make_draw(dir, "lugre", 202, 0, m, scale);
    const auto r = run_draw(dir, d, 202);
    const nlohmann::json* c = live_cause(r, "stick_slip", "j" + std::to_string(d.joint));
    ASSERT_NE(c, nullptr) << "scale " << scale << ": named " << joined(named(r));
    const nlohmann::json ni = (*c)["not_identifiable"];
    auto loose = [&](const std::string& key) { return std::find(ni.begin(), ni.end(), key) != ni.end(); };
    std::cout << "sigma0 x" << scale << ": " << (*c)["params"].dump() << " not identifiable " << ni.dump() << "\n  " << c->value("resolution", "") << "\n";
    EXPECT_NEAR((*c)["params"]["fc"].get<double>(), d.fc, 0.05 * d.fc) << scale;
    if (scale == 1) {
      EXPECT_FALSE(loose("sigma0")) << ni.dump();
      EXPECT_NEAR((*c)["params"]["sigma0"].get<double>(), d.sigma0, 0.05 * d.sigma0);
    } else {
      EXPECT_TRUE(loose("sigma0") && loose("sigma1")) << ni.dump();
      EXPECT_NE(c->value("resolution", "").find("no pre-sliding"), std::string::npos) << c->dump(1);
    }
  }
}

// Written models that rolled out worse than the model as given, within the 20 windows' noise,
// were kept while only "worse beyond noise" (a paired mean beyond two standard errors) made
// the confirmation in simulation try taking causes out: an end stop read as `parameters` and an
// offset (seed 224: 1.09 times the model as given's rollouts over the joints, every joint
// worse) and cubic damping read as `parameters` (seed 212: 1.03, two joints worse). Now any
// joint whose mean is worse starts the trials, the causes on it are also taken out together,
// and one goes only where the model without it rolls out better. Seed 208's end stop was read
// as its joint's armature (0.059), which rolled that joint 1.07 times worse and was kept for
// another joint's 0.87 (0.93 over the joints): a cause whose own joint rolls out worse with it
// goes whatever it gives the others. Seed 208's cubic damping was read as its joint's damping
// (0.56 for the model's 0.5), which took a third of that joint's held-out error and left the
// rest to a GP over its velocity, and rolled two coupled joints worse (j0 by 1.6 %) while
// better over the joints: a nearest candidate (unexplained.cc), now judged on the worse joints
// alone.
TEST(DiagnoseBeyond, AWrittenModelThatRollsOutWorseIsTakenBack) {
  const auto dir = test::temp_dir("taken_back");
  for (const auto& [kind, s] : std::vector<std::pair<std::string, int>>{{"stop", 224}, {"cubic", 212}, {"stop", 208}, {"cubic", 208}}) {
    const Draw d = make_draw(dir, kind, s, 0, Measurement{});
    const auto r = run_draw(dir, d, s, 20);
    EXPECT_TRUE(r["rollout"]["worse_on"].empty()) << kind << " " << s << ": named " << joined(named(r)) << "\n" << r["rollout"].dump(1);
    double log_ratio = 0;
    for (const auto& [j, before] : r["rollout"]["position_error_before"].items())
      log_ratio += std::log(r["rollout"]["position_error_after"][j].get<double>() / before.get<double>());
    EXPECT_LE(log_ratio, 1e-9) << kind << " " << s;
    // `unexplained` is of what the written model leaves (its GP scored on evenly spaced held-out
    // rows: their RMS within a tenth of the split's), not of the fit the rejections undid.
    for (const auto& u : r["unexplained"])
      if (u.contains("rmse_test")) {
        const double written = r["final"]["rmse_test"][u["joint"].get<std::string>()].get<double>();
        EXPECT_NEAR(u["rmse_test"].get<double>(), written, 0.1 * written) << kind << " " << s << ": " << u.dump();
      }
  }
}

// A cause kept beside structure it does not hold says so, and a cross record (a fresh log of
// the same robot) is scored with extended.xml as written. Cubic damping (seed 200) read as its
// joint's damping is kept - its rollouts are better - beside `unexplained` on that joint
// through qd:, and is now marked `nearest_candidate`; a real damping error (true 0.35 for 0.5,
// seed 223), whose joint keeps a GP-predictable residual too but a twentieth of what
// `parameters` took there, is not. Cubic 212's `parameters` is rejected: its cross record
// stated the fit's error for an extended.xml that is the model as given (a review's cubic
// damping: 23.2 -> 14 %, where the file scored 23.2). A delay corrected in the cross record
// also states the model as given on the torques as measured.
TEST(DiagnoseBeyond, ANearestCandidateIsMarkedAndCrossRecordsScoreTheWrittenFile) {
  const auto dir = test::temp_dir("nearest");
  auto run_with_cross = [&](const Draw& d, int s) {
    const std::string stem = (dir / (d.what.substr(0, d.what.find(' ')) + std::to_string(s))).string();
    DiagnoseOptions opt;
    opt.model = d.c.user;
    opt.data = measured(d.c, stem + ".h5", static_cast<unsigned>(0x7ab1e00 + s) + 100, d.m);
    opt.cross = {measured(d.c, stem + "_fresh.h5", static_cast<unsigned>(0x7ab1e00 + s) + 300, d.m)};
    opt.rollouts = 20;
    return diagnose(opt, "").report;
  };
  auto kept = [](const nlohmann::json& r, const std::string& effect) -> const nlohmann::json* {
    for (const auto& c : r["causes"])
      if (c["effect"] == effect && !c.contains("rejected") && !c.contains("superseded_by")) return &c;
    return nullptr;
  };
  {
    const Draw d = make_draw(dir, "cubic", 200, 0, Measurement{});
    const auto r = run_with_cross(d, 200);
    const nlohmann::json* p = kept(r, "parameters");
    ASSERT_NE(p, nullptr) << joined(named(r));
    EXPECT_TRUE(p->contains("nearest_candidate")) << p->dump();
    if (p->contains("nearest_candidate")) {
      EXPECT_EQ((*p)["nearest_candidate"]["joint"], "j" + std::to_string(d.joint));
    }
    EXPECT_LT(r["cross"][0]["rel_error_final"].get<double>(), r["cross"][0]["rel_error_given"].get<double>()) << r["cross"].dump();
  }
  {
    Draw d = make_draw(dir, "clean", 223, 0, Measurement{});
    with_true_damping(d, "0.35");
    const auto r = run_with_cross(d, 223);
    const nlohmann::json* p = kept(r, "parameters");
    ASSERT_NE(p, nullptr) << joined(named(r));
    EXPECT_FALSE(p->contains("nearest_candidate")) << p->dump();
  }
  {
    const Draw d = make_draw(dir, "cubic", 212, 0, Measurement{});
    const auto r = run_with_cross(d, 212);
    EXPECT_EQ(kept(r, "parameters"), nullptr) << joined(named(r));
    const double given = r["cross"][0]["rel_error_given"].get<double>();
    EXPECT_NEAR(r["cross"][0]["rel_error_final"].get<double>(), given, 1e-6 * given) << r["cross"].dump();
  }
  {
    const Draw d = make_draw(dir, "delay", 200, 5, Measurement{});
    const auto r = run_with_cross(d, 200);
    ASSERT_TRUE(r["delay"]["named"].get<bool>()) << r["delay"].dump();
    ASSERT_TRUE(r["cross"][0].contains("rel_error_given_as_measured")) << r["cross"].dump();
    EXPECT_GT(r["cross"][0]["rel_error_given_as_measured"].get<double>(), 2 * r["cross"][0]["rel_error_given"].get<double>());
  }
}

// Rows past a limited joint's range: the MJCF regressor's inverse dynamics holds no limit
// force, and a seventeenth review's elbow driven into its `range` left 29.3 % of its torque
// with the true model itself, in silence. The note names the joint and the share of rows.
TEST(DiagnoseBeyond, RowsPastAJointLimitAreSaid) {
  const auto dir = test::temp_dir("limit");
  const Draw d = make_draw(dir, "clean", 200, 0, Measurement{});
  const std::string data = measured(d.c, (dir / "clean200.h5").string(), 0x7ab1e00 + 300, d.m);
  std::ifstream in(d.c.user);
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string tag = "name=\"j0\" type=\"hinge\"";
  ASSERT_NE(xml.find(tag), std::string::npos);
  xml.insert(xml.find(tag) + tag.size(), " limited=\"true\" range=\"-12 12\"");   // degrees (the chain's MJCF default): 0.2094 rad
  const std::string limited = (dir / "limited.xml").string();
  std::ofstream(limited) << xml;
  DiagnoseOptions opt;
  opt.model = limited;
  opt.data = data;
  opt.rollouts = 0;
  const auto r = diagnose(opt, "").report;
  int said = 0;
  for (const auto& n : r["notes"])
    if (n.get<std::string>().find("joint 'j0'") != std::string::npos && n.get<std::string>().find("past its range [-0.2094, 0.2094] rad") != std::string::npos) ++said;
  EXPECT_EQ(said, 1) << r["notes"].dump(1);
  for (const auto& n : r["notes"]) EXPECT_EQ(n.get<std::string>().find("joint 'j1': "), std::string::npos) << n;
}

// A `parameters` cause whose every listed term is a joint's own attribute is written as those
// terms alone (parameters_written "listed"), the MJCF's inertials kept. A damping error (0.35
// for 0.5) was written with every body re-identified by the consistent fit beside it: draw
// 223's damped joint kept 0.0184 of its held-out torque where the true model leaves 0.0026,
// and draw 213's light joint was 3.1 times worse (RMS) than as given, which the held-out guard
// then refused, cause and all. Written alone, each is the true model within the estimate.
TEST(DiagnoseBeyond, AJointsOwnTermsAreWrittenAlone) {
  const auto dir = test::temp_dir("listed");
  for (int s : {223, 213}) {
    Draw d = make_draw(dir, "clean", s, 0, Measurement{});
    with_true_damping(d, "0.35");
    const std::string data = measured(d.c, (dir / ("damping" + std::to_string(s) + ".h5")).string(), static_cast<unsigned>(0x7ab1e00 + s) + 100, d.m);
    DiagnoseOptions opt;
    opt.model = d.c.user;
    opt.data = data;
    opt.rollouts = 5;
    const auto out = dir / ("out" + std::to_string(s));
    const auto r = diagnose(opt, out.string()).report;
    opt.model = d.c.truth;
    opt.rollouts = 0;
    const auto truth = diagnose(opt, "").report;
    EXPECT_EQ(r["parameters_written"], "listed") << s << ": " << r["notes"].dump(1);
    const std::string joint = "j" + std::to_string(d.joint);
    const MjcfRegressor written((out / "extended.xml").string()), given(d.c.user);
    const auto names = given.param_names();
    for (size_t k = 0; k < names.size(); ++k) {
      const double w = written.model_params()[static_cast<Eigen::Index>(k)], g = given.model_params()[static_cast<Eigen::Index>(k)];
      if (names[k] == "damping:" + joint)
        EXPECT_NEAR(w, 0.35, 0.03 * 0.35) << s;
      else
        EXPECT_NEAR(w, g, 1e-9 + 1e-6 * std::fabs(g)) << s << " " << names[k];
    }
    for (const auto& [j, t] : truth["baseline"]["rmse_test"].items())
      EXPECT_LE(r["final"]["rmse_test"][j].get<double>(), 1.05 * t.get<double>()) << s << " " << j << ": the written model against the true one";
  }
}

// The issue's case size: 30 s at 1 kHz, the 20 Hz import, 307 samples dropped at each end.
Measurement issue_case_size() {
  Measurement m;
  m.lowpass_hz = 20, m.drop_edges = 307, m.duration = 30;
  return m;
}

// One draw diagnosed as logged on time and with its torques `delay_samples` ticks late (files
// NAME.h5 and NAME_late.h5 in dir), the delay read on each printed.
struct OnTimeAndLate {
  nlohmann::json on_time, late;
};
OnTimeAndLate on_time_and_late(const Case& c, const std::filesystem::path& dir, const std::string& name, unsigned seed, Measurement m,
                               int delay_samples) {
  OnTimeAndLate out;
  out.on_time = diagnose_case(c, measured(c, (dir / (name + ".h5")).string(), seed, m));
  m.delay_samples = delay_samples;
  out.late = diagnose_case(c, measured(c, (dir / (name + "_late.h5")).string(), seed, m));
  for (const auto* r : {&out.on_time, &out.late})
    std::cout << "  " << name << (r == &out.late ? " late" : " on time") << ": delay " << (*r)["delay"]["seconds"].get<double>() << " +- "
              << (*r)["delay"]["stderr"].get<double>() << " s below " << (*r)["delay"]["band_hz"].get<double>() << " Hz, named "
              << joined(named(*r)) << ", held out " << (*r)["final"]["rel_error_test_all"].get<double>() << "\n";
  return out;
}

// A model text with its one `key` replaced by `value`.
std::string filled(std::string xml, const std::string& key, const std::string& value) { return xml.replace(xml.find(key), key.size(), value); }

// A light joint's own term is judged against its own noise. A nineteenth review's 5-joint arm
// with a wrist whose torque is 1/250 of the shoulder's: the wrist's armature 3 times the
// MJCF's left its joint 60 times its noise, with Delta BIC -199 over one noise variance for
// every joint (the wrist's sums are nothing beside the shoulder's noise), and nothing named.
// Per joint (the free fit weighted by each joint's noise) the evidence is thousands; the
// armature is written alone. Clean data of the same arm name nothing.
const char* kArm5 = R"(<mujoco model="arm5">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <inertial pos="0 0 0.05" mass="5" diaginertia="0.03 0.03 0.02"/>
      <joint name="J1" type="hinge" axis="0 0 1" damping="2.0" armature="0.5"/>
      <body name="upper" pos="0 0 0.1">
        <inertial pos="0.2 0 0" mass="4" diaginertia="0.01 0.06 0.06"/>
        <joint name="J2" type="hinge" axis="0 1 0" damping="1.5" armature="0.4"/>
        <body name="fore" pos="0.4 0 0">
          <inertial pos="0.15 0 0" mass="2" diaginertia="0.004 0.02 0.02"/>
          <joint name="J3" type="hinge" axis="0 1 0" damping="0.8" armature="0.2"/>
          <body name="wrist" pos="0.3 0 0">
            <inertial pos="0.03 0 0" mass="0.15" diaginertia="0.0001 0.0002 0.0002"/>
            <joint name="J4" type="hinge" axis="0 1 0" damping="0.01" armature="ARMATURE"/>
            <body name="flange" pos="0.06 0 0">
              <inertial pos="0.01 0 0.01" mass="0.05" diaginertia="0.00002 0.00002 0.00002"/>
              <joint name="J5" type="hinge" axis="1 0 0" damping="0.005" armature="0.001"/>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";

TEST(DiagnoseBeyond, ALightJointsOwnTermIsJudgedWithItsOwnNoise) {
  const auto dir = test::temp_dir("light");
  auto arm = [](const std::string& armature) { return filled(kArm5, "ARMATURE", armature); };
  const Measurement m = issue_case_size();
  for (const std::string truth : {"0.006", "0.002"}) {
    Case c;
    c.joints = 5;
    c.user = (dir / "given.xml").string();
    c.truth = (dir / ("true" + truth + ".xml")).string();
    std::ofstream(c.user) << arm("0.002");
    std::ofstream(c.truth) << arm(truth);
    const auto r = diagnose_case(c, measured(c, (dir / ("arm" + truth + ".h5")).string(), 11, m), 0);
    if (truth == "0.002") {
      EXPECT_EQ(joined(named(r)), "nothing") << r["statistics"].dump();
      continue;
    }
    ASSERT_EQ(joined(named(r)), "parameters") << r["statistics"].dump();
    EXPECT_GT(r["statistics"]["parameters_delta_bic_per_joint"].get<double>(), 1000);
    const auto& p = r["causes"][0]["params"];
    ASSERT_TRUE(p.contains("armature:J4")) << p.dump();
    EXPECT_NEAR(p["armature:J4"].get<double>(), 0.006, 0.1 * 0.006);
    EXPECT_EQ(r["parameters_written"], "listed") << p.dump();
    EXPECT_LT(r["final"]["rmse_test"]["J4"].get<double>(), 0.1 * r["baseline"]["rmse_test"]["J4"].get<double>());
  }
}

// A cause stands on its own coefficients. kArm5 with a lifting column (slide) under the
// shoulder and a telescoping slide before the elbow, the shape of a twenty-second review's
// arm: on clean data an `offset` of 0.012 +- 0.005 N m (2.4 robust standard errors) on the
// light elbow passed the evidence bar at Delta BIC 91 - the drop of the elbow's residual when
// the base parameters, freed by it, moved onto the elbow from the joints they share - and
// beside a 4x wrist damping it was kept (a twenty-second review: it spoiled the damping's
// written residual, the damping was judged nearest and taken back).
const char* kArm7 = R"(<mujoco model="arm7">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <inertial pos="0 0 0.05" mass="6" diaginertia="0.05 0.05 0.03"/>
      <joint name="J1" type="hinge" axis="0 0 1" damping="2.0" armature="0.5"/>
      <body name="column" pos="0 0 0.1">
        <inertial pos="0 0 0.1" mass="3" diaginertia="0.02 0.02 0.01"/>
        <joint name="S1" type="slide" axis="0 0 1" damping="20" armature="1"/>
        <body name="upper" pos="0 0 0.2">
          <inertial pos="0.2 0 0" mass="3" diaginertia="0.01 0.05 0.05"/>
          <joint name="J2" type="hinge" axis="0 1 0" damping="1.5" armature="0.4"/>
          <body name="tele" pos="0.3 0 0">
            <inertial pos="0.1 0 0" mass="1" diaginertia="0.002 0.01 0.01"/>
            <joint name="S2" type="slide" axis="1 0 0" damping="10" armature="0.5"/>
            <body name="fore" pos="0.2 0 0">
              <inertial pos="0.1 0 0" mass="1" diaginertia="0.002 0.008 0.008"/>
              <joint name="J3" type="hinge" axis="0 1 0" damping="0.5" armature="0.1"/>
              <body name="wrist" pos="0.2 0 0">
                <inertial pos="0.03 0 0" mass="0.15" diaginertia="0.0001 0.0002 0.0002"/>
                <joint name="J4" type="hinge" axis="0 1 0" damping="DAMPING" armature="0.002"/>
                <body name="flange" pos="0.06 0 0">
                  <inertial pos="0.01 0 0.01" mass="0.05" diaginertia="0.00002 0.00002 0.00002"/>
                  <joint name="J5" type="hinge" axis="1 0 0" damping="0.005" armature="0.001"/>
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";

// kArm7 as given (wrist damping 0.01) in `dir`; the true model `truth` beside it, or the same file.
Case arm7_case(const std::filesystem::path& dir, const std::string& truth = "") { return given_case(dir, filled(kArm7, "DAMPING", "0.01"), 7, truth); }

TEST(DiagnoseBeyond, ACauseStandsOnItsOwnCoefficients) {
  const auto dir = test::temp_dir("own");
  Case c = arm7_case(dir);
  for (const unsigned seed : {1u, 2u})   // seed 1: the offset beside the damping, before
    for (const std::string damping : {"0.01", "0.04"}) {
      c.truth = (dir / ("true" + damping + ".xml")).string();
      std::ofstream(c.truth) << filled(kArm7, "DAMPING", damping);
      const auto r = diagnose_case(c, measured(c, (dir / ("arm" + damping + "_" + std::to_string(seed) + ".h5")).string(), seed, issue_case_size()), 0);
      std::cout << "seed " << seed << " damping " << damping << ": " << joined(named(r)) << "\n";
      if (damping == "0.01") {
        EXPECT_EQ(joined(named(r)), "nothing") << seed;
        continue;
      }
      ASSERT_EQ(joined(named(r)), "parameters") << seed;
      const auto& p = r["causes"][0]["params"];
      ASSERT_TRUE(p.contains("damping:J4")) << p.dump();
      EXPECT_NEAR(p["damping:J4"].get<double>(), 0.04, 0.05 * 0.04);
      EXPECT_FALSE(r["causes"][0].contains("nearest_candidate")) << r["causes"][0].dump();
      EXPECT_FALSE(r["causes"][0].contains("reads_as_well")) << r["causes"][0].dump();   // a damping is a viscous friction: nothing to say
    }
}

// 12-bit encoders on a model-exact log: the yaw base joint, whose torque is all inertia, is left
// 48 % of its torque by the accelerations' quantization error, the elbow and the flange 5-6 %.
// A twenty-second review had such joints `left_unexplained` ("a load, a command, a
// temperature"). Now they are at the encoders' floor, which the import's recorded steps give;
// a slow drift in time of about the floor's size on the same log is still left unexplained.
TEST(DiagnoseBeyond, TwelveBitEncodersLeaveAFloorNotAnEffect) {
  const auto dir = test::temp_dir("bits");
  const Case c = arm7_case(dir);
  Measurement m = issue_case_size();
  m.bits = 12;
  auto r = diagnose_case(c, measured(c, (dir / "exact.h5").string(), 1, m), 0);
  EXPECT_EQ(joined(named(r)), "nothing");
  EXPECT_TRUE(r["left_unexplained"].empty()) << r["left_unexplained"].dump();
  std::set<std::string> at_floor;
  for (const auto& f : r["at_resolution_floor"]) {
    at_floor.insert(f["joint"].get<std::string>());
    // The floor is what the joint measured, within the margin (the floor's own spread).
    EXPECT_GT(f["floor_rmse"].get<double>(), f["rmse_test"].get<double>() / 1.5) << f.dump();
    EXPECT_LT(f["floor_rmse"].get<double>(), 1.5 * f["rmse_test"].get<double>()) << f.dump();
  }
  EXPECT_EQ(at_floor.count("J1"), 1u) << r["at_resolution_floor"].dump();
  // A drift in time on the base of about its floor's size (RMS 0.35 N m against 0.59): within 2
  // times the floor by magnitude, but slow, where the floor is not.
  m.extra_joint = 0;   // J1
  const double a = 0.5, period = 0.45 * m.duration;
  m.drift = [a, period](double t) { return a * std::sin(2 * M_PI * t / period); };
  r = diagnose_case(c, measured(c, (dir / "drift.h5").string(), 1, m), 0);
  bool listed = false;
  for (const auto& l : r["left_unexplained"]) listed |= l["joint"] == "J1";
  EXPECT_TRUE(listed) << r["left_unexplained"].dump() << r["at_resolution_floor"].dump() << joined(named(r));
  for (const auto& f : r["at_resolution_floor"]) EXPECT_LE(f["slow_share"].get<double>(), 0.15) << f.dump();
}

// An effect only the fit rows hold (a twenty-third review's joint limit, reached in the first
// 15 s of 30 only): the held-out rows are clean, and the fit split's 77 % on the joint was said
// nowhere. Here a load on the shoulder for the first 12 s: listed, as on the fit split.
TEST(DiagnoseBeyond, AnEffectOnlyTheFitRowsHoldIsLeftUnexplained) {
  const auto dir = test::temp_dir("early");
  const Case c = arm7_case(dir);
  Measurement m = issue_case_size();
  m.extra_joint = 2;   // J2
  m.drift = [](double t) { return t < 12 ? 3.0 * std::sin(2 * M_PI * t / 5) : 0.0; };
  const auto r = diagnose_case(c, measured(c, (dir / "early.h5").string(), 1, m), 0);
  bool listed = false;
  for (const auto& l : r["left_unexplained"])
    if (l["joint"] == "J2") {
      listed = true;
      EXPECT_EQ(l.value("split", ""), "fit") << l.dump();
      EXPECT_GT(l["rel_error_fit"].get<double>(), 0.05) << l.dump();
    }
  EXPECT_TRUE(listed) << r["left_unexplained"].dump() << " " << joined(named(r)) << " " << r["final"]["rel_error_fit"].dump();
}

// A constant force on the vertical column slide is, on any log, the weight of a little less
// mass it carries with that mass's inertia handed back to the armature: `parameters` writes
// it so (a twenty-second review), and says now that an offset reads the same.
TEST(DiagnoseBeyond, AnOffsetOnAVerticalSlideIsSaidToReadAsItsCarriedMass) {
  const auto dir = test::temp_dir("lift");
  const Case c = arm7_case(dir, filled(filled(kArm7, "DAMPING", "0.01"), "</mujoco>",
                                       R"(<custom><text name="spml.plugin.lift" data="type=offset joints=S1 c=5"/></custom></mujoco>)"));
  const auto r = diagnose_case(c, measured(c, (dir / "lift.h5").string(), 3, issue_case_size()), 0);
  ASSERT_EQ(joined(named(r)), "parameters");
  const auto& cause = r["causes"][0];
  ASSERT_TRUE(cause.contains("reads_as_well")) << cause.dump();
  ASSERT_EQ(cause["reads_as_well"].size(), 1u) << cause["reads_as_well"].dump();   // not the spring's or asymmetric friction's copies
  const auto& a = cause["reads_as_well"][0];
  EXPECT_EQ(a["effect"], "offset");
  EXPECT_EQ(a["joint"], "S1");
  EXPECT_GE(a["share"].get<double>(), 0.95);
  EXPECT_NEAR(std::fabs(a["params"]["S1.c"].get<double>()), 5.0, 0.05 * 5.0) << a.dump();
}

// A yaw, a horizontal slide and two pitch joints (a twenty-fifth review's arm).
const char* kArmYawSlide = R"(<mujoco model="arm_yaw_slide">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <inertial pos="0 0 0.05" mass="5" diaginertia="0.04 0.04 0.03"/>
      <joint name="yaw" type="hinge" axis="0 0 1" damping="1.5" armature="0.3"/>
      <body name="carriage" pos="0 0 0.1">
        <inertial pos="0.05 0 0" mass="2" diaginertia="0.01 0.01 0.01"/>
        <joint name="slide" type="slide" axis="1 0 0" damping="15" armature="0.8"/>
        <body name="upper" pos="0.1 0 0">
          <inertial pos="0.2 0 0" mass="2.5" diaginertia="0.008 0.04 0.04"/>
          <joint name="pitch1" type="hinge" axis="0 1 0" damping="1.0" armature="0.3"/>
          <body name="fore" pos="0.4 0 0">
            <inertial pos="0.15 0 0" mass="1.2" diaginertia="0.003 0.012 0.012"/>
            <joint name="pitch2" type="hinge" axis="0 1 0" damping="0.5" armature="0.1"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";

// A stepped sine for every joint of kArmYawSlide (a reference CSV for Measurement::reference):
// the frequency steps through `freqs` in equal parts of `duration`, the phase continuous, the
// amplitude 0.4 rad (the slide 0.05 m).
std::string stepped_sine(const std::filesystem::path& path, const std::vector<double>& freqs, const std::vector<double>& phases, double duration) {
  const std::vector<double> amp = {0.4, 0.05, 0.4, 0.4};
  std::ofstream f(path);
  f.precision(12);
  f << "t,q:yaw,q:slide,q:pitch1,q:pitch2\n";
  const double dt = 0.002, part = duration / static_cast<double>(freqs.size());
  std::vector<double> phase = phases;
  for (int i = 0; i * dt <= duration + 1e-9; ++i) {
    const double t = i * dt;
    const size_t k = std::min(freqs.size() - 1, static_cast<size_t>(t / part));
    f << t;
    for (size_t j = 0; j < amp.size(); ++j) {
      phase[j] += 2 * M_PI * freqs[k] * dt;
      f << "," << amp[j] * std::sin(phase[j]);
    }
    f << "\n";
  }
  return path.string();
}

// What the encoders' quantization leaves is no effect, even where a GP predicts it. A model-exact
// 10-bit log of kArmYawSlide under a slow stepped sine: the yaw joint's held-out residual is 2.3
// times its torque, 1.45 times the floor, and a GP on the states predicted 73 % of it through
// qdd:yaw - the quantization error read back through the accelerations it made - and reported it
// `unexplained` (the pitch1 joint's 75 % too). Both are at the encoders' floor now; a cubic
// damping on pitch1, whose torque follows the excitation's band, is still `unexplained` there.
TEST(DiagnoseBeyond, AGpOnTheEncodersFloorIsNoEffect) {
  const auto dir = test::temp_dir("floor_gp");
  Case c = given_case(dir, kArmYawSlide, 4);
  Measurement m = issue_case_size();
  m.bits = 10;
  m.reference = stepped_sine(dir / "stepped.csv", {0.22484809, 0.10401516, 0.18756436, 0.16597457, 0.33016917},
                             {4.7475047, 5.8585926, 4.6190528, 1.3722347}, m.duration);
  auto r = diagnose_case(c, measured(c, (dir / "exact.h5").string(), 156, m), 0);
  EXPECT_TRUE(r["unexplained"].empty()) << r["unexplained"].dump();
  EXPECT_TRUE(r["left_unexplained"].empty()) << r["left_unexplained"].dump();
  bool yaw = false;
  for (const auto& f : r["at_resolution_floor"])
    if (f["joint"] == "yaw") {
      yaw = true;
      EXPECT_GT(f.value("gp_share", 0.0), 0.5) << f.dump();   // what was reported `unexplained` before
      EXPECT_LE(f["rmse_test"].get<double>(), 2 * f["floor_rmse"].get<double>()) << f.dump();
    }
  EXPECT_TRUE(yaw) << r["at_resolution_floor"].dump();
  // A cubic damping on pitch1 (60 qd^3 N m), slow as the motion is.
  m.extra_joint = 2;
  m.extra = [](double, double qd) { return 60.0 * qd * qd * qd; };
  r = diagnose_case(c, measured(c, (dir / "cubic.h5").string(), 156, m), 0);
  bool held = false;
  for (const auto& u : r["unexplained"])
    if (u["joint"] == "pitch1" && u.contains("share")) held = true;
  EXPECT_TRUE(held) << r["unexplained"].dump() << r["at_resolution_floor"].dump() << joined(named(r));
}

// A reference of holds for every joint of kArmYawSlide: every 0.25 s a new set point, reached
// by an 80 ms ramp; each joint's set points a sum of four sines (0.1-1 Hz) of 0.2 rad each
// (the slide 0.025 m).
std::string holds(const std::filesystem::path& path, double duration) {
  const std::vector<double> amp = {0.2, 0.025, 0.2, 0.2};
  const double f[4][4] = {{0.13, 0.41, 0.67, 0.92}, {0.21, 0.36, 0.58, 0.87}, {0.11, 0.47, 0.74, 0.95}, {0.17, 0.29, 0.62, 0.81}};
  auto set_point = [&](size_t j, double t) {
    double v = 0;
    for (int i = 0; i < 4; ++i) v += amp[j] * std::sin(2 * M_PI * f[j][i] * t + 1.3 * (i + 1) * (j + 1));
    return v;
  };
  std::ofstream out(path);
  out.precision(12);
  out << "t,q:yaw,q:slide,q:pitch1,q:pitch2\n";
  for (double t = 0; t <= duration + 1e-9; t += 0.25)
    for (const double at : {t, t + 0.17}) {   // the hold, then the ramp's start
      if (at > duration) break;
      out << at;
      for (size_t j = 0; j < amp.size(); ++j) out << "," << set_point(j, t);
      out << "\n";
    }
  return path.string();
}

// A reference of holds puts much of the torque into the import's transition band, and the
// states went through the import's low-pass as the torques did. Filtered a second time, the
// model's columns lost that content: the MJCF that made the log (kArmYawSlide, a twenty-fifth
// review's arm) left 8.3 % of every joint's torque at 14 bits, `parameters` was named, and at
// 10 bits `stick_slip` on two joints of four (3 of 3 seeds). A second pass would change these
// torques by 8 % of their RMS: the smooth columns are now left as the states made them
// (parallel_filter.again_above_hz), and the same logs name nothing.
TEST(DiagnoseBeyond, AReferenceOfHoldsNamesNothingOnTheModelThatMadeIt) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("holds");
  Case c = given_case(dir, kArmYawSlide, 4);
  Measurement m = issue_case_size();
  m.reference = holds(dir / "holds.csv", m.duration);
  for (const int bits : {14, 10}) {
    m.bits = bits;
    const auto r = diagnose_case(c, measured(c, (dir / ("holds" + std::to_string(bits) + ".h5")).string(), 151, m), 0);
    EXPECT_EQ(joined(named(r)), "nothing") << bits << " bits";
    EXPECT_GT(r["parallel_filter"]["second_pass_change"].get<double>(), 0.05) << r["parallel_filter"].dump();
    EXPECT_GT(r["parallel_filter"]["again_above_hz"].get<double>(), 0) << r["parallel_filter"].dump();
    EXPECT_TRUE(r["unexplained"].empty()) << r["unexplained"].dump();
    if (bits == 14) {   // filtered twice, 8.3 % on every joint
      for (const auto& [joint, e] : r["baseline"]["rel_error_test"].items()) EXPECT_LT(e.get<double>(), 0.06) << joint;
    }
  }
}

// A twenty-sixth review's spatial arm: a yaw and two pitch joints.
const char* kArm3Spatial = R"(<mujoco model="arm3s">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <worldbody>
    <body name="base" pos="0 0 0">
      <joint name="yaw" type="hinge" axis="0 0 1" armature="0.3" damping="2.5"/>
      <inertial pos="0 0 0.1" mass="3" diaginertia="0.05 0.05 0.03"/>
      <body name="upper" pos="0 0 0.2">
        <joint name="sh" type="hinge" axis="0 1 0" armature="0.2" damping="1.5"/>
        <inertial pos="0.25 0 0" mass="2.2" diaginertia="0.004 0.05 0.05"/>
        <body name="fore" pos="0.5 0 0">
          <joint name="el" type="hinge" axis="0 1 0" armature="0.08" damping="0.6"/>
          <inertial pos="0.18 0 0.01" mass="0.9" diaginertia="0.001 0.012 0.012"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";

// Point-to-point moves for every joint of kArm3Spatial at once (a twenty-sixth review's
// reference): from the set point before to {yaw, sh, el} between t0 and t1 with a trapezoidal
// velocity (30 % of the move accelerating, 30 % braking), dwells of 0.3 s between; written
// every millisecond.
struct Move { double t0, t1, q[3]; };
const Move kReviewMoves[] = {
      {0.000, 1.165, 0.018124, 0.571492, -0.670662},
      {1.466, 2.431, -0.197621, 0.362281, -0.520755},
      {2.730, 3.853, 0.070306, 0.482658, -0.036554},
      {4.153, 5.012, 0.462315, 0.580984, -0.208439},
      {5.311, 6.493, 0.686442, -0.386769, 0.174163},
      {6.793, 7.816, 0.708486, 0.198789, -0.586567},
      {8.116, 9.015, -0.010208, 0.000271, 0.733732},
      {9.314, 10.125, -0.441966, 0.026504, 0.225873},
      {10.424, 11.588, 0.131225, -0.278600, 0.687640},
      {11.888, 12.783, 0.281281, -0.028753, -0.452832},
      {13.083, 14.099, 0.433009, -0.371054, -0.064134},
      {14.398, 15.216, -0.526832, -0.334378, 0.740012},
      {15.515, 16.646, -0.188333, 0.287368, -0.732851},
      {16.947, 18.095, 0.059473, 0.384321, -0.358499},
      {18.395, 19.221, -0.243130, 0.566928, -0.112864},
      {19.521, 20.421, 0.729566, 0.483835, -0.167983},
      {20.720, 21.505, 0.491277, -0.471034, -0.172498},
      {21.805, 22.931, 0.668228, -0.319828, -0.674048},
      {23.231, 24.303, 0.194845, -0.314994, 0.009429},
      {24.604, 25.247, 0.320140, 0.032071, 0.327437},
      {25.546, 26.199, 0.231704, -0.155597, -0.001106},
      {26.500, 27.301, 0.214538, 0.081913, 0.187384},
      {27.600, 28.239, -0.439773, -0.513715, -0.186723},
      {28.538, 29.427, -0.620253, 0.201107, -0.020229},
      {29.727, 30.627, 0.155945, 0.521854, 0.142184},
      {30.927, 30.999, 0.135512, 0.513665, 0.130121}};

std::string trapezoids(const std::filesystem::path& path, double duration) {
  constexpr double acc = 0.3, vmax = 1 / (1 - acc);
  auto profile = [&](double s) {
    return s < acc ? 0.5 * vmax / acc * s * s : s < 1 - acc ? 0.5 * vmax * acc + vmax * (s - acc) : 1 - 0.5 * vmax / acc * (1 - s) * (1 - s);
  };
  std::ofstream out(path);
  out.precision(9);
  out << "t,q:yaw,q:sh,q:el\n";
  double from[3] = {0, 0, 0};
  size_t k = 0;
  for (int i = 0; i * 0.001 <= duration + 1e-9; ++i) {
    const double t = i * 0.001;
    while (k + 1 < std::size(kReviewMoves) && t >= kReviewMoves[k + 1].t0) {
      for (int j = 0; j < 3; ++j) from[j] = kReviewMoves[k].q[j];
      ++k;
    }
    const Move& m = kReviewMoves[k];
    const double p = t < m.t0 ? 0 : t <= m.t1 ? profile((t - m.t0) / (m.t1 - m.t0)) : 1;
    out << t;
    for (int j = 0; j < 3; ++j) out << "," << from[j] + (m.q[j] - from[j]) * p;
    out << "\n";
  }
  return path.string();
}

// A delay is judged held out beside whichever base parameters predict the held-out split
// better unshifted: the refitted ones or the MJCF's. A twenty-sixth review's model-exact 10-bit
// log under point-to-point moves had -36 ms named (every joint agreeing, standard error 0.4
// ms): beside refitted base parameters, whose errors in variables the quantized accelerations
// make, it gained a tenth held out, though they predicted worse than the MJCF's; `parameters`
// was not named, and the model as given predicted every joint worse with the shift (1.30 ->
// 1.36, 0.21 -> 0.23, 0.33 -> 0.36 of their torques). Judged with the MJCF's parameters alone,
// a real 5 ms delay on a robot with a payload the MJCF lacks was lost (a second review's, on
// 7 of 7 logs with a payload or a heavier link): there the refitted ones predict better, and judge it.
TEST(DiagnoseBeyond, ADelayIsJudgedBesideTheBaseParametersThatPredictBetter) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("trapezoid_delay");
  Case c = given_case(dir, kArm3Spatial, 3);
  Measurement m = issue_case_size();
  m.bits = 10;
  m.reference = trapezoids(dir / "moves.csv", m.duration);
  const auto r = diagnose_case(c, measured(c, (dir / "moves.h5").string(), 2, m));
  EXPECT_FALSE(r["delay"]["named"].get<bool>()) << r["delay"].dump();
  EXPECT_FALSE(r["delay"]["corrected"].get<bool>()) << r["delay"].dump();
  for (const auto& [joint, e] : r["final"]["rel_error_test"].items())
    EXPECT_LE(e.get<double>(), r["baseline"]["rel_error_test"][joint].get<double>() * (1 + 1e-9)) << joint;
  // A real delay beside a 1.5 kg payload the MJCF lacks, default excitation.
  const Case heavy = given_case(dir, kArm3Spatial, 3, filled(kArm3Spatial, R"(<inertial pos="0.18 0 0.01" mass="0.9" diaginertia="0.001 0.012 0.012"/>)",
                                       R"(<inertial pos="0.18 0 0.01" mass="0.9" diaginertia="0.001 0.012 0.012"/>
          <body name="payload" pos="0.36 0 0"><inertial pos="0 0 0" mass="1.5" diaginertia="0.002 0.002 0.002"/></body>)"));
  Measurement d = issue_case_size();
  d.bits = 16;
  d.delay_samples = 5;
  const auto h = diagnose_case(heavy, measured(heavy, (dir / "heavy.h5").string(), 12, d));
  EXPECT_TRUE(h["delay"]["named"].get<bool>()) << h["delay"].dump();
  EXPECT_NEAR(h["delay"]["seconds"].get<double>(), 0.005, 0.001) << h["delay"].dump();
}

// A twenty-seventh review's 4-joint arm: a yaw, two pitch joints and a roll at the wrist.
const char* kArm4Chirped = R"(<mujoco model="arm4">
 <compiler angle="radian" inertiafromgeom="false"/>
 <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
 <worldbody>
  <body name="base" pos="0 0 0">
   <joint name="j1" type="hinge" axis="0 0 1" armature="0.25" damping="1.8"/>
   <inertial pos="0.02 0 0.12" mass="4.1" diaginertia="0.07 0.06 0.035"/>
   <body name="upper" pos="0 0 0.28">
    <joint name="j2" type="hinge" axis="0 1 0" armature="0.18" damping="1.2"/>
    <inertial pos="0.18 0.01 0" mass="2.7" diaginertia="0.006 0.038 0.04"/>
    <body name="fore" pos="0.36 0 0">
     <joint name="j3" type="hinge" axis="0 1 0" armature="0.09" damping="0.7"/>
     <inertial pos="0.14 0 0.01" mass="1.3" diaginertia="0.002 0.012 0.013"/>
     <body name="wrist" pos="0.3 0 0">
      <joint name="j4" type="hinge" axis="1 0 0" armature="0.03" damping="0.25"/>
      <inertial pos="0.04 0.02 0.0" mass="0.6" diaginertia="0.0015 0.001 0.0012"/>
     </body>
    </body>
   </body>
  </body>
 </worldbody>
</mujoco>
)";

// Coarse encoders' errors in the columns pull the delay search's least-squares minimum: a
// twenty-sixth review's 12-bit logs of this arm read -3.6 to -7.9 ms with no delay, and a real
// 5 ms delay -3.1 ms, not named, with `parameters` beside the exact model. The search now runs
// below a band of its own where the errors' torques are small (delay.cc, search_band): the
// clean log reads the logger's half tick, the delay is named within 1 ms with nothing beside it.
TEST(DiagnoseBeyond, CoarseEncodersDoNotPullTheDelay) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("coarse_delay");
  const Case c = given_case(dir, kArm3Spatial, 3);
  Measurement m = issue_case_size();
  m.bits = 12;
  const auto [clean, late] = on_time_and_late(c, dir, "arm3", 5, m, 5);
  EXPECT_FALSE(clean["delay"]["named"].get<bool>()) << clean["delay"].dump();
  EXPECT_NEAR(clean["delay"]["seconds"].get<double>(), 0, 0.001) << clean["delay"].dump();
  EXPECT_LT(clean["delay"]["band_hz"].get<double>(), m.lowpass_hz) << clean["delay"].dump();
  EXPECT_TRUE(named(clean).empty()) << joined(named(clean));
  EXPECT_TRUE(late["delay"]["named"].get<bool>()) << late["delay"].dump();
  EXPECT_NEAR(late["delay"]["seconds"].get<double>(), 0.005, 0.001) << late["delay"].dump();
  EXPECT_EQ(named(late), std::vector<std::string>{"delay"}) << joined(named(late));
  // A twenty-seventh review's 4-joint arm under a chirp: the delay, found at 4.54 ms, was given
  // up by the comparison with the causes chosen on the data as measured (fitted over the whole
  // band, scored below the search's) and `parameters` written on the exact model, 2.67 % held
  // out where the correction leaves 1.74 and the log without the delay 1.73.
  std::filesystem::create_directories(dir / "arm4");
  const Case arm4 = given_case(dir / "arm4", kArm4Chirped, 4);
  Measurement ch = issue_case_size();
  ch.bits = 12;
  ch.kind = "chirp";
  const auto [on_time, chirp] = on_time_and_late(arm4, dir, "chirp", 1, ch, 5);
  EXPECT_TRUE(named(on_time).empty()) << joined(named(on_time));
  EXPECT_TRUE(chirp["delay"]["named"].get<bool>()) << chirp["delay"].dump();
  EXPECT_NEAR(chirp["delay"]["seconds"].get<double>(), 0.005, 0.001) << chirp["delay"].dump();
  EXPECT_EQ(named(chirp), std::vector<std::string>{"delay"}) << joined(named(chirp));
  EXPECT_LE(chirp["final"]["rel_error_test_all"].get<double>(), 1.05 * on_time["final"]["rel_error_test_all"].get<double>());
}

// A vertical slide that carries most of the torque beside two light hinges (a twenty-eighth
// review's): the pooled held-out sum weighs the joints by their torques, and the gain a delay
// makes on the hinges was below a tenth of it - a 4 ms delay was lost at every bit depth and
// `parameters` (each damping 4-5 % high) named in its place. The delay's held-out test now also
// asks one noise variance per joint, as the base parameters' does.
const char* kSlideAndHinges = R"(<mujoco model="slide3">
 <compiler angle="radian" inertiafromgeom="false"/>
 <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
 <worldbody>
  <body name="car">
   <joint name="z" type="slide" axis="0 0 1" armature="5" damping="20"/>
   <inertial pos="0 0 0" mass="6" diaginertia="0.1 0.1 0.1"/>
   <body name="u" pos="0 0 0.1">
    <joint name="y" type="hinge" axis="0 0 1" armature="0.4" damping="1"/>
    <inertial pos="0.15 0 0" mass="2" diaginertia="0.005 0.02 0.02"/>
    <body name="f" pos="0.3 0 0">
     <joint name="p" type="hinge" axis="0 1 0" armature="0.3" damping="0.7"/>
     <inertial pos="0.1 0 0" mass="0.8" diaginertia="0.001 0.006 0.006"/>
    </body>
   </body>
  </body>
 </worldbody>
</mujoco>
)";

TEST(DiagnoseBeyond, ADelayOnLightJointsBesideAHeavySlideIsNamed) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("slide_delay");
  const Case c = given_case(dir, kSlideAndHinges, 3);
  Measurement m = issue_case_size();
  m.bits = 12;
  m.excitation_seed = 3;   // the review's draw (spml generate --seed 3)
  const auto [on_time, late] = on_time_and_late(c, dir, "slide", 3, m, 4);
  EXPECT_TRUE(named(on_time).empty()) << joined(named(on_time));
  EXPECT_TRUE(late["delay"]["named"].get<bool>()) << late["delay"].dump();
  EXPECT_NEAR(late["delay"]["seconds"].get<double>(), 0.0035, 0.001) << late["delay"].dump();   // 4 ticks less the half tick
  EXPECT_EQ(named(late), std::vector<std::string>{"delay"}) << joined(named(late));
  for (const std::string j : {"y", "p"})
    EXPECT_LE(late["final"]["rel_error_test"][j].get<double>(), 1.05 * on_time["final"]["rel_error_test"][j].get<double>()) << j;
}

// Fast moves: three small sines of 3-8 Hz on each joint (at most two), faded in over the first
// second, 30 s at 1 kHz, as a reference CSV in dir (returned).
std::string fast_moves(const std::filesystem::path& dir, const std::vector<std::string>& joints) {
  const auto reference = (dir / "fast.csv").string();
  std::ofstream f(reference);
  f << "t";
  for (const auto& j : joints) f << ",q:" << j;
  f << "\n";
  const double hz[2][3] = {{3.3, 5.1, 7.7}, {4.2, 6.3, 7.1}}, phase[2][3] = {{0.4, 2.9, 5.1}, {1.7, 3.8, 0.2}};
  for (int i = 0; i <= 30000; ++i) {
    const double t = 1e-3 * i, fade = std::min(1.0, t);
    f << t;
    for (size_t j = 0; j < joints.size() && j < 2; ++j) {
      double q = 0;
      for (int k = 0; k < 3; ++k) q += 0.05 * std::sin(2 * M_PI * hz[j][k] * t + phase[j][k]);
      f << "," << fade * q;
    }
    f << "\n";
  }
  return reference;
}

// The exact hinge the fast moves are measured on (0.22 kg m^2 about its axis, DAMPING to fill).
const char* kFastHinge = R"(<mujoco model="hinge">
 <compiler angle="radian" inertiafromgeom="false"/>
 <option timestep="0.001" gravity="0 0 0"><flag contact="disable"/></option>
 <worldbody>
  <body name="l1">
   <joint name="a" type="hinge" axis="0 0 1" armature="0.1" damping="DAMPING"/>
   <inertial pos="0.2 0 0" mass="2" diaginertia="0.004 0.04 0.04"/>
  </body>
 </worldbody>
</mujoco>
)";

// A delay's correction resamples the torques at t + d; at each record's end the last rows have
// no torque logged that late. Held there, a twenty-eighth review's fast moves (3-8 Hz, rows at
// 200 Hz) had the test split's last row 9.4 N m off, 37 % of its joint's held-out sum of
// squares: the delay was read to 1 us, yet the written model read 0.829 % held out where the log
// without the delay reads 0.697. Now the rows past an end extrapolate the torques where that
// predicts the record's own last samples better than holding does.
TEST(DiagnoseBeyond, ADelayCorrectionKeepsTheRecordsEnds) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("delay_ends");
  const Case c = given_case(dir, R"(<mujoco model="planar2v">
 <compiler angle="radian" inertiafromgeom="false"/>
 <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
 <worldbody>
  <body name="l1" pos="0 0 0.5">
   <joint name="s" type="hinge" axis="0 1 0" armature="0.2" damping="1.5"/>
   <inertial pos="0.2 0 0" mass="2.5" diaginertia="0.004 0.04 0.04"/>
   <body name="l2" pos="0.4 0 0">
    <joint name="e" type="hinge" axis="0 1 0" armature="0.1" damping="0.8"/>
    <inertial pos="0.18 0 0" mass="1.2" diaginertia="0.002 0.015 0.015"/>
   </body>
  </body>
 </worldbody>
</mujoco>
)", 2);
  Measurement m = issue_case_size();
  m.bits = 12;
  m.reference = fast_moves(dir, {"s", "e"});
  // 6 ticks, 5.6 ms: the last rows lie up to 1.1 samples past the end.
  const auto [on_time, late] = on_time_and_late(c, dir, "fast", 1, m, 6);
  // (On these fast moves the exact model's shoulder inertia sum read 1 % high, 5 standard
  // errors, with or without the delay, and `parameters` was named until stop 61 took the
  // processing chain's own bias out (TheChainsOwnBiasIsTakenOutOfTheBaseParameters); the
  // rollouts rejected it. What extended.xml holds is the test.)
  EXPECT_TRUE(written(on_time).empty()) << joined(named(on_time));
  EXPECT_EQ(written(late), std::vector<std::string>{"delay"}) << joined(named(late));
  for (const std::string j : {"s", "e"})
    EXPECT_LE(late["final"]["rel_error_test"][j].get<double>(), 1.02 * on_time["final"]["rel_error_test"][j].get<double>()) << j;
}

// A split's ends hold no start-up transient of the parallel filter's second pass. A recorded
// low-pass filtered the torques once over the whole log; the model's columns of each split go
// through it again on their own, and started on an odd reflection they rang at the split's
// ends (3-8 Hz moves through a 20 Hz import: the last 50 rows of an exact hinge's test split
// 0.22 N m off where the rest lay within 0.04, three quarters of the held-out error). The
// model is exact, so its residual is the noise and the processing's floor, the same at the
// ends as between them.
TEST(DiagnoseBeyond, TheSplitsEndsHoldNoTransientOfTheSecondPass) {
  const auto dir = test::temp_dir("second_pass_ends");
  const Case c = given_case(dir, filled(kFastHinge, "DAMPING", "0.3"), 1);
  Measurement m = issue_case_size();
  m.bits = 16;
  m.reference = fast_moves(dir, {"a"});
  DiagnoseOptions opt;
  opt.model = c.user;
  opt.data = measured(c, (dir / "fast.h5").string(), 1, m);
  opt.rollouts = 0;
  const auto out = dir / "out";
  diagnose(opt, out.string());
  const CsvText series = read_csv((out / "series.csv").string());
  const int split = series.column("split"), tau = series.column("tau:a"), given = series.column("given:a");
  ASSERT_GE(std::min({split, tau, given}), 0);
  std::map<std::string, std::vector<double>> residual;
  for (const auto& row : series.rows) residual[row[static_cast<size_t>(split)]].push_back(std::stod(row[static_cast<size_t>(tau)]) - std::stod(row[static_cast<size_t>(given)]));
  auto rms = [](const std::vector<double>& r, size_t from, size_t to) {
    double s = 0;
    for (size_t i = from; i < to; ++i) s += r[i] * r[i];
    return std::sqrt(s / static_cast<double>(to - from));
  };
  constexpr size_t kEnd = 50;
  for (const std::string name : {"fit", "test"}) {
    const auto& r = residual[name];
    ASSERT_GT(r.size(), 4 * kEnd) << name;
    const double body = rms(r, kEnd, r.size() - kEnd), first = rms(r, 0, kEnd), last = rms(r, r.size() - kEnd, r.size());
    std::cout << "  " << name << ": residual RMS " << first << " (first " << kEnd << " rows), " << body << ", " << last << " (last)\n";
    EXPECT_LE(first, 1.5 * body) << name;
    EXPECT_LE(last, 1.5 * body) << name;
  }
}

// The processing chain's own bias is measured and taken out of the base parameters before they
// are tested (chain_bias.cc). Under 3-8 Hz moves through a 20 Hz import the import's nested
// central differences lose (w h)^2 / 3 of the accelerations (0.07 % at the excitation's
// acceleration-weighted mean, 1 kHz), diagnose's second pass and instruments add to it, and an
// exact hinge read its inertia 0.17 % high without noise, 0.12 % at 1 % torque noise: 21
// standard errors, and `parameters` was named on every seed tried (1-4; rejected only in
// simulation). Undamped, the generator's integrator adds nothing of its own (MuJoCo's implicit
// damping reads as h D / 2 more inertia, 0.026 % for the damping of 0.3 here), so what the
// replay leaves of the deviation is what it does not model.
TEST(DiagnoseBeyond, TheChainsOwnBiasIsTakenOutOfTheBaseParameters) {
  const auto dir = test::temp_dir("chain_bias");
  const std::string inertia = "Izz:l1 + armature:a";
  {
    const Case c = given_case(dir, filled(kFastHinge, "DAMPING", "0"), 1);
    Measurement m = issue_case_size();
    m.bits = 0, m.torque_noise = 0;
    m.reference = fast_moves(dir, {"a"});
    const nlohmann::json r = diagnose_case(c, measured(c, (dir / "exact.h5").string(), 1, m), 0);
    const nlohmann::json& b = r["statistics"]["parameters_chain_bias"];
    ASSERT_TRUE(b["applied"].get<bool>()) << b.dump();
    const nlohmann::json& p = b["parameters"][inertia];
    const double model = p["model"].get<double>(), read = p["estimate"].get<double>() - model, left = read - p["chain_bias"].get<double>();
    std::cout << "  undamped, exact: the inertia read " << 100 * read / model << " % off, " << 100 * left / model << " % less the chain's bias\n";
    EXPECT_GT(read, 1e-3 * model);                       // the chain's bias is there to take out
    EXPECT_LE(std::fabs(left), 0.15 * std::fabs(read));  // and the replay measures it
  }
  const Case c = given_case(dir, filled(kFastHinge, "DAMPING", "0.3"), 1);
  Measurement m = issue_case_size();
  m.bits = 16;
  m.reference = fast_moves(dir, {"a"});
  for (unsigned seed : {1u, 2u}) {
    const nlohmann::json r = diagnose_case(c, measured(c, (dir / ("noisy" + std::to_string(seed) + ".h5")).string(), seed, m), 0);
    EXPECT_TRUE(named(r).empty()) << "seed " << seed << ": " << joined(named(r));
  }
  // Through a 10 Hz import the second pass changes these moves so much that the parallel
  // filter decides column by column; the replay's noise-free columns are not decided as the
  // log's are, and it read the inertia 8 % high (1277 standard errors; `parameters` named on
  // this log). There the chain is not replayed, and nothing is named, as before the replay.
  m.lowpass_hz = 10, m.drop_edges = 500;
  const nlohmann::json r = diagnose_case(c, measured(c, (dir / "lowpass10.h5").string(), 1, m), 0);
  EXPECT_GT(r["parallel_filter"]["again_above_hz"].get<double>(), 0);
  EXPECT_FALSE(r["statistics"]["parameters_chain_bias"]["applied"].get<bool>());
  EXPECT_TRUE(named(r).empty()) << joined(named(r));
}

// MuJoCo's frictionloss is a soft constraint whose torque switches with qd + qdd dmax timeconst / 2
// (9.5 ms ahead at the default solref), not with qd as the coulomb column does. Under 3-8 Hz
// moves a frictionloss the model lacked, named `coulomb` and written as its declaration, left
// the hinge's fresh log much of what the model as given had (a review's vertical slide carrying
// a hinge: 0.78 % of the torque, the true model 0.28 %). The written form is the data's choice
// (choose_coulomb_form): here frictionloss, which plain MuJoCo simulates. Judged as a user would,
// on a log of another seed, against the same level written as the declaration. (A hinge alone
// under these moves, 0.22 kg m^2, gets `parameters` and `stick_slip` named instead: README,
// known wrong answers.)
TEST(DiagnoseBeyond, AMissingFrictionlossIsWrittenAsFrictionloss) {
  const auto dir = test::temp_dir("frictionloss_form");
  const std::string given = R"(<mujoco model="vertical slide and hinge">
 <compiler angle="radian" inertiafromgeom="false"/>
 <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
 <worldbody>
  <body name="carriage">
   <joint name="z" type="slide" axis="0 0 1" armature="0.5" damping="5"/>
   <inertial pos="0 0 0" mass="4" diaginertia="0.02 0.02 0.02"/>
   <body name="arm">
    <joint name="a" type="hinge" axis="0 -1 0" armature="0.03" damping="0.3"/>
    <inertial pos="0.15 0 0" mass="1.2" diaginertia="0.002 0.012 0.012"/>
   </body>
  </body>
 </worldbody>
</mujoco>
)";
  const Case c = given_case(dir, given, 2, filled(given, "damping=\"0.3\"", "damping=\"0.3\" frictionloss=\"0.15\""));
  Measurement m = issue_case_size();
  m.bits = 16;
  m.reference = fast_moves(dir, {"z", "a"});
  DiagnoseOptions opt;
  opt.model = c.user;
  opt.data = measured(c, (dir / "fit.h5").string(), 1, m);
  opt.rollouts = 0;
  const auto out = dir / "out";
  const nlohmann::json r = diagnose(opt, out.string()).report;
  const nlohmann::json* coulomb = nullptr;
  for (const auto& cause : r["causes"])
    if (cause["effect"] == "coulomb" && !cause.contains("superseded_by") && !cause.contains("rejected")) coulomb = &cause;
  ASSERT_NE(coulomb, nullptr) << joined(named(r));
  EXPECT_EQ(coulomb->value("written_as", ""), "mjcf") << coulomb->dump();
  ASSERT_TRUE(coulomb->contains("written_form_check")) << coulomb->dump();
  const nlohmann::json& check = (*coulomb)["written_form_check"];
  EXPECT_TRUE(check["frictionloss"].get<bool>()) << check.dump();
  EXPECT_TRUE(r["needs_spml_plugins"].empty()) << r["needs_spml_plugins"].dump();
  const std::string written_xml = (out / "extended.xml").string();
  ModelPtr w = load_mjcf(written_xml);
  const double level = w->dof_frictionloss[w->jnt_dofadr[mj_name2id(w.get(), mjOBJ_JOINT, "a")]];
  EXPECT_NEAR(level, 0.15, 0.3 * 0.15);   // the ideal column's fit reads it low: the soft zone
  // The same level as the declaration, for the comparison.
  const std::string declared_xml = (dir / "declared.xml").string();
  {
    std::string text = test::read_file(written_xml);
    const std::string attr = " frictionloss=\"";
    const auto at = text.find(attr);
    ASSERT_NE(at, std::string::npos);
    text.erase(at, text.find('"', at + attr.size()) + 1 - at);
    std::ofstream(declared_xml) << test::with_declarations(text, {"type=coulomb joints=a fc=" + test::num(level) + " smooth=0"});
  }
  const std::string fresh = measured(c, (dir / "fresh.h5").string(), 2, m);
  auto held_out = [&](const std::string& model) {
    DiagnoseOptions o;
    o.model = model;
    o.data = fresh;
    o.rollouts = 0;
    return diagnose(o, "").report["baseline"]["rel_error_test"]["a"].get<double>();
  };
  const double as_frictionloss = held_out(written_xml), as_declared = held_out(declared_xml), true_model = held_out(c.truth);
  std::cout << "  fresh log, the hinge's held-out error: written " << 100 * as_frictionloss << " %, the level as a declaration "
            << 100 * as_declared << " %, the true model " << 100 * true_model << " % (level " << level << " for 0.15)\n";
  EXPECT_LT(as_frictionloss, as_declared);
  EXPECT_LE(as_frictionloss, 1.5 * true_model);
}

// An effect outside the vocabulary that the vocabulary takes most of is said to be so. A
// nineteenth review's tendon spring from the world to the forearm of the 5-joint arm was read
// as `parameters` (the upper arm written 12.45 kg for 4) and a spring on the base; they took
// seven times what a GP over the states still predicted, under the third that marked a nearest
// candidate, and nothing said that the written inertials are a fit, not the arm's: the written
// model still left 9-11 % of the base's and shoulder's torque, 90 % of it predicted.
TEST(DiagnoseBeyond, ATendonTheVocabularyTakesMostOfIsMarkedNearest) {
  const auto dir = test::temp_dir("tendon");
  std::string arm = filled(kArm5, "ARMATURE", "0.002");
  Case c;
  c.joints = 5;
  c.user = (dir / "given.xml").string();
  c.truth = (dir / "tendon.xml").string();
  std::ofstream(c.user) << arm;
  arm = filled(arm, R"(<inertial pos="0.15 0 0" mass="2")", R"(<site name="fs" pos="0.15 0 0"/><inertial pos="0.15 0 0" mass="2")");
  std::ofstream(c.truth) << filled(arm, "</worldbody>", R"(<site name="anchor" pos="0.5 0.3 0.6"/></worldbody>
  <tendon><spatial stiffness="60" springlength="0.2"><site site="anchor"/><site site="fs"/></spatial></tendon>)");
  const auto r = diagnose_case(c, measured(c, (dir / "tendon.h5").string(), 11, issue_case_size()), 20);
  EXPECT_EQ(r["rollout"]["worse_on"].size(), 0u) << r["rollout"].dump();
  // Each kept cause on a joint the written model leaves 5 % or more of its torque, most of it
  // structure, is marked; and that joint is unexplained through a position.
  size_t kept = 0;
  for (const auto& cause : r["causes"]) {
    if (cause.contains("superseded_by") || cause.contains("rejected") || cause["effect"] == "delay") continue;
    ++kept;
    EXPECT_TRUE(cause.contains("nearest_candidate")) << cause.dump();
  }
  EXPECT_GT(kept, 0u) << joined(named(r));
  bool held = false;
  for (const auto& u : r["unexplained"])
    if (u.contains("share") && r["final"]["rel_error_test"][u["joint"].get<std::string>()].get<double>() >= 0.05) {
      held = true;
      EXPECT_EQ(u["inputs"][0].get<std::string>().rfind("q:", 0), 0u) << u.dump();
    }
  EXPECT_TRUE(held) << r["unexplained"].dump();
  // The written model is better than the one as given held out on the joints the tendon moves.
  for (const std::string j : {"J1", "J2", "J3"})
    EXPECT_LT(r["final"]["rmse_test"][j].get<double>(), 0.5 * r["baseline"]["rmse_test"][j].get<double>()) << j;
}

// A torque of the position outside the vocabulary, a sin(2 (q - q_mid)), which a spring takes
// most of near the middle of the stroke (a twenty-first review's 1.2 sin(2 q) on its base
// joint): the spring is named, and what it leaves (about a tenth) is predicted through q: by
// the GP, but at 4-5 times its white noise, under `unexplained`'s noise margin - written as a
// physical spring, said nowhere. Structure through the positions alone is not the measurement
// chain's (at most 0.21 of a clean joint's residual): now the joint is `unexplained` through
// its own position and the spring is marked `nearest_candidate`; no cause rolls out worse.
TEST(DiagnoseBeyond, APositionTorqueASpringTakesMostOfIsUnexplainedThroughItsPosition) {
  const auto dir = test::temp_dir("sine");
  for (const int s : {203, 207}) {
    const Draw d = make_draw(dir, "sine", s, 0, issue_case_size());
    const auto r = run_draw(dir, d, s, 20);
    const std::string joint = "j" + std::to_string(d.joint);
    std::cout << d.what << " on " << joint << ": named " << joined(named(r)) << "\n  unexplained " << r["unexplained"].dump() << "\n";
    bool found = false;
    for (const auto& u : r["unexplained"])
      if (u["joint"] == joint) {
        found = true;
        EXPECT_EQ(u["inputs"][0], "q:" + joint);
        EXPECT_GE(u["share_through_positions"].get<double>(), 0.4);
      }
    EXPECT_TRUE(found) << r["unexplained"].dump();
    EXPECT_TRUE(r["rollout"]["worse_on"].empty()) << r["rollout"].dump();
    for (const auto& cause : r["causes"]) {
      if (cause.contains("superseded_by") || cause.contains("rejected") || cause["effect"] == "delay") continue;
      EXPECT_TRUE(cause.contains("nearest_candidate")) << cause.dump();
    }
    EXPECT_LT(r["final"]["rmse_test"][joint].get<double>(), 0.2 * r["baseline"]["rmse_test"][joint].get<double>());
  }
}

// A joint limit the motion reaches briefly (MuJoCo's own, in the true model; the model as given
// has none): its force lies in the few percent of rows past it, too few and too steep for the
// GP, and a twenty-first review's limits reached in 3 and 7 % of the rows were `left_unexplained`
// with "a load, a command, a temperature" said first. The residual's energy is now located at
// that end of the joint's travel, on its position.
TEST(DiagnoseBeyond, AJointLimitReachedBrieflyIsSaidToLieAtAnEnd) {
  const auto dir = test::temp_dir("limit");
  const std::string arm = filled(kArm5, "ARMATURE", "0.002");
  Case c;
  c.joints = 5;
  c.user = (dir / "given.xml").string();
  c.truth = (dir / "limit.xml").string();
  std::ofstream(c.user) << arm;
  Measurement m = issue_case_size();
  // The motion of the model as given is the reference the limited robot tracks: an excitation
  // planned for the limited model would stay within its range.
  MeasurementOptions probe;
  probe.duration = m.duration;
  probe.torque_noise = 0;
  probe.seed = 11;
  probe.excitation.seed = 11 + 17;
  const MeasuredRun free = simulate_measured(c.user, probe);
  m.reference = (dir / "reference.csv").string();
  {
    std::ofstream ref(m.reference);
    ref.precision(12);
    ref << "t";
    for (const auto& j : free.joints) ref << ",q:" << j;
    ref << "\n";
    for (Eigen::Index i = 0; i < free.tick_qpos.rows(); ++i) {
      ref << static_cast<double>(i) / 1000;
      for (Eigen::Index k = 0; k < free.tick_qpos.cols(); ++k) ref << "," << free.tick_qpos(i, k);
      ref << "\n";
    }
  }
  const Eigen::VectorXd q = free.tick_qpos.col(2);
  std::vector<double> sorted(q.data(), q.data() + q.size());
  std::sort(sorted.begin(), sorted.end());
  const double low = sorted[sorted.size() / 20];   // past it 5 % of the time
  const std::string elbow = R"(<joint name="J3" type="hinge" axis="0 1 0")";
  std::ofstream(c.truth) << filled(arm, elbow, elbow + R"( limited="true" range=")" + test::num(low) + R"( 10")");
  const auto r = diagnose_case(c, measured(c, (dir / "limit.h5").string(), 11, m), 20);
  std::cout << "limit at " << low << ": named " << joined(named(r)) << "\n";
  // Said on the elbow, in `unexplained` (the GP predicts part of it) or `left_unexplained`, and
  // only there.
  int said = 0;
  for (const auto& list : {r["unexplained"], r["left_unexplained"]})
    for (const auto& e : list) {
      EXPECT_EQ(e["joint"], "J3") << e.dump();
      if (e["joint"] != "J3" || !e.contains("at_an_end")) continue;
      ++said;
      EXPECT_EQ(e["at_an_end"]["input"], "q:J3");
      EXPECT_EQ(e["at_an_end"]["end"], "lower");
      EXPECT_NEAR(e["at_an_end"]["beyond"].get<double>(), low, 0.05);
      EXPECT_GE(e["at_an_end"]["energy"].get<double>(), 0.5);
    }
  EXPECT_EQ(said, 1) << r["left_unexplained"].dump() << r["unexplained"].dump();
}

// The held-out gain of `parameters` per joint is judged with the free fit weighted by the
// joints' noise too. A twentieth review's 6-joint arm (a slide among its hinges; its last joint
// 1/830 of the base's torque) with that joint's damping twice the MJCF's: the evidence passed
// (Delta BIC 1287) and the damping was contradicted, but the unweighted free fit left the light
// joint the heavy ones' misfit, its held-out gain failed, and nothing was named (44.6 % of the
// joint's held-out torque left). Now the damping is named and written alone.
const char* kArm6 = R"(<mujoco model="arm6">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <worldbody>
    <body name="base" pos="0 0 0.3">
      <joint name="J1" type="hinge" axis="0 0 1" armature="0.5" damping="2.0"/>
      <inertial pos="0 0 0.1" mass="8" diaginertia="0.12 0.12 0.08"/>
      <body name="l2" pos="0 0 0.2">
        <joint name="J2" type="hinge" axis="0 1 0" armature="0.4" damping="1.5"/>
        <inertial pos="0.2 0 0" mass="5" diaginertia="0.02 0.09 0.09"/>
        <body name="l3" pos="0.4 0 0">
          <joint name="J3" type="hinge" axis="0 1 0" armature="0.2" damping="0.8"/>
          <inertial pos="0.15 0 0" mass="2.5" diaginertia="0.008 0.03 0.03"/>
          <body name="l4" pos="0.3 0 0">
            <joint name="J4" type="slide" axis="1 0 0" armature="0.3" damping="5.0"/>
            <inertial pos="0.05 0 0" mass="1.0" diaginertia="0.002 0.004 0.004"/>
            <body name="l5" pos="0.1 0 0">
              <joint name="J5" type="hinge" axis="1 0 0" armature="0.002" damping="0.01"/>
              <inertial pos="0.02 0 0.01" mass="0.15" diaginertia="0.00015 0.0002 0.0002"/>
              <body name="l6" pos="0.04 0 0">
                <joint name="J6" type="hinge" axis="0 0 1" armature="0.0005" damping="DAMPING"/>
                <inertial pos="0.015 0.005 0" mass="0.05" diaginertia="0.00002 0.00003 0.00003"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";

TEST(DiagnoseBeyond, ALightJointsGainIsJudgedWithItsOwnNoise) {
  const auto dir = test::temp_dir("light6");
  Case c;
  c.joints = 6;
  c.user = (dir / "given.xml").string();
  c.truth = (dir / "true.xml").string();
  std::ofstream(c.user) << filled(kArm6, "DAMPING", "0.003");
  std::ofstream(c.truth) << filled(kArm6, "DAMPING", "0.006");
  const auto r = diagnose_case(c, measured(c, (dir / "arm6.h5").string(), 1, issue_case_size()), 0);
  ASSERT_EQ(joined(named(r)), "parameters") << r["statistics"].dump();
  const auto& p = r["causes"][0]["params"];
  ASSERT_TRUE(p.contains("damping:J6")) << p.dump();
  EXPECT_NEAR(p["damping:J6"].get<double>(), 0.006, 0.05 * 0.006);
  EXPECT_EQ(r["parameters_written"], "listed");
  EXPECT_LT(r["final"]["rmse_test"]["J6"].get<double>(), 0.05 * r["baseline"]["rmse_test"]["J6"].get<double>());
}

// A joint no cause touches keeps its held-out torque. An eighteenth review's gantry (a 6 kg
// slide, two hinges, a 0.25 kg wrist about its own axis) with a weak cable (a spatial tendon
// with a spring, outside the vocabulary) from the world to the second link: `parameters` was
// written with the hand's mass 0.078 kg, and the wrist, whose torque is a thousandth of the
// slide's, predicted its held-out torque 6.8 times worse (RMS, 0.22 -> 1.46 %), inside a
// geometric mean over the joints of 0.5. The written fit weighted each joint by its residual in
// the unweighted free fit, where the wrist held the large joints' misfit (700 times its noise);
// now by the smaller of that and its residual with the MJCF's own parameters. The held-out
// guard also refuses a written model with one joint's RMS twice its own as given.
const char* kGantry = R"(<mujoco model="gantry">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="0.001" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <default><joint type="hinge" armature="0.05" damping="0.4"/><geom type="capsule" size="0.02" contype="0" conaffinity="0"/></default>
  <worldbody>
    <site name="anchor" pos="0.3 0 1.3"/>
    <body name="carriage" pos="0 0 0.5">
      <joint name="rail" type="slide" axis="1 0 0" armature="2.0" damping="8"/>
      <inertial pos="0 0 0" mass="6.0" diaginertia="0.05 0.05 0.05"/>
      <body name="link1" pos="0 0 0.05">
        <joint name="lift" axis="0 1 0" armature="0.12" damping="0.9"/>
        <inertial pos="0.15 0 0.01" mass="1.8" diaginertia="0.002 0.018 0.017"/>
        <body name="link2" pos="0.3 0 0">
          <joint name="bend" axis="0 1 0" armature="0.04" damping="0.3"/>
          <inertial pos="0.11 0 0" mass="0.7" diaginertia="0.0006 0.004 0.0038"/>
          <site name="s2" pos="0.2 0 0.02"/>
          <body name="hand" pos="0.22 0 0">
            <joint name="roll" axis="1 0 0" armature="0.002" damping="0.01"/>
            <inertial pos="0.02 0.015 0" mass="0.25" diaginertia="0.0002 0.00015 0.00015"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  CABLE
</mujoco>
)";

TEST(DiagnoseBeyond, AJointNoCauseListsKeepsItsHeldOutTorque) {
  const auto dir = test::temp_dir("cable");
  auto model = [](const std::string& cable) { return filled(kGantry, "CABLE", cable); };
  Case c;
  c.joints = 4;
  c.user = (dir / "given.xml").string();
  c.truth = (dir / "cable.xml").string();
  std::ofstream(c.user) << model("");
  std::ofstream(c.truth) << model(R"(<tendon><spatial name="cable" stiffness="8" springlength="0.6"><site site="anchor"/><site site="s2"/></spatial></tendon>)");
  const auto r = diagnose_case(c, measured(c, (dir / "cable.h5").string(), 62, issue_case_size()), 20);
  // Every joint no kept cause lists (the wrist: the cable does not reach it) within 1.25 times
  // its RMS as given; and none, listed or not, past the guard's bar of 2.
  std::set<std::string> listed;
  for (const auto& cause : r["causes"])
    if (!cause.contains("superseded_by") && !cause.contains("rejected"))
      for (const auto& j : cause["joints"]) listed.insert(j.get<std::string>());
  for (const auto& [j, given] : r["baseline"]["rmse_test"].items()) {
    const double ratio = r["final"]["rmse_test"][j].get<double>() / given.get<double>();
    EXPECT_LE(ratio, listed.count(j) ? 2.0 : 1.25) << j << ": named " << joined(named(r));
  }
  EXPECT_FALSE(listed.count("roll")) << joined(named(r));
  // The cable is outside the vocabulary: on the bend joint it leaves structure, said.
  bool bend = false;
  for (const auto& u : r["unexplained"]) bend |= u["joint"] == "bend";
  EXPECT_TRUE(bend) << r["unexplained"].dump();
}

// A probe over seeds, for the tables of the issue (not run by ctest: --gtest_also_run_disabled_tests).
// SPML_BEYOND_KIND: a kind of make_draw; SPML_BEYOND_FIRST, SPML_BEYOND_SEEDS: the seeds;
// SPML_BEYOND_DELAY_MS; SPML_BEYOND_NOISE (torque noise fraction); SPML_BEYOND_BITS;
// SPML_BEYOND_LOWPASS (the import's low-pass in Hz, default 10; 0: raw differences);
// SPML_BEYOND_FHIGH (the excitation's top frequency); SPML_BEYOND_DROP (samples dropped at each
// end after the low-pass, default 200; the import asks 612 for its 10 Hz pass at 1 kHz where
// the log ends moving, as these do); SPML_BEYOND_DECIMATE (default 5; 1 keeps the 1 kHz log);
// SPML_BEYOND_DURATION (seconds, default 10); SPML_BEYOND_TRUE_DAMPING (the drawn
// joint's true damping, the model's staying 0.5); SPML_BEYOND_SIGMA0_SCALE (LuGre's bristle
// stiffness times this).
TEST(DiagnoseBeyond, DISABLED_SeedTable) {
  auto env = [](const char* k, const char* d) { const char* v = std::getenv(k); return std::string(v ? v : d); };
  const std::string kind = env("SPML_BEYOND_KIND", "clean");
  const int seeds = std::stoi(env("SPML_BEYOND_SEEDS", "5")), first = std::stoi(env("SPML_BEYOND_FIRST", "0"));
  const auto dir = test::temp_dir("table");
  for (int s = first; s < first + seeds; ++s) {
    Measurement m = noise_level(std::stod(env("SPML_BEYOND_NOISE", "0.01")), std::stoi(env("SPML_BEYOND_BITS", "18")));
    m.lowpass_hz = std::stod(env("SPML_BEYOND_LOWPASS", "10"));
    m.f_high = std::stod(env("SPML_BEYOND_FHIGH", "0"));
    m.drop_edges = std::stoi(env("SPML_BEYOND_DROP", "200"));
    m.decimate = std::stoi(env("SPML_BEYOND_DECIMATE", "5"));
    m.duration = std::stod(env("SPML_BEYOND_DURATION", "10"));
    Draw d = make_draw(dir, kind, s, std::stod(env("SPML_BEYOND_DELAY_MS", "5")), m, std::stod(env("SPML_BEYOND_SIGMA0_SCALE", "1")));
    if (const std::string damping = env("SPML_BEYOND_TRUE_DAMPING", ""); !damping.empty()) with_true_damping(d, damping);
    const auto r = run_draw(dir, d, s);
    std::cout << "TABLE " << kind << " seed " << s << " joint j" << d.joint << " other j" << d.other << " (" << d.what << "): delay "
              << 1e3 * r["delay"]["seconds"].get<double>() << " ± " << 1e3 * r["delay"]["stderr"].get<double>() << " ms named "
              << r["delay"]["named"] << "; causes " << joined(named(r)) << "\n   delay: " << r["delay"]["why"].get<std::string>() << "\n";
    for (const auto& cause : r["causes"])
      std::cout << "   cause " << cause["effect"] << " " << cause["joints"].dump() << " " << cause.value("params", nlohmann::json()).dump()
                << (cause.contains("superseded_by") ? " superseded" : "") << (cause.contains("rejected") ? " REJECTED (" + cause["rejected"].value("summary", std::string("in simulation")) + ")" : std::string())
                << (cause.contains("not_identifiable") ? " not identifiable " + cause["not_identifiable"].dump() : "")
                << (cause.contains("nearest_candidate") ? " NEAREST on " + cause["nearest_candidate"]["joint"].get<std::string>() : "")
                << (cause.contains("resolution") ? "\n     resolution: " + cause["resolution"].get<std::string>() : "") << "\n";
    for (const auto& u : r["unexplained"])
      std::cout << "   unexplained " << u["joint"] << " top " << u["inputs"][0] << " share " << u["share"] << " explained_rmse "
                << std::sqrt(std::pow(u["rmse_test"].get<double>(), 2) - std::pow(u["rmse_test_with_gp"].get<double>(), 2)) << " noise_rmse " << u["noise_rmse"]
                << (u.contains("at_an_end") ? " AT_AN_END " + u["at_an_end"].dump() : "") << "\n";
    for (const auto& t : r["not_tried"])
      if (t.value("joint", "") == "j" + std::to_string(d.joint) && t.value("effect", "") == "stick_slip")
        std::cout << "   not tried " << t["reason"] << (t.contains("resolution") ? "\n     resolution: " + t["resolution"].get<std::string>() : "") << "\n";
    if (!r["left_unexplained"].empty()) std::cout << "   left_unexplained " << r["left_unexplained"].dump() << "\n";
    std::cout << "   rollout worse_on " << r["rollout"]["worse_on"].dump() << "; held-out relative error on j" << d.joint << " "
              << r["baseline"]["rel_error_test"]["j" + std::to_string(d.joint)] << " as given, " << r["final"]["rel_error_test"]["j" + std::to_string(d.joint)] << " written\n";
    double held = 0, roll = 0;   // geometric means over the joints of written / as given
    int joints = 0;
    for (const auto& [j, given] : r["baseline"]["rel_error_test"].items()) {
      held += std::log(r["final"]["rel_error_test"][j].get<double>() / given.get<double>());
      if (r["rollout"].contains("position_error_after"))
        roll += std::log(r["rollout"]["position_error_after"][j].get<double>() / r["rollout"]["position_error_before"][j].get<double>());
      ++joints;
    }
    std::cout << "   every joint, written / as given (geometric mean): held-out " << std::exp(held / joints) << ", rollouts " << std::exp(roll / joints) << "\n";
  }
}

}  // namespace
}  // namespace spml

// Issue #20 item 6, MuJoCo's own physics where it exists: a hidden spring and hidden viscous
// friction, held in the true model as MuJoCo's own joint attributes (stiffness/springref,
// damping; the data are MuJoCo's physics, no plugin), measured like a real log (PD forward
// simulation, 1 % torque noise, 18-bit encoders, `import --lowpass 10 --derive`, 200 Hz).
// extended.xml must state them in the same terms, without a plugin text.

namespace spml {
namespace {

// The chain's joint `joint` with `attributes` added to its <joint> element (random_chain writes
// each joint on one line, armature 0.05 and damping 0.5).
std::string with_joint_attributes(std::string xml, int joint, const std::string& attributes) {
  const std::string tag = "name=\"j" + std::to_string(joint) + "\" type=\"hinge\"";
  const auto at = xml.find(tag);
  EXPECT_NE(at, std::string::npos);
  return xml.insert(at + tag.size(), " " + attributes);
}

struct Native {
  Case c;
  int joint = 0;
  double rms_tau = 0, rms_q = 0, rms_qd = 0;   // of the joint along the excitation (model as given)
};

// A random 3-joint chain; the true model is the chain with `attributes(native)` on joint `joint`.
Native make_native(const std::filesystem::path& dir, const std::string& tag, unsigned seed, int joint,
                   const std::function<std::string(const Native&)>& attributes) {
  Native n;
  n.joint = joint;
  n.c = make_case(dir, tag, seed, "", joint);
  MeasurementOptions probe;
  probe.duration = 10;
  probe.torque_noise = 0;
  probe.seed = seed;
  probe.excitation.seed = seed + 17;
  const MeasuredRun run = simulate_measured(n.c.user, probe);
  n.rms_tau = run.rms[joint];
  n.rms_q = std::sqrt(run.tick_qpos.col(joint).squaredNorm() / static_cast<double>(run.tick_qpos.rows()));
  n.rms_qd = std::sqrt(run.tick_qvel.col(joint).squaredNorm() / static_cast<double>(run.tick_qvel.rows()));
  if (attributes) std::ofstream(n.c.truth) << with_joint_attributes(test::read_file(n.c.user), joint, attributes(n));
  return n;
}

nlohmann::json diagnose_into(const Native& n, const std::string& data, const std::filesystem::path& out) {
  DiagnoseOptions opt;
  opt.model = n.c.user;
  opt.data = data;
  opt.rollouts = 5;
  return diagnose(opt, out.string()).report;
}

bool declares(const nlohmann::json& r, const std::string& effect) {
  for (const auto& name : r["needs_spml_plugins"])
    if (name.get<std::string>().find("diagnosed_" + effect + "_") != std::string::npos) return true;
  return false;
}

// A spring of stiffness k (its force along the motion 10 % of the joint's RMS torque) about a
// rest position r of 0.2-0.4 rad either side of the trajectory's centre: `spring` named on that
// joint and written as MuJoCo's stiffness (within 10 %) and springref. The springref tolerance:
// springref = f0/k with the force -k q + f0, so dr = (df0 - r dk)/k. With dk within the 10 % the
// stiffness is held to, and the constant part f0 determined as well as the spring's force along
// the motion - df0 within 10 % of its RMS k*RMS(q - r) -, |dr| <= 0.1 (RMS(q - r) + |r|).
TEST(DiagnoseNative, SpringIsWrittenAsMuJoCosStiffnessAndSpringref) {
  const auto dir = test::temp_dir("native_spring");
  for (unsigned s = 0; s < 2; ++s) {
    std::mt19937_64 rng(0x5b1a9u + s);
    const int joint = static_cast<int>((rng() + s) % 3);
    const double r = (rng() % 2 ? 1 : -1) * std::uniform_real_distribution<double>(0.2, 0.4)(rng);
    double k = 0;
    const Native n = make_native(dir, "s" + std::to_string(s), 0x5b1a0u + s, joint, [&](const Native& p) {
      k = 0.1 * p.rms_tau / std::sqrt(p.rms_q * p.rms_q + r * r);   // RMS of k (q - r): 10 % of the joint's torque
      return "stiffness=\"" + test::num(k) + "\" springref=\"" + test::num(r * 180 / M_PI) + "\"";   // degrees: MuJoCo's default
    });
    const auto out = dir / ("out" + std::to_string(s));
    const auto r_json = diagnose_into(n, measured(n.c, (dir / ("s" + std::to_string(s) + ".h5")).string(), 90 + s), out);
    const auto causes = named(r_json);
    const std::string jn = "j" + std::to_string(joint);
    std::cout << "spring on " << jn << " (k " << k << ", springref " << r << " rad, rms q " << n.rms_q << "): named " << joined(causes) << "\n";
    ASSERT_NE(std::find(causes.begin(), causes.end(), "spring@" + jn), causes.end()) << joined(causes);
    for (const auto& c : causes) EXPECT_TRUE(c.rfind("spring@", 0) != 0 || c == "spring@" + jn) << joined(causes);
    for (const auto& c : r_json["causes"])
      if (c["effect"] == "spring" && !c.contains("superseded_by")) {
        std::cout << "  params " << c["params"].dump() << " stderr " << c["stderr"].dump() << "\n  written " << c.value("mjcf", nlohmann::json()).dump() << "\n";
        EXPECT_EQ(c.value("written_as", ""), "mjcf") << c.dump();
      }
    EXPECT_FALSE(declares(r_json, "spring")) << r_json["needs_spml_plugins"].dump();
    const std::string text = test::read_file((out / "extended.xml").string());
    EXPECT_EQ(text.find("type=spring"), std::string::npos) << text;
    ModelPtr m = load_mjcf((out / "extended.xml").string());
    const int j = mj_name2id(m.get(), mjOBJ_JOINT, jn.c_str());
    ASSERT_GE(j, 0);
    const double k_written = m->jnt_stiffness[j], r_written = m->qpos_spring[m->jnt_qposadr[j]];
    std::cout << "  extended.xml: stiffness " << k_written << " (true " << k << "), springref " << r_written << " rad (true " << r << ")\n";
    EXPECT_NEAR(k_written, k, 0.1 * k);
    EXPECT_NEAR(r_written, r, 0.1 * (std::sqrt(n.rms_q * n.rms_q + r * r) + std::abs(r)));
    const double before = r_json["baseline"]["rel_error_test_all"], after = r_json["final"]["rel_error_test_all"];
    std::cout << "  held out: " << before << " as given -> " << after << " written; extended_check " << r_json["extended_check"].dump() << "\n";
    EXPECT_LT(after, before);
    // The written file states what the fit predicts (re-identified parameters: the effects are refitted with
    // what is written, and the check is against the joint fit's prediction).
    if (r_json["parameters_written"] == "none") {
      EXPECT_LT(r_json["extended_check"]["max_abs_deviation"].get<double>(), 1e-8 * r_json["extended_check"]["rms_torque"].get<double>());
    }
  }
}

// Viscous friction fv (10 % of the joint's RMS torque along the motion) on top of the MJCF's
// damping 0.5: extended.xml's damping on that joint is 0.5 + fv within 10 % of fv, and no
// viscous plugin text.
TEST(DiagnoseNative, ViscousFrictionIsWrittenAsDamping) {
  const auto dir = test::temp_dir("native_viscous");
  for (unsigned s = 0; s < 2; ++s) {
    const int joint = static_cast<int>((s + 1) % 3);
    double fv = 0;
    const Native n = make_native(dir, "v" + std::to_string(s), 0x7e5c0u + s, joint, [&](const Native& p) {
      fv = 0.1 * p.rms_tau / p.rms_qd;
      return std::string();
    });
    std::string xml = test::read_file(n.c.user);
    const std::string tag = "name=\"j" + std::to_string(joint) + "\"";
    const auto line = xml.find(tag), at = xml.find("damping=\"0.5\"", line);
    ASSERT_NE(at, std::string::npos);
    std::ofstream(n.c.truth) << xml.replace(at, 13, "damping=\"" + test::num(0.5 + fv) + "\"");
    const auto out = dir / ("out" + std::to_string(s));
    const auto r_json = diagnose_into(n, measured(n.c, (dir / ("v" + std::to_string(s) + ".h5")).string(), 110 + s), out);
    const std::string jn = "j" + std::to_string(joint);
    std::cout << "viscous on " << jn << " (fv " << fv << "): named " << joined(named(r_json)) << "\n";
    for (const auto& c : r_json["causes"])
      std::cout << "  " << c["effect"] << " " << c.value("written_as", "-") << " " << c.value("mjcf", nlohmann::json()).dump() << "\n";
    EXPECT_FALSE(declares(r_json, "viscous")) << r_json["needs_spml_plugins"].dump();
    const std::string text = test::read_file((out / "extended.xml").string());
    EXPECT_EQ(text.find("type=viscous"), std::string::npos) << text;
    ModelPtr m = load_mjcf((out / "extended.xml").string());
    const int j = mj_name2id(m.get(), mjOBJ_JOINT, jn.c_str());
    ASSERT_GE(j, 0);
    const double d = m->dof_damping[m->jnt_dofadr[j]];
    std::cout << "  extended.xml damping " << d << " (true " << 0.5 + fv << ")\n";
    EXPECT_NEAR(d - 0.5, fv, 0.1 * fv);
    EXPECT_LT(r_json["final"]["rel_error_test_all"].get<double>(), r_json["baseline"]["rel_error_test_all"].get<double>());
  }
}

// Clean draws (the model as given made the data) and payload draws (2 kg more on the last body:
// its gravity torque, ~sin q, is what a spring ~q could imitate over a stroke): no spring named.
TEST(DiagnoseNative, CleanAndPayloadDrawsGetNoSpring) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("native_clean");
  for (unsigned s = 0; s < 5; ++s) {
    const bool payload = s >= 3;
    const unsigned seed = 0xc1ea0u + s;
    const Native n = make_native(dir, "c" + std::to_string(s), seed, 0, nullptr);
    if (payload) {
      std::mt19937_64 rng(seed);   // make_case's chain again, with the payload
      std::ofstream(n.c.truth) << test::random_chain(rng, n.c.joints, 2.0);
    }
    for (const double lowpass : {10.0, 0.0}) {   // the usual import, and raw central differences
      const std::string data = (dir / ("c" + std::to_string(s) + (lowpass > 0 ? "f" : "r") + ".h5")).string();
      const auto causes = named(diagnose_case(n.c, measured(n.c, data, 130 + s, 0, lowpass)));
      std::cout << (payload ? "payload" : "clean") << " draw " << s << (lowpass > 0 ? " (10 Hz low-pass)" : " (raw differences)") << ": named "
                << joined(causes) << "\n";
      for (const auto& c : causes) EXPECT_NE(c.rfind("spring@", 0), 0u) << joined(causes);
    }
  }
}

}  // namespace
}  // namespace spml
