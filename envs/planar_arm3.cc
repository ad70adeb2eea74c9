#include "spml/envs/planar_arm3.h"

#include <cmath>
#include <stdexcept>

namespace spml::planar_arm3 {
namespace {

// Parameter indices in the paper's order.
enum : int { FS1, FS2, FS3, FV1, FV2, FV3, IA2, IA3, MX3, MXR1, MXR2, MY1, MY2, MY3, ZZ3, ZZR1, ZZR2 };
constexpr int kZZ[3] = {ZZR1, ZZR2, ZZ3}, kMX[3] = {MXR1, MXR2, MX3}, kMY[3] = {MY1, MY2, MY3};
constexpr int kFV[3] = {FV1, FV2, FV3}, kFS[3] = {FS1, FS2, FS3};

using Row = Eigen::Matrix<double, 1, kParams>;

// Rotate a planar vector (given as two coefficient rows) by angle q: R(q) * v.
void rotate(double q, const Row& x, const Row& y, Row& ox, Row& oy) {
  double c = std::cos(q), s = std::sin(q);
  ox = c * x - s * y;
  oy = s * x + c * y;
}

}  // namespace

const std::vector<std::string>& param_names() {
  static const std::vector<std::string> names = {"FS1", "FS2", "FS3", "FV1", "FV2", "FV3", "IA2", "IA3", "MX3",
                                                 "MXR1", "MXR2", "MY1", "MY2", "MY3", "ZZ3", "ZZR1", "ZZR2"};
  return names;
}

Eigen::Matrix<double, 3, kParams> regressor(const Eigen::Vector3d& q, const Eigen::Vector3d& qd,
                                            const Eigen::Vector3d& qdd, const Geometry& geo) {
  // After regrouping, each link behaves as a massless body with first moments (MX, MY)
  // and inertia ZZ about its joint, so only the origin accelerations are needed.
  const double L[2] = {geo.L1, geo.L2};
  double w[3], a[3], ax[3], ay[3];
  {
    // Gravity as an upward acceleration of the base, expressed in link 0's frame.
    double bx = 0.0, by = geo.g;
    for (int j = 0; j < 3; ++j) {
      w[j] = (j ? w[j - 1] : 0.0) + qd[j];
      a[j] = (j ? a[j - 1] : 0.0) + qdd[j];
      double c = std::cos(q[j]), s = std::sin(q[j]);
      ax[j] = c * bx + s * by;   // R(q)^T * b
      ay[j] = -s * bx + c * by;
      if (j < 2) {
        bx = ax[j] - L[j] * w[j] * w[j];
        by = ay[j] + L[j] * a[j];
      }
    }
  }
  Eigen::Matrix<double, 3, kParams> Phi = Eigen::Matrix<double, 3, kParams>::Zero();
  Row fx = Row::Zero(), fy = Row::Zero(), n = Row::Zero();   // wrench from the links beyond
  for (int j = 2; j >= 0; --j) {
    Row Fx = Row::Zero(), Fy = Row::Zero(), N = Row::Zero();
    Fx[kMX[j]] = -w[j] * w[j];
    Fx[kMY[j]] = -a[j];
    Fy[kMX[j]] = a[j];
    Fy[kMY[j]] = -w[j] * w[j];
    N[kZZ[j]] = a[j];
    N[kMX[j]] = ay[j];
    N[kMY[j]] = -ax[j];
    Row cx = Row::Zero(), cy = Row::Zero();
    if (j < 2) rotate(q[j + 1], fx, fy, cx, cy);   // child's force in this link's frame
    Row nj = N + n;
    if (j < 2) nj += L[j] * cy;
    fx = Fx + cx;
    fy = Fy + cy;
    n = nj;
    Phi.row(j) = n;
    Phi(j, kFV[j]) += qd[j];
    Phi(j, kFS[j]) += qd[j] > 0 ? 1.0 : (qd[j] < 0 ? -1.0 : 0.0);
    if (j == 1) Phi(j, IA2) += qdd[j];
    if (j == 2) Phi(j, IA3) += qdd[j];
  }
  return Phi;
}

Geometry geometry(const mjModel* m) {
  if (m->nbody != 4 || m->njnt != 3) throw std::runtime_error("planar_arm3: expected 3 bodies with one hinge each");
  Geometry geo;
  geo.L1 = m->body_pos[3 * 2 + 0];
  geo.L2 = m->body_pos[3 * 3 + 0];
  geo.g = -m->opt.gravity[2];
  return geo;
}

Eigen::Matrix<double, kParams, 1> coefficients(const mjModel* m) {
  Geometry geo = geometry(m);
  double mass[3], mx[3], my[3], zz[3];
  for (int j = 0; j < 3; ++j) {
    int b = j + 1;
    const double* c = m->body_ipos + 3 * b;
    mass[j] = m->body_mass[b];
    mx[j] = mass[j] * c[0];
    my[j] = mass[j] * c[2];   // the plane's y is the body's z
    // Inertia about the joint axis (body y): principal inertia along y (inertia frame
    // assumed aligned, as in the shipped models) plus the parallel-axis term.
    zz[j] = m->body_inertia[3 * b + 1] + mass[j] * (c[0] * c[0] + c[2] * c[2]);
  }
  Eigen::Matrix<double, kParams, 1> th = Eigen::Matrix<double, kParams, 1>::Zero();
  double m23 = mass[1] + mass[2];
  th[ZZR1] = zz[0] + m->dof_armature[0] + geo.L1 * geo.L1 * m23;
  th[MXR1] = mx[0] + geo.L1 * m23;
  th[MY1] = my[0];
  th[ZZR2] = zz[1] + geo.L2 * geo.L2 * mass[2];
  th[MXR2] = mx[1] + geo.L2 * mass[2];
  th[MY2] = my[1];
  th[ZZ3] = zz[2];
  th[MX3] = mx[2];
  th[MY3] = my[2];
  th[IA2] = m->dof_armature[1];
  th[IA3] = m->dof_armature[2];
  for (int j = 0; j < 3; ++j) {
    th[kFV[j]] = m->dof_damping[j];
    th[kFS[j]] = m->dof_frictionloss[j];
  }
  return th;
}

}  // namespace spml::planar_arm3

#include "spml/envs/parametric_model.h"

namespace spml {
namespace {
// The paper's 17-coefficient regressor of the planar 3-link arm (SimDyn), on the columns
// q:/qd:/qdd:joint0..2 with outputs tau:joint0..2.
class PlanarArm3Model : public RowwiseModel {
 public:
  explicit PlanarArm3Model(const Split& s) {
    for (int j = 0; j < 3; ++j) {
      const std::string joint = "joint" + std::to_string(j);
      q_[j] = require_column(s, "q:" + joint, "planar_arm3");
      qd_[j] = require_column(s, "qd:" + joint, "planar_arm3");
      qdd_[j] = require_column(s, "qdd:" + joint, "planar_arm3");
    }
  }
  std::string name() const override { return "planar_arm3"; }
  Eigen::MatrixXd features(const Eigen::Ref<const Eigen::RowVectorXd>& x) const override {
    Eigen::Vector3d q, qd, qdd;
    for (int j = 0; j < 3; ++j) {
      q[j] = x[q_[j]];
      qd[j] = x[qd_[j]];
      qdd[j] = x[qdd_[j]];
    }
    return planar_arm3::regressor(q, qd, qdd);
  }
 private:
  int q_[3], qd_[3], qdd_[3];
};
const bool kArmRegistered = register_parametric_model("planar_arm3", [](const Dataset& ds, const Split& s) {
  require_outputs(s, {"tau:joint0", "tau:joint1", "tau:joint2"}, "planar_arm3");
  auto m = std::make_unique<PlanarArm3Model>(s);
  take_coefficients(*m, ds, planar_arm3::kParams, 3);
  return std::unique_ptr<ParametricModel>(std::move(m));
});
}  // namespace
}  // namespace spml
