// Entry points of the built-in learner library (spml/learner.h).
#include <cstdlib>
#include <stdexcept>
#include <vector>

#include "learners.h"

namespace spml::builtin {

namespace {
const std::vector<spml_learner>& all() {
  static const std::vector<spml_learner> list = [] {
    std::vector<spml_learner> v{lls_learner(), svr_learner(), lls_prior_learner(), lls_simulated_learner()};
    add_gaussian_process_learners(v);
    return v;
  }();
  return list;
}
}  // namespace

}  // namespace spml::builtin

SPML_EXPORT_LEARNERS(spml::builtin::all().data(), spml::builtin::all().size())
