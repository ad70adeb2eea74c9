/* spml force-plugin ABI, version 3 (revision 1).
 *
 * A force plugin adds a passive generalized force to a MuJoCo model: friction of some kind,
 * a ripple, an offset. MuJoCo 2.2.2 has no engine-plugin API, so this is spml's own, shaped
 * after MuJoCo 3's mjpPlugin: a static descriptor with a name, the configuration keys it
 * accepts, create/destroy, a compute callback that adds into the generalized force, an
 * optional per-step advance for internal state, and - what mjpPlugin lacks - the plugin's
 * parameter vector, for effects linear in it the regressor columns, and a description of
 * the shape parameters that are not linear (so the same plugin that injects an effect in
 * simulation is a candidate cause when identifying measured data).
 *
 * A library exports (spml/abi.h explains the conventions shared with the learner ABI):
 *   int32_t spml_force_plugin_abi_version(void);            returns SPML_FORCE_PLUGIN_ABI_VERSION
 *   const spml_force_plugin* spml_force_plugin_get(int32_t i);  i-th plugin, NULL past the end
 * All callbacks may assume valid pointers; none may keep a pointer to the mjData.
 *
 * Version history: 1 - spmlForcePlugin, one plugin per library (spml_force_plugin()),
 * NULL-terminated key names. 2 - this layout (snake_case, several plugins per library,
 * typed key table, size_t error buffers, shape parameters). 3 - write_config, so a fitted
 * instance can be written back into an MJCF declaration (spml diagnose's extended model).
 *
 * Revisions add to a version without breaking it, so the version number stays and a library
 * built before keeps loading unchanged. A library of revision r >= 1 also exports
 *   int32_t spml_force_plugin_abi_revision(void);          returns the r it was built for
 * and its entries carry the members appended up to r; the host reads an appended member only
 * from a library that declares its revision (one without the symbol is revision 0, and its
 * shorter entries end at write_config). Revision 1: flags (SPML_FORCE_INDEPENDENT).
 */
#ifndef SPML_FORCE_PLUGIN_H
#define SPML_FORCE_PLUGIN_H

#include <mujoco/mujoco.h>

#include "spml/abi.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SPML_FORCE_PLUGIN_ABI_VERSION 3
#define SPML_FORCE_PLUGIN_ABI_REVISION 1   /* the newest revision this header describes (see above) */

/* flags (revision 1). INDEPENDENT: instances share no mutable state (no globals, no caches
 * between instances), so the host may call two instances from two threads at the same time;
 * one instance is never called from two threads at once. spml check-plugin tests the promise
 * (clause `independent`). Without it the host calls the plugin from one thread. */
#define SPML_FORCE_INDEPENDENT 1u

/* Where a shape parameter's search range is measured (see spml_shape_param). */
#define SPML_SHAPE_ABSOLUTE 0  /* lo..hi as given */
#define SPML_SHAPE_POSITION 1  /* lo..hi are fractions of the joint's observed position range */
#define SPML_SHAPE_SPEED    2  /* lo..hi are fractions of the joint's largest observed |velocity| */

/* A configuration key that shapes the force non-linearly (a band edge, a wavenumber, a
 * Stribeck velocity): what a search over it needs to know. */
typedef struct spml_shape_param {
  const char* key;      /* a key of config_keys; NULL ends the table */
  int32_t domain;       /* SPML_SHAPE_* */
  double lo, hi;        /* search range in that domain */
  int32_t log_scale;    /* 1: search log-uniformly (lo > 0) */
  int32_t integer;      /* 1: whole numbers only */
} spml_shape_param;

typedef struct spml_force_plugin {
  int32_t abi_version;              /* SPML_FORCE_PLUGIN_ABI_VERSION */
  const char* name;                 /* e.g. "friction_band": the word used to name causes */
  const char* summary;              /* one line, for listings and messages */
  const spml_config_key* config_keys;   /* keys besides type/joints, {NULL}-terminated */

  /* Creates an instance acting on the given joints (ids into m). keys/values are the
   * configuration from the MJCF, already checked against config_keys (types and bounds);
   * keys left out take their default. On error: return NULL and write a message (about the
   * values, without the element name) into error. */
  void* (*create)(const mjModel* m, const int* joints, int32_t njoint, const char* const* keys,
                  const char* const* values, int32_t nkv, char* error, size_t error_size);
  void (*destroy)(void* instance);

  /* Adds the effect's generalized force (length m->nv) into qfrc for the state in d. */
  void (*compute)(const void* instance, const mjModel* m, const mjData* d, mjtNum* qfrc);

  /* Optional (NULL if stateless): advance internal state over one step of length dt,
   * called after the integrator step with the new state in d. */
  void (*advance)(void* instance, const mjModel* m, const mjData* d, mjtNum dt);
  /* Optional: return internal state to its initial value. */
  void (*reset)(void* instance);

  /* The parameter vector: count, a name per entry, read and write. */
  int32_t (*nparam)(const void* instance);
  const char* (*param_name)(const void* instance, int32_t i);
  void (*get_params)(const void* instance, mjtNum* theta);
  void (*set_params)(void* instance, const mjtNum* theta);

  /* Optional (NULL if the force is not linear in its parameters): write R, an
   * m->nv x nparam row-major matrix with force = R(qpos, qvel) * theta. R arrives
   * zeroed by the host: write only the entries of the joints the instance acts on. */
  void (*regressor)(const void* instance, const mjModel* m, const mjtNum* qpos,
                    const mjtNum* qvel, mjtNum* R);

  /* Optional (NULL if none): the shape parameters, {NULL}-terminated. */
  const spml_shape_param* shape_params;

  /* Optional (NULL if it cannot): write into buf the configuration, as space-separated
   * key=value words without type/joints, that recreates this instance with its current
   * parameters (set_params included). Returns the length it needed (like snprintf); the
   * host retries with a larger buffer when that is >= size. */
  int32_t (*write_config)(const void* instance, char* buf, size_t size);

  /* Revision 1 (read only from a library that exports spml_force_plugin_abi_revision): */
  uint32_t flags;                   /* SPML_FORCE_* bits, 0 for none */
} spml_force_plugin;

#ifdef __cplusplus
}
#endif

#endif /* SPML_FORCE_PLUGIN_H */
