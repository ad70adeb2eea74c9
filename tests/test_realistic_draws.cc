// Hidden-effect draws that look like real logs (issue #20 item 1). Each draw: a random 2-7
// joint spatial chain (test::random_chain), nothing or one effect of the plugin vocabulary
// (or a 2 kg payload) hidden in the true model, a forward simulation under the PD controller
// (spml generate --model's code), recorded with encoder quantization, torque noise and
// jittered sampling instants, positions only. Velocities and accelerations come from the
// import code path twice: low-pass + central differences (spml import --lowpass --derive)
// and raw central differences (spml import --derive), both decimated to 200 Hz by import's
// --decimate (its anti-alias low-pass first). spml diagnose runs on the model the user has.
//
// ConfusionTable (CI): prints the table per noise level and derivative path, and asserts the
// issue's bar, every draw: clean ones name nothing, hidden effects are named exactly.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <set>

#include "spml/dataset.h"
#include "spml/diagnose.h"
#include "spml/envs/measured_run.h"
#include "test_util.h"

namespace spml {
namespace {

struct NoiseLevel {
  std::string name;
  double torque_noise;
  int bits;
  double rate, jitter;
};
const std::vector<NoiseLevel> kLevels = {
    {"torque 0.5 %, 20 bit, 2 kHz, jitter 2 us", 0.005, 20, 2000, 2e-6},
    {"torque 1 %, 18 bit, 1 kHz, jitter 10 us", 0.01, 18, 1000, 1e-5},
    {"torque 2 %, 16 bit, 500 Hz, jitter 40 us", 0.02, 16, 500, 4e-5},
};
const std::vector<std::string> kEffects = {"coulomb", "viscous", "stribeck", "friction_band", "ripple", "offset", "asymmetric_friction", "payload"};
constexpr int kDrawsPerLevel = 8;       // 2 clean + 6 effects
constexpr double kDuration = 10;        // s logged per draw
constexpr double kOutRate = 200;        // Hz after decimation (diagnose's cost grows with rows)
constexpr double kLowpass = 10;         // Hz: the excitation tops at 1 Hz, the PD's bandwidth is 4 Hz

struct Draw {
  std::string hidden = "clean", label;
  std::set<std::string> expected;       // "effect@joint" or "parameters"
  std::string user_path, true_path;
  int joints = 0;
  unsigned set = 0;                     // SPML_REALISTIC_SET it was drawn from
};

// SPML_REALISTIC_SET=k (default 0, what CI runs) draws another set of chains, effects' sizes
// and noise seeds with the same effects per slot: data the thresholds were not tuned on.
unsigned draw_set() {
  const char* v = std::getenv("SPML_REALISTIC_SET");
  return v ? static_cast<unsigned>(std::stoul(v)) : 0u;
}

// The draw's models: a chain, and the same chain with the effect (or payload) hidden.
Draw make_draw(int level, int index, const std::filesystem::path& dir, unsigned set = draw_set()) {
  std::mt19937_64 rng(0x7ea10000u + static_cast<unsigned>(100 * level + index) + 10000u * set);
  Draw d;
  d.set = set;
  if (index >= 2) d.hidden = kEffects[static_cast<size_t>(level * 6 + index - 2) % kEffects.size()];
  std::uniform_int_distribution<int> pick_n(2, 7);
  d.joints = pick_n(rng);
  const auto seed = rng();
  std::mt19937_64 chain_rng(seed), again(seed);
  const std::string user = test::random_chain(chain_rng, d.joints, 0);
  d.label = "chain" + std::to_string(d.joints);
  d.user_path = (dir / ("user" + std::to_string(level) + "_" + std::to_string(index) + ".xml")).string();
  d.true_path = (dir / ("true" + std::to_string(level) + "_" + std::to_string(index) + ".xml")).string();
  std::ofstream(d.user_path) << user;
  std::string truth = user;
  if (d.hidden == "payload") {
    truth = test::random_chain(again, d.joints, 2.0);
    d.expected = {"parameters"};
  } else if (d.hidden != "clean") {
    // The effect's size: 8-14 % of the joint's RMS torque on the user's model (a clean run).
    MeasurementOptions probe;
    probe.duration = 2;
    probe.torque_noise = 0;
    const MeasuredRun clean = simulate_measured(d.user_path, probe);
    std::uniform_int_distribution<int> pick_joint(0, d.joints - 1);
    const int j = pick_joint(rng);
    const std::string joint = "j" + std::to_string(j);
    std::map<std::string, double> values;
    // A ripple the stroke spans at least four periods of (issue #20 item 7: a periodic effect
    // only where the data span several periods; diagnose searches from three, the probe's 2 s
    // stroke may be shorter than the fit split's - hence one period of margin): gear 13 on a
    // 1.24 rad stroke (2.6 periods) was hidden here once, a ripple diagnose does not search.
    const double stroke = clean.q.col(j).maxCoeff() - clean.q.col(j).minCoeff();
    const int min_gear = std::max(3, static_cast<int>(std::ceil(4 * 2 * M_PI / stroke)));
    truth = test::with_declarations(user, {test::effect_text(d.hidden, joint, 0.01 * clean.rms[j], rng, values, min_gear)});
    d.expected = {d.hidden + "@" + joint};
  }
  std::ofstream(d.true_path) << truth;
  return d;
}

// The run's data through spml import's conditioning: low-pass + differences, or raw differences.
std::string condition(const MeasuredRun& run, const NoiseLevel& n, bool lowpass, const std::string& path) {
  ImportSpec spec;
  for (const auto& j : run.joints) spec.x.push_back("q:" + j), spec.y.push_back("tau:" + j);
  spec.t = "t";
  spec.conditioning.derive = true;
  spec.conditioning.lowpass_hz = lowpass ? kLowpass : 0;
  spec.conditioning.drop_edges = lowpass ? static_cast<int>(0.2 * n.rate) : 2;
  spec.conditioning.decimate = static_cast<int>(n.rate / kOutRate);
  write_dataset(path, table_to_dataset(measured_table(run, path), spec));
  return path;
}

// The draw's log: its true model under the PD controller at noise level l.
MeasuredRun measure(const Draw& d, size_t l, int i) {
  const NoiseLevel& n = kLevels[l];
  MeasurementOptions o;
  o.duration = kDuration;
  o.rate = n.rate;
  o.torque_noise = n.torque_noise;
  o.encoder_bits = n.bits;
  o.jitter = n.jitter;
  o.seed = 1000 * l + static_cast<unsigned>(i) + 100000u * d.set;
  o.excitation.seed = o.seed + 17;
  return simulate_measured(d.true_path, o);
}

// The causes a report names, in its order: "effect@joint", or "parameters". Not those a later
// cause superseded, nor those rejected by the written model's checks (report.md lists them as
// REJECTED, extended.xml leaves them out).
std::vector<std::string> named_causes(const nlohmann::json& report) {
  std::vector<std::string> out;
  for (const auto& cause : report["causes"])
    if (!cause.contains("superseded_by") && !cause.contains("rejected"))
      out.push_back(cause["effect"] == "parameters" ? "parameters" : cause["effect"].get<std::string>() + "@" + cause["joints"][0].get<std::string>());
  return out;
}

// One draw of `set` diagnosed alone (the single-draw tests below): its report.
nlohmann::json diagnose_draw(const Draw& d, int level, int index, bool lowpass, const std::filesystem::path& file) {
  DiagnoseOptions opt;
  opt.model = d.user_path;
  opt.data = condition(measure(d, static_cast<size_t>(level), index), kLevels[static_cast<size_t>(level)], lowpass, file.string());
  opt.rollouts = 0;
  return diagnose(opt, "").report;
}

std::set<std::string> named_set(const nlohmann::json& report) {
  const auto list = named_causes(report);
  return {list.begin(), list.end()};
}

struct Outcome {
  std::string level, path, hidden, label, named;   // named: "nothing" or "a@j0+b@j1"
  std::set<std::string> named_set, expected;
  double seconds = 0;
  // Viscous friction on a joint with MJCF damping is a damping change: "parameters" alone is
  // as right as naming it.
  bool exact() const {
    return named_set == expected || (hidden == "viscous" && named_set == std::set<std::string>{"parameters"});
  }
};

std::vector<Outcome> run_draws() {
  const auto dir = test::temp_dir("realistic");
  std::vector<Outcome> out;
  for (size_t l = 0; l < kLevels.size(); ++l) {
    const NoiseLevel& n = kLevels[l];
    for (int i = 0; i < kDrawsPerLevel; ++i) {
      // SPML_REALISTIC_ONLY=level:draw runs that draw alone (with SPML_KEEP_TEST_FILES, its
      // models and datasets stay in the temp folder for a look with spml diagnose).
      if (const char* only = std::getenv("SPML_REALISTIC_ONLY"); only && std::string(only) != std::to_string(l) + ":" + std::to_string(i))
        continue;
      const Draw d = make_draw(static_cast<int>(l), i, dir);
      const MeasuredRun run = measure(d, l, i);
      for (const bool lowpass : {true, false}) {
        const auto start = std::chrono::steady_clock::now();
        DiagnoseOptions opt;
        opt.model = d.user_path;
        opt.data = condition(run, n, lowpass, (dir / ("d" + std::to_string(l) + "_" + std::to_string(i) + (lowpass ? "_lowpass" : "_raw") + ".h5")).string());
        opt.rollouts = 0;
        const auto r = diagnose(opt, "").report;
        Outcome c{n.name, lowpass ? "lowpass+derive" : "raw differences", d.hidden, d.label, "", {}, d.expected, 0};
        for (const auto& name : named_causes(r)) {
          c.named_set.insert(name);
          c.named += (c.named.empty() ? "" : "+") + name;
        }
        if (c.named.empty()) c.named = "nothing";
        c.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        std::string expected;
        for (const auto& e : d.expected) expected += e + " ";
        std::cout << "level " << l << " draw " << i << " " << std::setw(7) << d.label << " " << std::setw(15) << c.path << "  hidden "
                  << std::setw(24) << (expected.empty() ? "nothing" : expected) << " named " << c.named << "  (" << std::fixed
                  << std::setprecision(1) << c.seconds << " s)" << std::defaultfloat << (c.exact() ? "" : "  <-- differs") << std::endl;
        // Why a hidden effect was not searched (e.g. a ripple whose period the stroke does not span).
        if (!c.exact())
          for (const auto& n : r["not_tried"])
            if (d.hidden.find(n["effect"].get<std::string>()) != std::string::npos)
              std::cout << "    not tried: " << n.dump() << std::endl;
        out.push_back(c);
      }
    }
  }
  return out;
}

// Rows: hidden effect (or clean) and how many draws; columns: how many of them named that
// cause (on any joint; "nothing" when none was named). A draw naming two causes counts twice.
void print_tables(const std::vector<Outcome>& all) {
  std::map<std::pair<std::string, std::string>, std::vector<const Outcome*>> groups;
  for (const auto& o : all) groups[{o.level, o.path}].push_back(&o);
  std::vector<std::string> cols = {"nothing", "parameters"};
  for (const auto& e : kEffects)
    if (e != "payload") cols.push_back(e);
  for (const auto& [key, items] : groups) {
    std::map<std::string, std::map<std::string, int>> table;
    int exact = 0;
    for (const Outcome* o : items) {
      table[o->hidden]["draws"]++;
      std::set<std::string> named;
      for (const auto& n : o->named_set) named.insert(n.substr(0, n.find('@')));
      if (named.empty()) named.insert("nothing");
      for (const auto& n : named) table[o->hidden][n]++;
      exact += o->exact();
    }
    std::cout << "\nconfusion table: " << key.first << ", " << key.second << " (" << exact << "/" << items.size()
              << " named exactly, joint included)\n" << std::setw(20) << "hidden \\ named" << std::setw(6) << "draws";
    for (const auto& c : cols) std::cout << std::setw(static_cast<int>(c.size()) + 2) << c;
    std::cout << "\n";
    for (auto& [h, row] : table) {
      std::cout << std::setw(20) << h << std::setw(6) << row["draws"];
      for (const auto& c : cols) std::cout << std::setw(static_cast<int>(c.size()) + 2) << (row.count(c) ? std::to_string(row[c]) : ".");
      std::cout << "\n";
    }
  }
}

const std::vector<Outcome>& outcomes() {
  static const std::vector<Outcome> all = [] {
    const auto start = std::chrono::steady_clock::now();
    auto v = run_draws();
    print_tables(v);
    std::cout << "\n" << v.size() / 2 << " draws x 2 derivative paths in " << std::fixed << std::setprecision(1)
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s\n" << std::defaultfloat;
    return v;
  }();
  return all;
}

TEST(RealisticDraws, ConfusionTable) {
  const auto& all = outcomes();
  if (std::getenv("SPML_REALISTIC_ONLY")) GTEST_SKIP() << "SPML_REALISTIC_ONLY: one draw, no bar";
  ASSERT_EQ(all.size(), 2u * kLevels.size() * kDrawsPerLevel);
  // Issue #20's bar, draw by draw: clean draws give no cause, each hidden effect is named
  // exactly on its joint (viscous friction may be named `parameters`, a damping change), on
  // both derivative paths. The history of the counts (named exactly, low-pass / raw
  // differences, of 24): 11 / 1 when the draws were added; 17 once a Stribeck fit with fs < fc
  // was refused; 19 / 13 with `parameters` judged by instrumental variables (least squares'
  // shrunken inertias had named it on a clean raw draw); 20 when a cause's evidence counted the
  // effective sample size of its own joints; 22 with a ripple's wavenumber bounded by the data's
  // band; raw 19 with import's anti-aliased decimation (plain subsampling folded the
  // differences' noise into the band), 21 once no `delay` was named on raw differences; 23 / 22
  // with ripples hidden over four periods of the stroke; 24 low-pass with the Stribeck speed
  // searched only where fs >= fc; raw 23 when the filter was also detected from the model's
  // error above the band (a Stribeck curve had been named `coulomb`), 24 when `parameters`'
  // held-out gain could also show joint by joint (viscous friction on a small joint among
  // noisy large ones had been named nothing).
  std::map<std::string, int> exact, clean_ok;
  std::string wrong;
  for (const auto& o : all) {
    exact[o.path] += o.exact();
    clean_ok[o.path] += o.hidden == "clean" && o.named == "nothing";
    if (!o.exact()) wrong += "\n  " + o.level + ", " + o.path + ": " + o.label + " hidden " + o.hidden + ", named " + o.named;
  }
  std::cout << "named exactly: lowpass+derive " << exact["lowpass+derive"] << "/24, raw differences " << exact["raw differences"]
            << "/24; clean with no cause: " << clean_ok["lowpass+derive"] << "/6, " << clean_ok["raw differences"] << "/6\n";
  EXPECT_TRUE(wrong.empty()) << "draws not named exactly:" << wrong;
}

// Level 0, draw 4 alone (a fast check of what ConfusionTable counts): a Stribeck curve of
// fc 0.20, fs 0.61, vs 0.29 rad/s is named `stribeck` on its joint and nothing else, through the
// 10 Hz import and through raw differences. Its speed search once settled at the bottom of the
// range (0.004 rad/s) where the fit had fs < fc (stick phases), was refused, and `coulomb` was
// named beside `parameters`. On raw differences the accelerations hold 2 % of their power above
// five times the band, but the model's error 99 % on every joint without the effect: the
// low-pass is detected from the error, and without it `coulomb` was named (fc 0.33 +- 0.015).
TEST(RealisticDraws, StribeckIsSearchedInsideItsForm) {
  SPML_SKIP_UNDER_SANITIZERS();
  const auto dir = test::temp_dir("realistic-stribeck");
  const Draw d = make_draw(0, 4, dir, 0);
  ASSERT_EQ(d.hidden, "stribeck");
  const MeasuredRun run = measure(d, 0, 4);
  for (const bool lowpass : {true, false}) {
    DiagnoseOptions opt;
    opt.model = d.user_path;
    opt.data = condition(run, kLevels[0], lowpass, (dir / (lowpass ? "lowpass.h5" : "raw.h5")).string());
    opt.rollouts = 0;
    const auto r = diagnose(opt, "").report;
    EXPECT_EQ(named_set(r), d.expected) << (lowpass ? "low-pass: " : "raw differences: ") << r["causes"].dump(1);
    const auto& filter = r["parallel_filter"];
    EXPECT_EQ(filter["source"], lowpass ? "recorded" : "detected") << filter.dump();
    if (!lowpass) {
      EXPECT_NE(filter["why"].get<std::string>().find("of its error power above"), std::string::npos) << filter.dump();
      EXPECT_TRUE(filter["torques_filtered"].get<bool>());
    }
  }
}

// Set 1, level 1, draw 6: a Stribeck curve (fc 0.63, fs 1.88, vs 0.22) through the 10 Hz import.
// Coulomb joins first and LuGre (`stick_slip`) was compared with Coulomb alone: held out 7.20
// against 11.3, so it took the place of a Stribeck curve that does better still (4.28). The
// stateful rival must now beat every static candidate on the joint, and the report says that
// it lost, with both residuals (not_tried: the LuGre fit left no trace before).
TEST(RealisticDraws, LuGreMustBeatTheBestStaticFrictionNotCoulombAlone) {
  const auto dir = test::temp_dir("realistic-rival");
  const Draw d = make_draw(1, 6, dir, 1);
  ASSERT_EQ(d.hidden, "stribeck");
  const auto r = diagnose_draw(d, 1, 6, true, dir / "d.h5");
  EXPECT_EQ(named_set(r), d.expected) << r["causes"].dump(1);
  ASSERT_EQ(d.expected.size(), 1u);
  const std::string joint = d.expected.begin()->substr(d.expected.begin()->find('@') + 1);
  bool said = false;
  for (const auto& n : r["not_tried"])
    said = said || (n["effect"] == "stick_slip" && n.value("joint", "") == joint &&
                    n["reason"].get<std::string>().find("does not beat the static frictions on its joint") != std::string::npos);
  EXPECT_TRUE(said) << r["not_tried"].dump(1);
}

// Set 2, level 0, draw 6: a ripple on j0 of a 5-joint chain through the 10 Hz import. The delay
// search (base parameters, a constant and static friction beside the shift) read part of the
// ripple as an offset of -14.7 ms; corrected, the data then had `parameters`, the ripple and a
// band named. Now the causes are chosen on the data as measured too, and the delay stays only
// when its model wins (there the ripple and band fitted to 17.7 against 6053 on the shifted
// torques): the ripple alone, no delay. Since the joints must agree on a delay, the ripple's
// joint, asking for -25.5 ms of its own where the others ask -6 to +2, is left out of the search
// and the rest find 0.1 ms: no delay passes the search at all.
TEST(RealisticDraws, ADelayThatIsAnotherEffectIsDropped) {
  const auto dir = test::temp_dir("realistic-delay");
  const Draw d = make_draw(0, 6, dir, 2);
  ASSERT_EQ(d.hidden, "ripple");
  const auto r = diagnose_draw(d, 0, 6, true, dir / "d.h5");
  EXPECT_EQ(named_set(r), d.expected) << r["causes"].dump(1);
  EXPECT_FALSE(r["delay"]["named"].get<bool>()) << r["delay"].dump();
  const std::string ripple_joint = d.expected.begin()->substr(d.expected.begin()->find('@') + 1);
  const auto& out = r["delay"]["joints_left_out"];
  EXPECT_NE(std::find(out.begin(), out.end(), ripple_joint), out.end()) << r["delay"].dump();
}

// Asymmetric friction holds Coulomb's column and the joint's damping column; Coulomb joins
// first. Two draws of set 2 through the 10 Hz import, where `parameters` + `coulomb` were named:
// - level 2, draw 4 (Coulomb 0.084 both ways, viscous 0.105 forward, 0.021 backward): fitted
//   beside Coulomb, the shared column split as fc_pos -0.015 + Coulomb 0.093, refused as
//   energy-feeding friction. It is now tried in Coulomb's place (Diagnosis::nests).
// - level 1, draw 2 (Coulomb 2.49, viscous 3.11 forward, 0.62 backward, MJCF damping 0.5):
//   fv_neg -2.58 was refused against the MJCF's damping where the refitted damping beside it was
//   3.7. It is now judged against the damping it is fitted beside.
TEST(RealisticDraws, AsymmetricFrictionReplacesTheCoulombItHolds) {
  const auto dir = test::temp_dir("realistic-asymmetric");
  for (const auto& [level, index] : {std::pair{2, 4}, std::pair{1, 2}}) {
    const Draw d = make_draw(level, index, dir, 2);
    ASSERT_EQ(d.hidden, "asymmetric_friction");
    const auto r = diagnose_draw(d, level, index, true, dir / ("d" + std::to_string(level) + ".h5"));
    EXPECT_EQ(named_set(r), d.expected) << "level " << level << ": " << r["causes"].dump(1);
    bool superseded = false;
    for (const auto& cause : r["causes"])
      superseded |= cause["effect"] == "coulomb" && cause.value("superseded_by", "") == "asymmetric_friction";
    EXPECT_TRUE(superseded) << "level " << level << ": " << r["causes"].dump(1);
  }
}

}  // namespace
}  // namespace spml
