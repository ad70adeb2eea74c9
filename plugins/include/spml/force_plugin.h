/* spml force-plugin ABI, version 1.
 *
 * A force plugin is a shared library that adds a passive generalized force to a MuJoCo
 * model: friction of some kind, a ripple, an offset. MuJoCo 2.2.2 has no engine-plugin API,
 * so this is spml's own, shaped after MuJoCo 3's mjpPlugin: a static descriptor with a
 * name, the configuration keys it accepts, create/destroy, a compute callback that adds
 * into the generalized force, an optional per-step advance for internal state, and - what
 * mjpPlugin lacks - the plugin's parameter vector and, for effects linear in it, the
 * regressor columns. The same plugin that injects an effect in simulation is therefore a
 * candidate cause when identifying measured data.
 *
 * A library exports one function, spml_force_plugin(), returning its descriptor.
 * The host rejects a descriptor whose abi_version differs from SPML_FORCE_PLUGIN_ABI.
 * All callbacks may assume valid pointers; none may keep a pointer to the mjData.
 */
#ifndef SPML_FORCE_PLUGIN_H_
#define SPML_FORCE_PLUGIN_H_

#include <mujoco/mujoco.h>

#ifdef __cplusplus
extern "C" {
#endif

#define SPML_FORCE_PLUGIN_ABI 1
#define SPML_FORCE_PLUGIN_ENTRY "spml_force_plugin"

typedef struct spmlForcePlugin_ {
  int abi_version;                 /* SPML_FORCE_PLUGIN_ABI */
  const char* name;                /* e.g. "friction_band": the word used to name causes */
  const char* description;         /* one line, for listings and messages */
  const char* const* keys;         /* NULL-terminated configuration keys it accepts */

  /* Creates an instance acting on the given joints (ids into m). keys/values are the
   * configuration from the MJCF, already checked against `keys`. On error: return NULL and
   * write a message (about the values, without the element name) into err. */
  void* (*create)(const mjModel* m, const int* joints, int njoint, const char* const* keys,
                  const char* const* values, int nkv, char* err, int errlen);
  void (*destroy)(void* instance);

  /* Adds the effect's generalized force (length m->nv) into qfrc for the state in d. */
  void (*compute)(const void* instance, const mjModel* m, const mjData* d, mjtNum* qfrc);

  /* Optional (NULL if stateless): advance internal state over one step of length dt,
   * called after the integrator step with the new state in d. */
  void (*advance)(void* instance, const mjModel* m, const mjData* d, mjtNum dt);
  /* Optional: return internal state to its initial value. */
  void (*reset)(void* instance);

  /* The parameter vector: count, a name per entry, read and write. */
  int (*nparam)(const void* instance);
  const char* (*param_name)(const void* instance, int i);
  void (*get_params)(const void* instance, mjtNum* theta);
  void (*set_params)(void* instance, const mjtNum* theta);

  /* Optional (NULL if the force is not linear in its parameters): write R, an
   * m->nv x nparam row-major matrix with force = R(qpos, qvel) * theta. */
  void (*regressor)(const void* instance, const mjModel* m, const mjtNum* qpos,
                    const mjtNum* qvel, mjtNum* R);
} spmlForcePlugin;

typedef const spmlForcePlugin* (*spmlForcePluginEntry)(void);

#ifdef __cplusplus
}
#endif

#endif /* SPML_FORCE_PLUGIN_H_ */
