// What every part of the Python module shares: NumPy <-> Eigen conversions whose errors name
// the argument, the Python faces of spml's exceptions, and the module's registration hooks.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "spml/dataset.h"

namespace spml::py {

namespace pb = pybind11;

// A file named as input does not exist: raised as FileNotFoundError with spml's message.
class MissingFile : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// A value the caller passed is wrong (an unknown learner, a config value out of bounds):
// raised as ValueError.
class BadArgument : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Throws MissingFile with e's message when one of `inputs` does not exist.
void rethrow_if_missing(const std::vector<std::string>& inputs, const std::exception& e);

// Runs `body`; when it throws and one of `inputs` does not exist, the error becomes a
// MissingFile with the same message (so Python sees FileNotFoundError naming the file).
template <class Body>
auto naming_missing_files(const std::vector<std::string>& inputs, Body body) -> decltype(body()) {
  try {
    return body();
  } catch (const std::exception& e) {
    rethrow_if_missing(inputs, e);
    throw;
  }
}

// A float64 matrix from any array-like (converted); `what` names it in errors ("X", "phi").
RowMatrix to_matrix(const pb::handle& obj, const std::string& what);
// A float64 vector from any 1-D array-like.
Eigen::VectorXd to_vector(const pb::handle& obj, const std::string& what);
pb::array_t<double> to_numpy(const RowMatrix& m);
pb::array_t<double> to_numpy(const Eigen::VectorXd& v);
pb::array_t<double> to_numpy(const Eigen::MatrixXd& m);

// Force-plugin libraries or folders added to the process's search path (--plugin-path).
void add_plugin_path(const std::string& path);
void add_plugin_paths(const std::vector<std::string>& paths);

// Registration of each part (one file each), called by module.cc.
void bind_dataset(pb::module_& m);
void bind_learners(pb::module_& m);
void bind_models(pb::module_& m);
void bind_diagnose(pb::module_& m);

}  // namespace spml::py
