// Helpers shared by the force plugins shipped with spml: configuration parsing and a
// template that turns a small C++ class into the C descriptor of force_plugin.h, so each
// plugin source holds only its physics.
//
// An effect class provides:
//   static const char* const kName, kDescription; static constexpr spml_config_key kKeys[] ({NULL}-ended)
//   explicit Effect(const EffectConfig&)            (throws std::invalid_argument on bad values)
//   void compute(const mjModel*, const mjData*, mjtNum* qfrc) const
//   std::vector<std::string> names; std::vector<double> theta;   (the parameter vector)
//   std::string config() const    (key=value words recreating it with the current theta)
// and optionally
//   static constexpr bool kLinear = true; void regressor(const mjModel*, const mjtNum* qpos, const mjtNum* qvel, mjtNum* R) const
//   static constexpr bool kStateful = true; void advance(const mjModel*, const mjData*, mjtNum dt); void reset()
//   static constexpr spml_shape_param kShape[] ({NULL}-ended)
// The host has already checked every value against kKeys and filled in the defaults, so an
// effect only checks relations between values (lower < upper, fc <= fs).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

#include "spml/force_plugin.h"
#include "spml/parse.h"

namespace spml::effects {

struct Joint {
  std::string name;
  int id, qpos, dof;
};

// "joint 3 'elbow' (hinge)" or "joint 0 (free, unnamed)" for messages: mj_id2name gives NULL
// for an unnamed joint, and a free joint has no name unless the MJCF gives one.
inline std::string describe_joint(const mjModel* m, int j) {
  static const char* const kTypes[] = {"free", "ball", "slide", "hinge"};
  const int type = m->jnt_type[j];
  const std::string kind = type >= 0 && type < 4 ? kTypes[type] : "type " + std::to_string(type);
  const char* name = mj_id2name(m, mjOBJ_JOINT, j);
  return "joint " + std::to_string(j) + (name && *name ? " '" + std::string(name) + "' (" + kind + ")" : " (" + kind + ", unnamed)");
}

class EffectConfig {
 public:
  EffectConfig(const mjModel* m, const int* joints, int njoint, const char* const* keys,
               const char* const* values, int nkv) {
    for (int i = 0; i < njoint; ++i) {
      const int j = joints[i];
      if (j < 0 || j >= m->njnt) throw std::invalid_argument("joint index " + std::to_string(j) + " is not in the model");
      const char* name = mj_id2name(m, mjOBJ_JOINT, j);   // NULL for an unnamed joint
      if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE)
        throw std::invalid_argument(describe_joint(m, j) + " is not a hinge or slide joint");
      if (!name || !*name) throw std::invalid_argument(describe_joint(m, j) + " has no name; effects act on named joints");
      this->joints.push_back({name, j, m->jnt_qposadr[j], m->jnt_dofadr[j]});
    }
    for (int i = 0; i < nkv; ++i) kv_.emplace_back(keys[i], values[i]);
  }

  bool has(const std::string& key) const {
    for (auto& [k, v] : kv_) if (k == key) return true;
    return false;
  }

  // A list of numbers; `expect` entries (a single value is broadcast), or any count if 0.
  std::vector<double> list(const std::string& key, size_t expect = 0) const {
    const std::string* text = find(key);
    if (!text) throw std::invalid_argument("missing required key '" + key + "'");
    const auto parsed = parse_numbers(*text);
    if (!parsed) throw std::invalid_argument("key '" + key + "': '" + *text + "' is not a list of finite numbers");
    std::vector<double> out = *parsed;
    if (expect && out.size() == 1) out.assign(expect, out[0]);
    if (expect && out.size() != expect)
      throw std::invalid_argument("key '" + key + "': expected 1 or " + std::to_string(expect) + " values, got " +
                                  std::to_string(out.size()));
    return out;
  }
  std::vector<double> per_joint(const std::string& key) const { return list(key, joints.size()); }
  double number(const std::string& key) const { return list(key, 1)[0]; }
  double number(const std::string& key, double fallback) const { return has(key) ? number(key) : fallback; }

  std::vector<Joint> joints;

 private:
  const std::string* find(const std::string& key) const {
    for (auto& [k, v] : kv_) if (k == key) return &v;
    return nullptr;
  }
  std::vector<std::pair<std::string, std::string>> kv_;
};

// Comma-joined exact_text of a list (a written configuration reads back to the same values).
inline std::string exact_list(const std::vector<double>& v) {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) out += (i ? "," : "") + exact_text(v[i]);
  return out;
}
// Every stride-th entry of theta starting at first: one parameter across joints.
inline std::vector<double> every(const std::vector<double>& theta, size_t first, size_t stride) {
  std::vector<double> out;
  for (size_t i = first; i < theta.size(); i += stride) out.push_back(theta[i]);
  return out;
}

inline void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

// Sign with optional tanh smoothing (width > 0): friction laws use it so that a
// simulation with a finite step does not chatter around zero velocity.
inline double smooth_sign(double v, double width) {
  if (width > 0) return std::tanh(v / width);
  return v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0);
}

template <class E, class = void> struct is_linear : std::false_type {};
template <class E> struct is_linear<E, std::void_t<decltype(E::kLinear)>> : std::bool_constant<E::kLinear> {};
template <class E, class = void> struct has_shape : std::false_type {};
template <class E> struct has_shape<E, std::void_t<decltype(E::kShape)>> : std::true_type {};
// An effect is flagged SPML_FORCE_INDEPENDENT unless its class says `static constexpr bool
// kIndependent = false` (one that keeps state outside its instance: a global, a shared cache).
template <class E, class = void> struct is_independent : std::true_type {};
template <class E> struct is_independent<E, std::void_t<decltype(E::kIndependent)>> : std::bool_constant<E::kIndependent> {};
template <class E, class = void> struct is_stateful : std::false_type {};
template <class E> struct is_stateful<E, std::void_t<decltype(E::kStateful)>> : std::bool_constant<E::kStateful> {};

template <class E>
const spml_force_plugin* make_descriptor() {
  static const spml_force_plugin d = [] {
    spml_force_plugin p{};
    p.abi_version = SPML_FORCE_PLUGIN_ABI_VERSION;
    // State kept in the instance (compute_linear's scratch is per thread), unless the class says not.
    p.flags = is_independent<E>::value ? SPML_FORCE_INDEPENDENT : 0u;
    p.name = E::kName;
    p.summary = E::kDescription;
    p.config_keys = E::kKeys;
    p.create = [](const mjModel* m, const int* joints, int32_t njoint, const char* const* keys,
                  const char* const* values, int32_t nkv, char* err, size_t errlen) -> void* {
      try {
        return new E(EffectConfig(m, joints, njoint, keys, values, nkv));
      } catch (const std::exception& e) {
        std::snprintf(err, errlen, "%s", e.what());
        return nullptr;
      }
    };
    p.destroy = [](void* inst) { delete static_cast<E*>(inst); };
    p.compute = [](const void* inst, const mjModel* m, const mjData* d, mjtNum* qfrc) {
      static_cast<const E*>(inst)->compute(m, d, qfrc);
    };
    if constexpr (is_stateful<E>::value) {
      p.advance = [](void* inst, const mjModel* m, const mjData* d, mjtNum dt) { static_cast<E*>(inst)->advance(m, d, dt); };
      p.reset = [](void* inst) { static_cast<E*>(inst)->reset(); };
    }
    p.nparam = [](const void* inst) { return static_cast<int32_t>(static_cast<const E*>(inst)->theta.size()); };
    p.param_name = [](const void* inst, int32_t i) { return static_cast<const E*>(inst)->names.at(i).c_str(); };
    p.get_params = [](const void* inst, mjtNum* out) {
      auto& th = static_cast<const E*>(inst)->theta;
      for (size_t i = 0; i < th.size(); ++i) out[i] = th[i];
    };
    p.set_params = [](void* inst, const mjtNum* in) {
      auto& th = static_cast<E*>(inst)->theta;
      for (size_t i = 0; i < th.size(); ++i) th[i] = in[i];
    };
    if constexpr (is_linear<E>::value) {
      p.regressor = [](const void* inst, const mjModel* m, const mjtNum* qpos, const mjtNum* qvel, mjtNum* R) {
        static_cast<const E*>(inst)->regressor(m, qpos, qvel, R);
      };
    }
    if constexpr (has_shape<E>::value) p.shape_params = E::kShape;
    p.write_config = [](const void* inst, char* buf, size_t size) -> int32_t {
      const std::string text = static_cast<const E*>(inst)->config();
      return static_cast<int32_t>(std::snprintf(buf, size, "%s", text.c_str()));
    };
    return p;
  }();
  return &d;
}

// Linear effects compute their force as R * theta, so force and regressor cannot disagree.
// The scratch buffer is per thread and only grows: no heap allocation per simulation step.
template <class E>
void compute_linear(const E& e, const mjModel* m, const mjData* d, mjtNum* qfrc) {
  const int np = static_cast<int>(e.theta.size());
  thread_local std::vector<mjtNum> R;
  R.assign(static_cast<size_t>(m->nv) * np, 0.0);
  e.regressor(m, d->qpos, d->qvel, R.data());
  for (int r = 0; r < m->nv; ++r)
    for (int c = 0; c < np; ++c) qfrc[r] += R[static_cast<size_t>(r) * np + c] * e.theta[c];
}

}  // namespace spml::effects

// One effect per library: the entry points of force_plugin.h (revision 1: its flags).
#define SPML_EXPORT_FORCE_PLUGIN(Effect)                                                              \
  extern "C" SPML_EXPORT int32_t spml_force_plugin_abi_version(void) { return SPML_FORCE_PLUGIN_ABI_VERSION; } \
  extern "C" SPML_EXPORT int32_t spml_force_plugin_abi_revision(void) { return SPML_FORCE_PLUGIN_ABI_REVISION; } \
  extern "C" SPML_EXPORT const spml_force_plugin* spml_force_plugin_get(int32_t i) {                   \
    return i == 0 ? spml::effects::make_descriptor<Effect>() : nullptr;                               \
  }
