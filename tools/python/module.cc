// The `_spml` extension module: the parts are bound in their own files; here spml's C++
// exceptions get their Python faces, each with spml's message unchanged.
#include "convert.h"
#include "spml/learners/learner.h"
#include "spml/plugin_loader.h"
#include "spml/version.h"

namespace spml::py {
namespace {

// The most specific class first: a missing input file, a bad argument or dataset (the
// caller can fix the value), a plugin that cannot load or a learner that failed (the run
// went wrong), anything else.
void translate(std::exception_ptr p) {
  try {
    if (p) std::rethrow_exception(p);
  } catch (const MissingFile& e) {
    PyErr_SetString(PyExc_FileNotFoundError, e.what());
  } catch (const BadArgument& e) {
    PyErr_SetString(PyExc_ValueError, e.what());
  } catch (const DatasetError& e) {
    PyErr_SetString(PyExc_ValueError, e.what());
  } catch (const std::invalid_argument& e) {
    PyErr_SetString(PyExc_ValueError, e.what());
  } catch (const PluginError& e) {
    PyErr_SetString(PyExc_RuntimeError, e.what());
  } catch (const LearnerError& e) {
    PyErr_SetString(PyExc_RuntimeError, e.what());
  }
}

}  // namespace
}  // namespace spml::py

PYBIND11_MODULE(_spml, m) {
  m.doc() = "spml's C++ core; use the `spml` package, which wraps it";
  m.attr("version") = SPML_VERSION;
  pybind11::register_exception_translator(&spml::py::translate);
  spml::py::bind_dataset(m);
  spml::py::bind_learners(m);
  spml::py::bind_models(m);
  spml::py::bind_diagnose(m);
}
