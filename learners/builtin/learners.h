// The learners of the built-in library (named as the paper's table rows).
#pragma once

#include "spml/learner_adapter.h"

namespace spml::builtin {
using namespace spml::adapter;

spml_learner lls_learner();
spml_learner lls_prior_learner();
spml_learner lls_simulated_learner();
spml_learner svr_learner();
// GP, GP-SepKer, SPGP, SPGP-SepKer, SPGP-from-zeros, SPGP-from-ones
void add_gaussian_process_learners(std::vector<spml_learner>& out);

}  // namespace spml::builtin
