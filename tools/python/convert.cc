#include "convert.h"

#include <filesystem>

namespace spml::py {

void rethrow_if_missing(const std::vector<std::string>& inputs, const std::exception& e) {
  std::error_code ec;
  for (const auto& p : inputs)
    if (!p.empty() && !std::filesystem::exists(p, ec)) throw MissingFile(e.what());
}

namespace {

using Array = pb::array_t<double, pb::array::c_style | pb::array::forcecast>;

Array as_array(const pb::handle& obj, const std::string& what, int ndim) {
  Array a = Array::ensure(obj);
  if (!a) {
    PyErr_Clear();
    throw BadArgument(what + ": expected an array of numbers, got " + std::string(pb::str(pb::type::of(obj))));
  }
  if (a.ndim() != ndim)
    throw BadArgument(what + ": expected a " + std::to_string(ndim) + "-D array, got " + std::to_string(a.ndim()) + "-D");
  return a;
}

}  // namespace

RowMatrix to_matrix(const pb::handle& obj, const std::string& what) {
  const Array a = as_array(obj, what, 2);
  return Eigen::Map<const RowMatrix>(a.data(), a.shape(0), a.shape(1));
}

Eigen::VectorXd to_vector(const pb::handle& obj, const std::string& what) {
  const Array a = as_array(obj, what, 1);
  return Eigen::Map<const Eigen::VectorXd>(a.data(), a.shape(0));
}

pb::array_t<double> to_numpy(const RowMatrix& m) {
  pb::array_t<double> a({m.rows(), m.cols()});
  std::copy(m.data(), m.data() + m.size(), a.mutable_data());
  return a;
}

pb::array_t<double> to_numpy(const Eigen::VectorXd& v) {
  pb::array_t<double> a(v.size());
  std::copy(v.data(), v.data() + v.size(), a.mutable_data());
  return a;
}

pb::array_t<double> to_numpy(const Eigen::MatrixXd& m) { return to_numpy(RowMatrix(m)); }

}  // namespace spml::py
