// Sequential and iterative semi-parametric learning (Riedel & Stulp, eqs. 3-6): the paper's
// core idea, for any two learners.
//
//   A-B      fit A on y; fit B on the residual y - A(x); predict A(x) + B(x)          (eqs. 3-5)
//   it-A-B   then, `iterations` times in all: refit A on y - B(x), B on y - A(x)     (eq. 6)
//
// The predictive variance is the sum of the parts' variances (either one alone when only
// one part has a variance): the parts are fitted to different targets and treated as
// independent.
#pragma once

#include <memory>
#include <string>

#include "spml/learners/learner.h"

namespace spml {

// Iterations of it-A-B when the config does not say (the paper: "a fixed number of times").
inline constexpr int kDefaultIterations = 3;

// A composed learner named `name` ("LLS-GP", "it-SVR-GP"); `iterative` selects it-A-B.
std::unique_ptr<Learner> make_composition(std::string name, std::unique_ptr<Learner> a, std::unique_ptr<Learner> b,
                                          bool iterative);

// Splits "A-B" or "it-A-B" into parts for which `known(part)` is true; false if none fits.
// Learner names may contain '-' ("GP-SepKer"), so every split point is tried, left to right.
template <class Known>
bool parse_composition(const std::string& name, Known known, std::string* a, std::string* b, bool* iterative) {
  std::string rest = name;
  *iterative = rest.rfind("it-", 0) == 0;
  if (*iterative) rest = rest.substr(3);
  for (size_t pos = rest.find('-'); pos != std::string::npos; pos = rest.find('-', pos + 1)) {
    const std::string first = rest.substr(0, pos), second = rest.substr(pos + 1);
    if (known(first) && known(second)) {
      *a = first;
      *b = second;
      return true;
    }
  }
  return false;
}

}  // namespace spml
