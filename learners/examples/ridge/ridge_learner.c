/* Ridge regression on the parametric model's features: theta = (A^T A + lambda I)^-1 A^T y
 * over the stacked regressor. A complete spml learner in plain C, to show the ABI; the
 * normal equations are small (params x params), so a plain Cholesky does. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "spml/learner.h"

typedef struct {
  int32_t params, inputs, outputs;
  double* theta;
} ridge_state;

/* 1 when all n values are finite: a fit on data holding NaN must be refused, not return NaN. */
static int all_finite(const double* v, int64_t n) {
  for (int64_t i = 0; i < n; ++i)
    if (!isfinite(v[i])) return 0;
  return 1;
}

static void* ridge_fit(const spml_learner_data* d, const spml_learner_model* model, const spml_learner_config* config,
                       char* error, size_t error_size) {
  (void)model;
  if (!d->phi || d->params <= 0) {
    snprintf(error, error_size, "Ridge needs the dataset's parametric model");
    return NULL;
  }
  if (!all_finite(d->x, d->rows * d->inputs) || !all_finite(d->y, d->rows * d->outputs) ||
      !all_finite(d->phi, d->rows * d->outputs * d->params)) {
    snprintf(error, error_size, "training data hold NaN or Inf values");
    return NULL;
  }
  double lambda = NAN; /* the host fills the table's default in; checked against its bounds */
  for (int32_t i = 0; i < config->count; ++i)
    if (strcmp(config->keys[i], "lambda") == 0) lambda = strtod(config->values[i], NULL);
  if (isnan(lambda)) {
    snprintf(error, error_size, "config 'lambda' missing");
    return NULL;
  }
  const int32_t M = d->params;
  const int64_t rows = d->rows * d->outputs;
  double* A = calloc((size_t)(M * M), sizeof(double));
  double* b = calloc((size_t)M, sizeof(double));
  ridge_state* s = malloc(sizeof *s);
  if (!A || !b || !s) {
    snprintf(error, error_size, "out of memory");
    free(A), free(b), free(s);
    return NULL;
  }
  for (int64_t r = 0; r < rows; ++r) {
    const double* phi = d->phi + r * M;
    const int64_t o = r / d->rows, i = r % d->rows;
    const double y = d->y[i * d->outputs + o];
    for (int32_t j = 0; j < M; ++j) {
      b[j] += phi[j] * y;
      for (int32_t k = 0; k <= j; ++k) A[j * M + k] += phi[j] * phi[k];
    }
  }
  for (int32_t j = 0; j < M; ++j) A[j * M + j] += lambda * (double)rows;
  /* Cholesky A = L L^T in place (lower), then two triangular solves. */
  for (int32_t j = 0; j < M; ++j) {
    for (int32_t k = 0; k < j; ++k) A[j * M + j] -= A[j * M + k] * A[j * M + k];
    if (A[j * M + j] <= 0) {
      snprintf(error, error_size, "normal equations not positive definite; raise lambda");
      free(A), free(b), free(s);
      return NULL;
    }
    A[j * M + j] = sqrt(A[j * M + j]);
    for (int32_t i = j + 1; i < M; ++i) {
      for (int32_t k = 0; k < j; ++k) A[i * M + j] -= A[i * M + k] * A[j * M + k];
      A[i * M + j] /= A[j * M + j];
    }
  }
  for (int32_t i = 0; i < M; ++i) {
    for (int32_t k = 0; k < i; ++k) b[i] -= A[i * M + k] * b[k];
    b[i] /= A[i * M + i];
  }
  for (int32_t i = M - 1; i >= 0; --i) {
    for (int32_t k = i + 1; k < M; ++k) b[i] -= A[k * M + i] * b[k];
    b[i] /= A[i * M + i];
  }
  free(A);
  s->params = M;
  s->inputs = d->inputs;
  s->outputs = d->outputs;
  s->theta = b;
  return s;
}

static int ridge_predict(void* state, const spml_learner_data* q, double* mean, double* variance, char* error,
                         size_t error_size) {
  (void)variance;
  const ridge_state* s = state;
  if (q->inputs != s->inputs || q->outputs != s->outputs) {
    snprintf(error, error_size, "query has %d inputs and %d outputs, the fit had %d and %d", q->inputs, q->outputs,
             s->inputs, s->outputs);
    return 1;
  }
  if (!q->phi || q->params != s->params) {
    snprintf(error, error_size, "query regressor has %d columns, expected %d", q->params, s->params);
    return 1;
  }
  for (int64_t r = 0; r < q->rows * q->outputs; ++r) {
    double v = 0;
    for (int32_t j = 0; j < s->params; ++j) v += q->phi[r * s->params + j] * s->theta[j];
    mean[(r % q->rows) * q->outputs + r / q->rows] = v;
  }
  return 0;
}

static int32_t ridge_coefficients(void* state, double* theta, int32_t capacity) {
  const ridge_state* s = state;
  for (int32_t j = 0; j < capacity && j < s->params; ++j) theta[j] = s->theta[j];
  return s->params;
}

static void ridge_destroy(void* state) {
  ridge_state* s = state;
  free(s->theta);
  free(s);
}

/* The host checks --set values against this table (type and bounds) before any fit. */
static const spml_config_key ridge_keys[] = {
    {"lambda", SPML_VALUE_NUMBER, 0.0, HUGE_VAL, "1e-6", "penalty per row on |theta|^2"},
    {NULL, 0, 0, 0, NULL, NULL}};

static const spml_learner ridge = {
    SPML_LEARNER_ABI_VERSION, "Ridge", "ridge regression on the model features (example)",
    SPML_LEARNER_USES_MODEL | SPML_LEARNER_PARAMETRIC | SPML_LEARNER_DETERMINISTIC, ridge_keys,
    ridge_fit, ridge_predict, NULL, ridge_coefficients, ridge_destroy};

/* spml_learner_abi_version() and spml_learner_get(i) over a table of one learner. */
SPML_EXPORT_LEARNERS(&ridge, 1)
