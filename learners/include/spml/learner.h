/* spml learner plugin ABI, version 2 (revision 1).
 *
 * A learner is a shared library that exports two C functions (spml/abi.h explains the
 * conventions shared with the force-plugin ABI):
 *
 *   int32_t spml_learner_abi_version(void);          returns SPML_LEARNER_ABI_VERSION
 *   const spml_learner* spml_learner_get(int32_t i); i-th learner it provides, NULL past the end
 *
 * One library may provide several learners (the built-in library provides LLS, SVR, GP, ...).
 * The host (spml bench) refuses a library whose version differs or that lacks either symbol,
 * naming the file. Everything crosses the boundary as plain C data; no C++ types, no
 * ownership transfer except the opaque state returned by fit() and released by destroy().
 *
 * Layout conventions
 *   x   rows x inputs, row-major.       y   rows x outputs, row-major.
 *   phi the parametric model's regressor, (outputs*rows) x params, row-major, output-major:
 *       row o*rows + i holds phi_o(x_i), so that the model predicts y[i][o] = phi row . theta.
 *   variance: the predictive variance of an observation (noise included), rows x outputs.
 *
 * Version history: 1 - config_keys was a comma-separated string. 2 - config_keys is a typed
 * spml_config_key table (the host checks every --set value before any fit), export macro
 * SPML_EXPORT from spml/abi.h.
 *
 * Revisions add to a version without breaking it, so the version number stays: a revision
 * appends optional members at the end of spml_learner and guards each with a flag. The host
 * reads an appended member only when its flag is set, so a library built against an older
 * revision (whose entries end earlier) keeps loading and working unchanged.
 *   2.1 - SPML_LEARNER_PROGRESS and fit_progress: a fit that reports how far it has come.
 */
#ifndef SPML_LEARNER_H
#define SPML_LEARNER_H

#include <stddef.h>
#include <stdint.h>

#include "spml/abi.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SPML_LEARNER_ABI_VERSION 2
#define SPML_LEARNER_ABI_REVISION 1   /* the newest revision this header describes (see above) */

/* flags */
#define SPML_LEARNER_USES_MODEL      1u  /* reads phi/theta; the host must supply a parametric model */
#define SPML_LEARNER_VARIANCE        2u  /* predict() fills the variance */
#define SPML_LEARNER_PARAMETRIC      4u  /* purely parametric fit: may be the first stage of "A-B" */
#define SPML_LEARNER_NONPARAMETRIC   8u  /* ignores phi: may be the residual stage of "A-B" */
#define SPML_LEARNER_DETERMINISTIC  16u  /* ignores the seed: repetitions are identical */
#define SPML_LEARNER_NEEDS_PRIOR    32u  /* fit() fails without the model's prior coefficients */
#define SPML_LEARNER_NEEDS_TRUTH    64u  /* fit() fails without the model's true coefficients */
#define SPML_LEARNER_PROGRESS      128u  /* revision 1: the entry has fit_progress (the host reads it only then) */

/* Revision 1: called by fit_progress, on the thread that called it, with the fraction of the
 * fit done so far - in [0, 1], never smaller than the fraction of an earlier call - and a short
 * text naming the stage ("subset fit", "epochs"; "" when there is nothing to say; the host
 * copies it, so it need only live during the call). The fraction is a best estimate of the
 * fit's work, so that elapsed / fraction foretells the fit's time; it need not reach 1
 * (fit_progress returning is what ends the fit). */
typedef void (*spml_learner_progress)(void* context, double fraction, const char* stage);

typedef struct spml_learner_data {
  int64_t rows;
  int32_t inputs;
  int32_t outputs;
  const double* x;      /* rows*inputs */
  const double* y;      /* rows*outputs; NULL in predict() */
  int32_t params;       /* columns of phi; 0 when there is no parametric model */
  const double* phi;    /* (outputs*rows)*params, or NULL */
} spml_learner_data;

typedef struct spml_learner_model {
  int32_t params;
  const char* const* names;  /* params names */
  const double* prior;       /* params values, or NULL when the dataset has none */
  const double* truth;       /* params values, or NULL (measured data) */
} spml_learner_model;

typedef struct spml_learner_config {
  int32_t count;
  const char* const* keys;
  const char* const* values;
  uint64_t seed;
} spml_learner_config;

typedef struct spml_learner {
  int32_t abi_version;       /* SPML_LEARNER_ABI_VERSION */
  const char* name;          /* as in the paper's tables, e.g. "SPGP-SepKer" */
  const char* summary;       /* one line */
  uint32_t flags;
  const spml_config_key* config_keys;   /* keys fit() accepts, {NULL}-terminated (NULL: none) */

  /* Fits and returns an opaque state, or NULL after writing a message into error. */
  void* (*fit)(const spml_learner_data* train, const spml_learner_model* model,
               const spml_learner_config* config, char* error, size_t error_size);
  /* Writes rows*outputs means and, when variance is not NULL and the learner has the
   * SPML_LEARNER_VARIANCE flag, rows*outputs variances. Returns 0, or non-zero after
   * writing a message into error. */
  int (*predict)(void* state, const spml_learner_data* query, double* mean, double* variance,
                 char* error, size_t error_size);
  /* Optional (may be NULL): warnings about the fit, e.g. an optimiser that stopped
   * abnormally or a Cholesky that needed jitter; "" when there is nothing to report.
   * The string lives as long as the state. */
  const char* (*notes)(void* state);
  /* Optional (may be NULL): writes the fitted parametric coefficients, returns how many
   * (0 when the learner has none). */
  int32_t (*coefficients)(void* state, double* theta, int32_t capacity);
  void (*destroy)(void* state);

  /* Revision 1 (read only when flags has SPML_LEARNER_PROGRESS). As fit, calling
   * progress(context, fraction, stage) now and then while it works. It must fit exactly as fit
   * does (the same state, the same predictions for the same seed); progress is never NULL. */
  void* (*fit_progress)(const spml_learner_data* train, const spml_learner_model* model,
                        const spml_learner_config* config, spml_learner_progress progress, void* context,
                        char* error, size_t error_size);
} spml_learner;

#ifdef __cplusplus
}
#define SPML_LEARNER_EXTERN_C extern "C"
#else
#define SPML_LEARNER_EXTERN_C
#endif

/* The two entry points, for a library whose learners are `count` entries from `table` (an
 * array, or any expression giving a pointer to the first: C or C++), e.g.
 *   SPML_EXPORT_LEARNERS(my_learners, 2)      SPML_EXPORT_LEARNERS(list().data(), list().size())
 * The twin of SPML_EXPORT_FORCE_PLUGIN; a helper only, the ABI is the two functions. */
#define SPML_EXPORT_LEARNERS(table, count)                                                                   \
  SPML_LEARNER_EXTERN_C SPML_EXPORT int32_t spml_learner_abi_version(void) { return SPML_LEARNER_ABI_VERSION; } \
  SPML_LEARNER_EXTERN_C SPML_EXPORT const spml_learner* spml_learner_get(int32_t i) {                          \
    return i >= 0 && (int64_t)i < (int64_t)(count) ? &(table)[i] : NULL;                                        \
  }

#endif /* SPML_LEARNER_H */
