/* What the two spml plugin ABIs (learners: spml/learner.h, force plugins:
 * spml/force_plugin.h) share, so that both read alike:
 *
 *   - a library exports  int32_t <abi>_abi_version(void)  and
 *                        const <abi>* <abi>_get(int32_t i)   (the i-th entry, NULL past the end),
 *     so one library may provide several learners or several force plugins;
 *   - every entry starts with  int32_t abi_version; const char* name; const char* summary;
 *   - configuration keys are described by a table of spml_config_key ending with {NULL};
 *     the host checks every value against its type and bounds before calling the plugin;
 *   - a callback that can fail writes its message into (char* error, size_t error_size).
 */
#ifndef SPML_ABI_H
#define SPML_ABI_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(_WIN32)
#define SPML_EXPORT __declspec(dllexport)
#else
#define SPML_EXPORT __attribute__((visibility("default")))
#endif

/* Value types of configuration keys. */
#define SPML_VALUE_NUMBER   1  /* one finite number */
#define SPML_VALUE_INTEGER  2  /* one whole number */
#define SPML_VALUE_NUMBERS  3  /* comma-separated finite numbers (e.g. one per joint) */
#define SPML_VALUE_TEXT     4  /* any text without spaces */

typedef struct spml_config_key {
  const char* name;           /* NULL ends the table */
  int32_t type;               /* SPML_VALUE_* */
  double min, max;            /* inclusive bounds of every number (use -HUGE_VAL/HUGE_VAL for none) */
  const char* default_value;  /* text of the default; NULL: a force plugin's key is required,
                                 a learner's default is worked out from the data */
  const char* help;           /* one line */
} spml_config_key;

#ifdef __cplusplus
}
#endif

#endif /* SPML_ABI_H */
