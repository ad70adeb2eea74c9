#include "spml/envs/parametric_model.h"

#include "spml/envs/planar_arm3.h"
#include "spml/envs/scenarios.h"

namespace spml {
namespace {

int require_column(const Split& s, const std::string& column, const std::string& model) {
  int i = s.x_index(column);
  if (i < 0) throw DatasetError("split '" + s.name + "': model '" + model + "' needs input column '" + column + "'");
  return i;
}

class ToyModel : public ParametricModel {
 public:
  explicit ToyModel(const Split& s) : x_(require_column(s, "x", "toy")) {}
  std::string name() const override { return "toy"; }
  int num_params() const override { return 4; }
  int num_outputs() const override { return 1; }
  Eigen::MatrixXd features(const Eigen::Ref<const Eigen::RowVectorXd>& x) const override {
    return toy_features(x[x_]).transpose();
  }
 private:
  int x_;
};

class ViaModel : public ParametricModel {
 public:
  explicit ViaModel(const Split& s)
      : d_(require_column(s, "deflection", "via")), r_(require_column(s, "deflection_rate", "via")) {}
  std::string name() const override { return "via"; }
  int num_params() const override { return 2; }
  int num_outputs() const override { return 1; }
  Eigen::MatrixXd features(const Eigen::Ref<const Eigen::RowVectorXd>& x) const override {
    Eigen::MatrixXd phi(1, 2);
    phi << x[d_], x[r_];
    return phi;
  }
 private:
  int d_, r_;
};

class PlanarArm3Model : public ParametricModel {
 public:
  explicit PlanarArm3Model(const Split& s) {
    const char* joints[3] = {"joint0", "joint1", "joint2"};
    for (int j = 0; j < 3; ++j) {
      q_[j] = require_column(s, std::string("q:") + joints[j], "planar_arm3");
      qd_[j] = require_column(s, std::string("qd:") + joints[j], "planar_arm3");
      qdd_[j] = require_column(s, std::string("qdd:") + joints[j], "planar_arm3");
    }
  }
  std::string name() const override { return "planar_arm3"; }
  int num_params() const override { return planar_arm3::kParams; }
  int num_outputs() const override { return 3; }
  Eigen::MatrixXd features(const Eigen::Ref<const Eigen::RowVectorXd>& x) const override {
    Eigen::Vector3d q, qd, qdd;
    for (int j = 0; j < 3; ++j) { q[j] = x[q_[j]]; qd[j] = x[qd_[j]]; qdd[j] = x[qdd_[j]]; }
    return planar_arm3::regressor(q, qd, qdd);
  }
 private:
  int q_[3], qd_[3], qdd_[3];
};

}  // namespace

Eigen::MatrixXd ParametricModel::stacked(const RowMatrix& X) const {
  const Eigen::Index N = X.rows();
  const int O = num_outputs();
  Eigen::MatrixXd A(N * O, num_params());
  for (Eigen::Index i = 0; i < N; ++i) {
    Eigen::MatrixXd phi = features(X.row(i));
    for (int o = 0; o < O; ++o) A.row(o * N + i) = phi.row(o);
  }
  return A;
}

Eigen::VectorXd ParametricModel::stacked_targets(const RowMatrix& Y) {
  Eigen::VectorXd b(Y.size());
  for (Eigen::Index o = 0; o < Y.cols(); ++o) b.segment(o * Y.rows(), Y.rows()) = Y.col(o);
  return b;
}

RowMatrix ParametricModel::predict(const RowMatrix& X, const Eigen::VectorXd& theta) const {
  RowMatrix Y(X.rows(), num_outputs());
  for (Eigen::Index i = 0; i < X.rows(); ++i) Y.row(i) = (features(X.row(i)) * theta).transpose();
  return Y;
}

std::unique_ptr<ParametricModel> make_parametric_model(const Dataset& ds, const Split& layout) {
  const std::string& n = ds.model.name;
  if (n == "toy") return std::make_unique<ToyModel>(layout);
  if (n == "via") return std::make_unique<ViaModel>(layout);
  if (n == "planar_arm3") return std::make_unique<PlanarArm3Model>(layout);
  throw DatasetError("no parametric model '" + n + "' (known: toy, via, planar_arm3)");
}

}  // namespace spml
