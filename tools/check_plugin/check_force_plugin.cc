// The force-plugin clauses, on an MJCF the checker writes: a hinge, a slide and a second hinge
// in a chain. Every plugin is created on all three joints through the host's own path
// (PluginInstance: the key table checked, defaults filled), with required keys drawn from the
// seed: shape parameters inside their search range, other numbers in [0.1, 2] clipped to the
// key's bounds; a draw the plugin refuses (e.g. lower >= upper) is redrawn. The states reach
// several rad (m) and rad/s (m/s), speeds log-uniform over four decades with either sign, so
// that a fault that shows only far out or only fast (or slow) does not pass.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <atomic>
#include <thread>

#include "detail.h"
#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"
#include "spml/parse.h"

namespace spml::check {
namespace {

constexpr const char* kModel = R"(<mujoco model="spml-check-plugin">
  <option timestep="0.002" gravity="0 0 -9.81"/>
  <worldbody>
    <body name="link1">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom type="capsule" size="0.05" fromto="0 0 0 0.5 0 0" mass="1"/>
      <body name="carriage" pos="0.5 0 0">
        <joint name="slide" type="slide" axis="1 0 0"/>
        <geom type="box" size="0.1 0.05 0.05" mass="0.5"/>
        <body name="link2" pos="0.2 0 0">
          <joint name="hinge2" type="hinge" axis="0 1 0"/>
          <geom type="capsule" size="0.04" fromto="0 0 0 0.3 0 0" mass="0.3"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";
// States: q uniform in [-kQ, kQ] (the joints are unlimited), |qd| log-uniform in
// [kQdMin, kQd] with a random sign.
constexpr double kQ = 3.0, kQd = 10.0, kQdMin = 1e-3;
constexpr int kStates = 20, kAttempts = 50;
constexpr int kManyCalls = 500;   // compute calls before the no-hidden-state repeat
constexpr double kRelTol = 1e-9;

ModelPtr write_and_load_model(std::uint64_t seed) {
  namespace fs = std::filesystem;
  const fs::path path = fs::temp_directory_path() / ("spml-check-plugin-" + std::to_string(::getpid()) + "-" + std::to_string(seed) + ".xml");
  { std::ofstream(path) << kModel; }
  ModelPtr m;
  try {
    m = load_mjcf(path.string());
  } catch (...) {
    fs::remove(path);
    throw;
  }
  fs::remove(path);
  return m;
}

struct State {
  std::vector<mjtNum> qpos, qvel;
};

std::vector<State> random_states(const mjModel* m, std::uint64_t seed, int count) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> q(-kQ, kQ), log_speed(std::log(kQdMin), std::log(kQd));
  std::bernoulli_distribution negative(0.5);
  std::vector<State> out(static_cast<size_t>(count));
  for (auto& s : out) {
    s.qpos.resize(static_cast<size_t>(m->nq));
    s.qvel.resize(static_cast<size_t>(m->nv));
    for (auto& v : s.qpos) v = q(rng);
    for (auto& v : s.qvel) v = (negative(rng) ? -1 : 1) * std::exp(log_speed(rng));
  }
  return out;
}

// The plugin's force at a state, added into `start` (zeros unless given).
std::vector<mjtNum> force(const PluginInstance& inst, const mjModel* m, mjData* d, const State& s,
                          std::vector<mjtNum> start = {}) {
  std::copy(s.qpos.begin(), s.qpos.end(), d->qpos);
  std::copy(s.qvel.begin(), s.qvel.end(), d->qvel);
  mj_forward(m, d);
  if (start.empty()) start.assign(static_cast<size_t>(m->nv), 0.0);
  inst.plugin().compute(inst.state(), m, d, start.data());
  return start;
}

// "" when a and b agree within rel * scale per entry, else the first entry that does not.
std::string disagreement(const std::vector<mjtNum>& a, const std::vector<mjtNum>& b, double rel, const std::vector<double>& scale,
                         const std::string& what_a, const std::string& what_b) {
  for (size_t i = 0; i < a.size(); ++i) {
    const double tol = rel * std::max(scale.empty() ? std::max(std::fabs(a[i]), std::fabs(b[i])) : scale[i], 1e-300);
    if (!std::isfinite(a[i]) || !std::isfinite(b[i]))   // no "difference nan" for a value that is not a number
      return "dof " + std::to_string(i) + ": " + what_a + " " + num(a[i]) + ", " + what_b + " " + num(b[i]) + " (not finite)";
    if (!(std::fabs(a[i] - b[i]) <= tol) && !(rel == 0 && a[i] == b[i]))
      return "dof " + std::to_string(i) + ": " + what_a + " " + num(a[i]) + ", " + what_b + " " + num(b[i]) + " (difference " +
             num(std::fabs(a[i] - b[i])) + ", allowed " + num(tol) + ")";
  }
  return "";
}

// A value for a required key, drawn as the file comment says; "" when none can be made.
std::string draw_value(const spml_config_key& k, const spml_shape_param* shape, std::mt19937_64& rng) {
  if (k.type == SPML_VALUE_TEXT) return "";
  double lo, hi;
  bool integer = k.type == SPML_VALUE_INTEGER, log_scale = false;
  if (shape) {
    const double span = shape->domain == SPML_SHAPE_POSITION ? 2 * kQ : shape->domain == SPML_SHAPE_SPEED ? kQd : 1.0;
    const double base = shape->domain == SPML_SHAPE_POSITION ? -kQ : 0.0;
    lo = base + shape->lo * span;
    hi = base + shape->hi * span;
    integer |= shape->integer != 0;
    log_scale = shape->log_scale && lo > 0;
  } else {
    lo = std::max(k.min, 0.1);
    hi = std::min(k.max, 2.0);
    if (lo > hi) {
      lo = std::isfinite(k.min) ? k.min : k.max - 1;
      hi = std::isfinite(k.max) ? k.max : lo + 1;
    }
  }
  std::uniform_real_distribution<double> u(0, 1);
  double v = log_scale ? std::exp(std::log(lo) + u(rng) * (std::log(hi) - std::log(lo))) : lo + u(rng) * (hi - lo);
  v = std::clamp(v, k.min, k.max);
  return integer ? std::to_string(std::llround(v)) : exact_text(v);
}

const spml_shape_param* shape_of(const spml_force_plugin& p, const char* key) {
  for (const spml_shape_param* sp = p.shape_params; sp && sp->key; ++sp)
    if (std::string(sp->key) == key) return sp;
  return nullptr;
}

std::string config_text(const std::vector<std::pair<std::string, std::string>>& config) {
  std::string out;
  for (const auto& [k, v] : config) out += (out.empty() ? "" : " ") + k + "=" + v;
  return out.empty() ? "(defaults only)" : out;
}

// The instance every clause uses, or the reason none could be made.
// `vary`: draw every numeric key the user did not --set, those with a default too.
std::unique_ptr<PluginInstance> create(const spml_force_plugin& p, const mjModel* m, std::uint64_t seed,
                                       const std::vector<std::pair<std::string, std::string>>& given, std::string* detail,
                                       const std::vector<int>& joints = {0, 1, 2}, bool vary = false) {
  std::mt19937_64 rng(seed);
  std::string last;
  for (int attempt = 0; attempt < kAttempts; ++attempt) {
    std::vector<std::pair<std::string, std::string>> config = given;
    for (const spml_config_key* k = p.config_keys; k && k->name; ++k) {
      bool set = false;
      for (const auto& kv : given) set |= kv.first == k->name;
      if (set || (k->default_value && !(vary && k->type != SPML_VALUE_TEXT))) continue;
      std::string v = draw_value(*k, shape_of(p, k->name), rng);
      if (v.empty()) {
        *detail = "required key '" + std::string(k->name) + "' is text without a default: the checker cannot make a value";
        return nullptr;
      }
      config.emplace_back(k->name, v);
    }
    try {
      auto inst = std::make_unique<PluginInstance>(p, m, joints, config, "check-plugin");
      std::string names;
      for (int j : joints) names += (names.empty() ? "" : ", ") + std::string(mj_id2name(m, mjOBJ_JOINT, j));
      *detail = "on joints " + names + " with " + config_text(config) + " (attempt " + std::to_string(attempt + 1) + ")";
      return inst;
    } catch (const std::exception& e) {
      last = e.what();
    }
  }
  *detail = "no configuration drawn in " + std::to_string(kAttempts) + " attempts was accepted; last: " + last;
  return nullptr;
}

Outcome shape_params(const spml_force_plugin& p) {
  int n = 0;
  for (const spml_shape_param* sp = p.shape_params; sp && sp->key; ++sp, ++n) {
    const std::string k = sp->key;
    const spml_config_key* key = find_config_key(p.config_keys, k);
    if (!key) return fail("shape parameter '" + k + "' is not one of its config keys");
    if (key->type == SPML_VALUE_TEXT) return fail("shape parameter '" + k + "' is a text key");
    if (!(sp->lo < sp->hi) || !std::isfinite(sp->lo) || !std::isfinite(sp->hi))
      return fail("shape parameter '" + k + "': range [" + num(sp->lo) + ", " + num(sp->hi) + "] is not finite lo < hi");
    if (sp->log_scale && sp->lo <= 0) return fail("shape parameter '" + k + "': log scale from " + num(sp->lo) + " (must be > 0)");
    if (sp->domain < SPML_SHAPE_ABSOLUTE || sp->domain > SPML_SHAPE_SPEED)
      return fail("shape parameter '" + k + "': unknown domain " + std::to_string(sp->domain));
    if (sp->domain == SPML_SHAPE_ABSOLUTE && (sp->lo < key->min || sp->hi > key->max))
      return fail("shape parameter '" + k + "': range [" + num(sp->lo) + ", " + num(sp->hi) + "] leaves the key's bounds [" +
                  num(key->min) + ", " + num(key->max) + "]");
  }
  return n ? pass(std::to_string(n) + " config keys with valid ranges") : skip("no shape parameters");
}

// What the clauses of one plugin share: the model, a data, the instance and the states.
struct Bench {
  const spml_force_plugin& p;
  const mjModel* m;
  DataPtr d;
  PluginInstance& inst;
  std::vector<State> states;
  std::string name;
};

// `finite` tells whether every force was finite (additivity aside): the other clauses compare
// forces and are skipped when it is not.
Outcome finite_and_additive(Bench& b, bool& finite) {
  const std::vector<mjtNum> offset{1.0, -2.0, 3.0};
  finite = false;
  for (size_t s = 0; s < b.states.size(); ++s) {
    const auto f = force(b.inst, b.m, b.d.get(), b.states[s]);
    for (size_t i = 0; i < f.size(); ++i)
      if (!std::isfinite(f[i]))
        return fail("force " + num(f[i]) + " on dof " + std::to_string(i) + " at state " + std::to_string(s) + " (q " +
                    num(b.states[s].qpos[b.m->jnt_qposadr[b.m->dof_jntid[i]]]) + ", qd " + num(b.states[s].qvel[i]) + ")");
  }
  finite = true;
  for (size_t s = 0; s < b.states.size(); ++s) {
    const auto f = force(b.inst, b.m, b.d.get(), b.states[s]);
    auto g = force(b.inst, b.m, b.d.get(), b.states[s], offset);
    std::vector<double> scale(f.size());
    for (size_t i = 0; i < f.size(); ++i) {
      g[i] -= offset[i];
      scale[i] = std::fabs(f[i]) + std::fabs(offset[i]);
    }
    if (std::string why = disagreement(g, f, kRelTol, scale, "added into a non-zero qfrc", "into zeros"); !why.empty())
      return fail("compute must add into qfrc, state " + std::to_string(s) + ": " + why);
  }
  return pass("finite at " + std::to_string(b.states.size()) + " random states (|q| <= " + num(kQ) + ", " + num(kQdMin) +
              " <= |qd| <= " + num(kQd) + "), added into qfrc");
}

// Compute at every state, then kManyCalls more calls, then every state again (hidden state that
// appears only after many calls), and each state around a call at another state.
Outcome no_hidden_state(Bench& b) {
  std::vector<std::vector<mjtNum>> first;
  for (const auto& s : b.states) first.push_back(force(b.inst, b.m, b.d.get(), s));
  for (int k = 0; k < kManyCalls; ++k) force(b.inst, b.m, b.d.get(), b.states[static_cast<size_t>(k) % b.states.size()]);
  for (size_t s = 0; s < b.states.size(); ++s)
    if (std::string why = disagreement(force(b.inst, b.m, b.d.get(), b.states[s]), first[s], 0, {}, "after " + std::to_string(kManyCalls) + " calls", "first");
        !why.empty())
      return fail("compute gave another force at the same state " + std::to_string(s) + " without advance (hidden state): " + why);
  for (size_t s = 0; s + 1 < b.states.size(); ++s) {
    const auto before = force(b.inst, b.m, b.d.get(), b.states[s]);
    force(b.inst, b.m, b.d.get(), b.states[s + 1]);
    const auto again = force(b.inst, b.m, b.d.get(), b.states[s]);
    if (std::string why = disagreement(again, before, 0, {}, "second call", "first"); !why.empty())
      return fail("compute gave another force at the same state " + std::to_string(s) + " without advance (hidden state): " + why);
  }
  return pass("same force at the same state, " + std::to_string(b.states.size()) + " states, before and after " +
              std::to_string(kManyCalls) + " other calls, no advance between");
}

// R theta against compute at every state, for the current parameters.
std::string regressor_mismatch(Bench& b) {
  const int np = b.inst.nparam(), nv = b.m->nv;
  const Eigen::VectorXd theta = b.inst.params();
  std::vector<mjtNum> R(static_cast<size_t>(nv * np));
  for (size_t s = 0; s < b.states.size(); ++s) {
    std::fill(R.begin(), R.end(), 0.0);
    b.p.regressor(b.inst.state(), b.m, b.states[s].qpos.data(), b.states[s].qvel.data(), R.data());
    std::vector<mjtNum> Rt(static_cast<size_t>(nv), 0.0);
    std::vector<double> scale(static_cast<size_t>(nv), 0.0);
    for (int r = 0; r < nv; ++r)
      for (int k = 0; k < np; ++k) {
        Rt[r] += R[static_cast<size_t>(r * np + k)] * theta[k];
        scale[r] += std::fabs(R[static_cast<size_t>(r * np + k)] * theta[k]);
      }
    const auto f = force(b.inst, b.m, b.d.get(), b.states[s]);
    for (int r = 0; r < nv; ++r) scale[r] = std::max(scale[r], std::fabs(f[r]));
    if (std::string why = disagreement(Rt, f, kRelTol, scale, "R*theta", "compute"); !why.empty())
      return "state " + std::to_string(s) + ", " + why;
  }
  return "";
}

Outcome regressor(Bench& b) {
  if (!b.p.regressor) return skip("no regressor (not linear in its parameters)");
  if (std::string why = regressor_mismatch(b); !why.empty()) return fail(why);
  const Eigen::VectorXd theta = b.inst.params();
  b.inst.set_params(1.25 * theta);   // other parameters: compute must follow them too
  std::string why = regressor_mismatch(b);
  b.inst.set_params(theta);
  if (!why.empty()) return fail("after set_params(1.25 theta): " + why);
  return pass("R(q, qd) theta = compute within rel " + num(kRelTol) + " at " + std::to_string(b.states.size()) +
              " random states, for theta and 1.25 theta");
}

Outcome params_roundtrip(Bench& b) {
  const int np = b.inst.nparam();
  if (np < 0) return fail("nparam is " + std::to_string(np));
  std::set<std::string> names;
  for (int i = 0; i < np; ++i) {
    const char* n = b.p.param_name(b.inst.state(), i);
    if (!n || !*n) return fail("parameter " + std::to_string(i) + " has no name");
    if (!names.insert(n).second) return fail("parameter name '" + std::string(n) + "' given twice");
  }
  const Eigen::VectorXd theta = b.inst.params();
  std::vector<std::vector<mjtNum>> before;
  for (const auto& s : b.states) before.push_back(force(b.inst, b.m, b.d.get(), s));
  b.inst.set_params(theta);
  const Eigen::VectorXd after = b.inst.params();
  for (int i = 0; i < np; ++i)
    if (!(after[i] == theta[i])) return fail("parameter " + std::to_string(i) + ": " + num(theta[i]) + " became " + num(after[i]));
  for (size_t s = 0; s < b.states.size(); ++s)
    if (std::string why = disagreement(force(b.inst, b.m, b.d.get(), b.states[s]), before[s], 0, {}, "after", "before"); !why.empty())
      return fail("set_params(get_params()) changed the force at state " + std::to_string(s) + ": " + why);
  return pass(std::to_string(np) + " named parameters; set_params(get_params()) changes nothing");
}

// After set_params(1.25 theta) on `inst`, its written words create (through the host) an
// instance with the same parameters and force; "" when they do, else what differs. `text`
// receives the words.
std::string recreate_problem(Bench& b, PluginInstance& inst, std::string* text) {
  const Eigen::VectorXd theta = inst.params();
  inst.set_params(1.25 * theta);   // the written text must carry set_params' values
  struct Restore {
    PluginInstance& i;
    Eigen::VectorXd t;
    ~Restore() { i.set_params(t); }
  } restore{inst, theta};
  *text = inst.config_text();
  if (text->empty()) return "write_config wrote nothing";
  std::unique_ptr<PluginInstance> again;
  try {
    again = std::make_unique<PluginInstance>(b.p, b.m, std::vector<int>{0, 1, 2}, parse_config_words(*text, "written config"), "written config");
  } catch (const std::exception& e) {
    return "'" + *text + "' does not create the plugin: " + e.what();
  }
  const Eigen::VectorXd t2 = again->params();
  if (t2.size() != theta.size()) return "'" + *text + "' recreates " + std::to_string(t2.size()) + " parameters, not " + std::to_string(theta.size());
  std::vector<mjtNum> a(static_cast<size_t>(t2.size())), c(a.size());
  for (Eigen::Index i = 0; i < t2.size(); ++i) a[i] = 1.25 * theta[i], c[i] = t2[i];
  if (std::string why = disagreement(c, a, kRelTol, {}, "recreated", "written"); !why.empty())
    return "'" + *text + "': parameters differ: " + why.replace(0, 3, "parameter");
  for (size_t s = 0; s < b.states.size(); ++s)
    if (std::string why = disagreement(force(*again, b.m, b.d.get(), b.states[s]), force(inst, b.m, b.d.get(), b.states[s]),
                                       kRelTol, {}, "recreated", "original");
        !why.empty())
      return "recreated from '" + *text + "' the force differs at state " + std::to_string(s) + ": " + why;
  return "";
}

// Twice: on the instance every clause uses (defaults kept), and on one created with every
// numeric key drawn (seeded, in range), so that words that leave out a key the user set fail.
Outcome write_config(Bench& b, const std::vector<std::pair<std::string, std::string>>& given, std::uint64_t seed) {
  if (!b.p.write_config) return skip("no write_config");
  std::string text, varied_text, detail;
  if (std::string why = recreate_problem(b, b.inst, &text); !why.empty()) return fail(why);
  const auto varied = create(b.p, b.m, seed + 2, given, &detail, {0, 1, 2}, true);
  const std::string ok = "recreate the parameters and the force within rel " + num(kRelTol);
  if (!varied) return pass("'" + text + "' " + ok + "; no configuration with every key drawn was accepted (" + detail + ")");
  if (std::string why = recreate_problem(b, *varied, &varied_text); !why.empty())
    return fail("created with every key drawn (" + detail + "): " + why);
  return pass("'" + text + "' and, with every key drawn, '" + varied_text + "' " + ok);
}

// Attached to the middle joint (slide) only, compute adds into qfrc pre-filled with other
// values: the other dofs (a hinge before it, a hinge after it) must keep theirs bit for bit.
// A plugin that writes a neighbour's dof adds a force the host never asked for and that no
// regressor column of that joint explains.
Outcome own_dofs(Bench& b, const std::vector<std::pair<std::string, std::string>>& given, std::uint64_t seed) {
  constexpr int kJoint = 1;
  std::string detail;
  const auto one = create(b.p, b.m, seed, given, &detail, {kJoint});
  if (!one) return skip("cannot be created on one joint: " + detail);
  const int own = b.m->jnt_dofadr[kJoint];
  const std::vector<mjtNum> prefilled{1.0, -2.0, 3.0};
  for (size_t s = 0; s < b.states.size(); ++s) {
    const auto f = force(*one, b.m, b.d.get(), b.states[s], prefilled);
    for (int v = 0; v < b.m->nv; ++v)
      if (v != own && !(f[v] == prefilled[v]))
        return fail("attached to joint slide (dof " + std::to_string(own) + ") only, compute changed dof " + std::to_string(v) +
                    " (joint " + mj_id2name(b.m, mjOBJ_JOINT, b.m->dof_jntid[v]) + ") from " + num(prefilled[v]) + " to " +
                    num(f[v]) + " at state " + std::to_string(s));
  }
  return pass("attached to slide only, the other dofs untouched at " + std::to_string(b.states.size()) + " states");
}

// A prescribed trajectory (smooth sines, no integration, phase-shifted per walk), walked one
// step at a time: the force at each state, then an advance over the step.
struct Walk {
  Walk(const PluginInstance& instance, mjData* data, double phase_shift = 0) : inst(instance), d(data), phase(phase_shift) {}
  const PluginInstance& inst;
  mjData* d;
  double phase;
  int k = 0;
  std::vector<std::vector<mjtNum>> out;
};
void step(const Bench& b, Walk& w) {
  const double dt = b.m->opt.timestep, t = w.k * dt;
  State s{std::vector<mjtNum>(static_cast<size_t>(b.m->nq)), std::vector<mjtNum>(static_cast<size_t>(b.m->nv))};
  for (int j = 0; j < b.m->nv; ++j) {
    const double f = 2 * M_PI * (1.0 + 0.7 * j);
    s.qpos[j] = 0.8 * std::sin(f * t + j + w.phase);
    s.qvel[j] = 0.8 * f * std::cos(f * t + j + w.phase);
  }
  w.out.push_back(force(w.inst, b.m, w.d, s));
  if (b.p.advance) b.p.advance(w.inst.state(), b.m, w.d, dt);
  ++w.k;
}
std::vector<std::vector<mjtNum>> trajectory(Bench& b, int steps) {
  Walk w{b.inst, b.d.get()};
  for (int k = 0; k < steps; ++k) step(b, w);
  return std::move(w.out);
}

Outcome reset(Bench& b) {
  if (!b.p.advance) return skip("stateless (no advance)");
  if (!b.p.reset) return fail("declares internal state (advance) but no reset: a host cannot start a second run from its first state");
  constexpr int kSteps = 300;
  const auto first = trajectory(b, kSteps);
  b.p.reset(b.inst.state());
  const auto second = trajectory(b, kSteps);
  for (int k = 0; k < kSteps; ++k)
    if (std::string why = disagreement(second[k], first[k], 0, {}, "after reset", "first run"); !why.empty())
      return fail("step " + std::to_string(k) + " of " + std::to_string(kSteps) + ": " + why);
  b.p.reset(b.inst.state());
  return pass("after reset, " + std::to_string(kSteps) + " steps replay the first trajectory bit for bit");
}

// SPML_FORCE_INDEPENDENT: two instances of differently drawn configurations, each walked alone
// along its own trajectory, then both walked in turn on one thread and at the same time on two:
// the forces must be each one's own, bit for bit. State shared between instances (a global, a
// cache) shows in turn; a scratch buffer that is not per thread may show on two threads.
Outcome independent(Bench& b, uint32_t flags, const std::vector<std::pair<std::string, std::string>>& given, std::uint64_t seed) {
  if (!(flags & SPML_FORCE_INDEPENDENT)) return skip("not flagged SPML_FORCE_INDEPENDENT (the host calls it from one thread)");
  // Long enough, and both threads held at a start line, for the two walks to overlap: a review
  // found that 300 steps started unsynchronised caught a static scratch buffer on 2 seeds of 100.
  constexpr int kSteps = 2000;
  std::string detail[2];
  std::unique_ptr<PluginInstance> inst[2];
  DataPtr data[2] = {make_data(b.m), make_data(b.m)};
  auto make = [&](int i) {
    inst[i] = create(b.p, b.m, seed + 11 + static_cast<std::uint64_t>(i), given, &detail[i], {0, 1, 2}, true);
    return inst[i] != nullptr;
  };
  auto fresh = [&] {   // both anew, the earlier ones gone first
    inst[0].reset(), inst[1].reset();
    return make(0) && make(1);
  };
  std::vector<std::vector<mjtNum>> alone[2];
  for (int i = 0; i < 2; ++i) {
    if (!make(i)) return fail("instance " + std::to_string(i + 1) + ": " + detail[i]);
    Walk w{*inst[i], data[i].get(), 1.3 * i};
    for (int k = 0; k < kSteps; ++k) step(b, w);
    alone[i] = std::move(w.out);
    inst[i].reset();
  }
  auto differs = [&](const Walk& w, int i, const std::string& how) -> std::string {
    for (int k = 0; k < kSteps; ++k)
      if (std::string why = disagreement(w.out[static_cast<size_t>(k)], alone[i][static_cast<size_t>(k)], 0, {}, how, "alone"); !why.empty())
        return "instance " + std::to_string(i + 1) + " (" + detail[i] + "), step " + std::to_string(k) + ": " + why;
    return "";
  };
  if (!fresh()) return fail("instances again: " + detail[0] + "; " + detail[1]);
  {
    Walk w0{*inst[0], data[0].get(), 0}, w1{*inst[1], data[1].get(), 1.3};
    for (int k = 0; k < kSteps; ++k) step(b, w0), step(b, w1);
    for (int i = 0; i < 2; ++i)
      if (std::string why = differs(i ? w1 : w0, i, "stepped in turn with the other"); !why.empty()) return fail(why);
  }
  if (!fresh()) return fail("instances again: " + detail[0] + "; " + detail[1]);
  {
    Walk w0{*inst[0], data[0].get(), 0}, w1{*inst[1], data[1].get(), 1.3};
    std::atomic<int> ready{0};
    auto start_line = [&] {
      ++ready;
      while (ready.load() < 2) std::this_thread::yield();
    };
    std::thread other([&] {
      start_line();
      for (int k = 0; k < kSteps; ++k) step(b, w1);
    });
    start_line();
    for (int k = 0; k < kSteps; ++k) step(b, w0);
    other.join();
    for (int i = 0; i < 2; ++i)
      if (std::string why = differs(i ? w1 : w0, i, "on two threads at once"); !why.empty()) return fail(why);
  }
  return pass("two instances give their own forces bit for bit along " + std::to_string(kSteps) +
              " steps each, stepped in turn on one thread and at once on two");
}

void check_one(const spml_force_plugin& p, uint32_t flags, const mjModel* m, Recorder& r) {
  const std::string name = p.name;
  r.run(name, "shape-params", [&] { return shape_params(p); });
  if (std::string why = force_plugin_problem(p); !why.empty()) return r.record(name, "callbacks", fail(why));
  r.record(name, "callbacks", pass());
  r.run(name, "key-table", [&] {
    const std::string why = key_table_problems(p.config_keys, true);
    return why.empty() ? pass() : fail(why);
  });
  std::unique_ptr<PluginInstance> inst;
  std::string detail;
  std::vector<std::pair<std::string, std::string>> given;
  r.run(name, "create", [&] {
    given = r.config_for(p.config_keys);
    inst = create(p, m, r.seed(), given, &detail);
    return inst ? pass(detail) : fail(detail);
  });
  if (!inst) return;
  Bench b{p, m, make_data(m), *inst, random_states(m, r.seed() + 1, kStates), name};
  bool finite = false;
  r.run(name, "finite-force", [&] { return finite_and_additive(b, finite); });
  // Every other clause compares forces; a NaN makes each comparison fail with NaN numbers.
  auto compare = [&](const char* clause, const std::function<Outcome()>& body) {
    r.run(name, clause, [&] { return finite ? body() : skip("skipped: the force is not finite (finite-force)"); });
  };
  compare("no-hidden-state", [&] { return no_hidden_state(b); });
  compare("own-dofs", [&] { return own_dofs(b, given, r.seed()); });
  compare("regressor", [&] { return regressor(b); });
  compare("params-roundtrip", [&] { return params_roundtrip(b); });
  compare("write-config", [&] { return write_config(b, given, r.seed()); });
  compare("reset", [&] { return reset(b); });
  compare("independent", [&] { return independent(b, flags, given, r.seed()); });
}

}  // namespace

void check_force_plugins(const std::string& file, Recorder& recorder) {
  const auto lib = load_library(file, force_plugin_kind(), recorder);
  if (!lib) return;
  const ModelPtr m = write_and_load_model(recorder.seed());
  for (const void* e : lib->entries())
    if (const auto& p = *static_cast<const spml_force_plugin*>(e); recorder.wanted(p.name))
      check_one(p, force_plugin_flags(p, lib->revision()), m.get(), recorder);
}

}  // namespace spml::check
