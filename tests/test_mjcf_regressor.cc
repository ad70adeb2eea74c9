#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <fstream>
#include <random>

#include "spml/envs/mjcf_regressor.h"
#include "spml/envs/planar_arm3.h"
#include "spml/envs/scenarios.h"
#include "test_util.h"

using namespace spml;

namespace {

// A branched tree: a torso on a slide joint carrying two arms, one of them two links long,
// with tilted axes, off-diagonal inertia (rotated principal axes), damping and armature.
const char* kBranched = R"(<mujoco model="branched">
  <option gravity="0.3 -0.2 -9.81"/>
  <worldbody>
    <body name="torso">
      <joint name="lift" type="slide" axis="0 0 1" damping="3" armature="0.2"/>
      <inertial pos="0.01 0.02 0.03" quat="0.9 0.1 0.2 0.3" mass="4" diaginertia="0.3 0.2 0.25"/>
      <body name="left" pos="0.2 0 0">
        <joint name="l1" type="hinge" axis="0 1 0.2" damping="0.5" armature="0.05"/>
        <inertial pos="0.3 0.01 0" quat="0.8 0 0.3 0.1" mass="2" diaginertia="0.05 0.04 0.03"/>
        <body name="left2" pos="0.5 0 0" quat="0.95 0.1 0 0.2">
          <joint name="l2" type="hinge" axis="1 0 0" damping="0.2"/>
          <inertial pos="0.1 0.05 -0.02" mass="1" diaginertia="0.01 0.012 0.008"/>
        </body>
      </body>
      <body name="right" pos="-0.2 0 0">
        <joint name="r1" type="hinge" axis="0 0 1" armature="0.1"/>
        <joint name="r2" type="slide" axis="1 0 0" damping="1"/>
        <inertial pos="-0.2 0 0.05" mass="1.5" diaginertia="0.02 0.03 0.04"/>
      </body>
    </body>
  </worldbody>
</mujoco>)";

double max_inverse_error(const std::string& file, bool attach_plugins) {
  MjcfRegressor reg(file);
  auto ws = reg.workspace();
  ModelPtr m = load_mjcf(file);
  DataPtr d = make_data(m.get());
  ForceEffects fx(m.get(), file);
  if (attach_plugins) fx.attach();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  double worst = 0;
  const int n = m->njnt;
  for (int trial = 0; trial < 100; ++trial) {
    Eigen::VectorXd q(n), qd(n), qdd(n);
    for (int j = 0; j < n; ++j) {
      q[j] = d->qpos[j] = 2 * u(rng);
      qd[j] = d->qvel[j] = 3 * u(rng);
      qdd[j] = d->qacc[j] = 10 * u(rng);
    }
    mj_inverse(m.get(), d.get());
    Eigen::VectorXd tau = reg.evaluate(ws, q, qd, qdd) * reg.model_params();
    for (int i = 0; i < m->nv; ++i) worst = std::max(worst, std::fabs(tau[i] - d->qfrc_inverse[i]));
  }
  return worst;
}

}  // namespace

TEST(MjcfRegressor, TimesModelParametersEqualsMjInverse) {
  auto dir = test::temp_dir("regressor");
  auto branched = (dir / "branched.xml").string();
  std::ofstream(branched) << kBranched;
  EXPECT_LT(max_inverse_error(mjcf_path("planar_arm3.xml"), false), 1e-8);
  EXPECT_LT(max_inverse_error(branched, false), 1e-8);
  // VIA: the tendon's spring and damper are columns; its stick-slip plugin is nonlinear and
  // not attached here, so mj_inverse sees the same forces.
  EXPECT_LT(max_inverse_error(mjcf_path("via_joint.xml"), false), 1e-8);
  // SimDyn-Gl: band and ripple are linear plugins, whose columns the regressor appends.
  EXPECT_LT(max_inverse_error(mjcf_path("planar_arm3_gl.xml"), true), 1e-8);
  std::filesystem::remove_all(dir);
}

TEST(MjcfRegressor, PluginColumnsAreAppended) {
  MjcfRegressor reg(mjcf_path("planar_arm3_gl.xml"));
  const auto& names = reg.param_names();
  EXPECT_NE(std::find(names.begin(), names.end(), "plugin:band.joint0.level"), names.end());
  EXPECT_NE(std::find(names.begin(), names.end(), "plugin:ripple.joint2.h8.cos"), names.end());
}

// The arm without offsets has the paper's 17 base parameters, spanning the same column space
// as the paper's analytic regressor.
TEST(MjcfRegressor, ArmBaseParametersMatchThePapers) {
  MjcfRegressor reg(mjcf_path("planar_arm3.xml"));
  EXPECT_EQ(reg.param_names().size(), 39u);   // 3 x 13, as in the paper
  auto base = reg.base_parameters();
  EXPECT_EQ(base.rank, 17);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::MatrixXd Yb(300, 17), Phi(300, 17);
  auto geo = planar_arm3::geometry(reg.model());
  auto ws = reg.workspace();
  for (int s = 0; s < 100; ++s) {
    Eigen::Vector3d q, qd, qdd;
    for (int j = 0; j < 3; ++j) q[j] = 3 * u(rng), qd[j] = 3 * u(rng), qdd[j] = 10 * u(rng);
    Yb.middleRows(3 * s, 3) = base.Y_base(reg.evaluate(ws, q, qd, qdd));
    Phi.middleRows(3 * s, 3) = planar_arm3::regressor(q, qd, qdd, geo);
  }
  Eigen::MatrixXd both(300, 34);
  both << Yb, Phi;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(both);
  qr.setThreshold(1e-9);
  EXPECT_EQ(qr.rank(), 17);   // same column space
  // The loaded model's base parameters reproduce the paper's coefficients through that map.
  Eigen::MatrixXd M = Yb.colPivHouseholderQr().solve(Phi);   // Phi = Yb * M
  Eigen::VectorXd beta_from_paper = M * planar_arm3::coefficients(reg.model());
  EXPECT_LT((beta_from_paper - base.model_values).norm(), 1e-6);
  EXPECT_EQ(reg.base_parameters(400, 1).names, base.names);   // deterministic
}

TEST(MjcfRegressor, OffsetsAddOneBaseParameterPerJoint) {
  RegressorOptions o;
  o.offsets = true;
  EXPECT_EQ(MjcfRegressor(mjcf_path("planar_arm3.xml"), o).base_parameters().rank, 20);
}

// On data simulated from an MJCF with known parameters and small noise, identification
// recovers the base parameters within 3 standard errors.
TEST(MjcfRegressor, IdentifyRecoversKnownParameters) {
  MjcfRegressor reg(mjcf_path("planar_arm3.xml"));
  auto base = reg.base_parameters();
  ModelPtr m = load_mjcf(mjcf_path("planar_arm3.xml"));
  DataPtr d = make_data(m.get());
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  std::normal_distribution<double> noise(0, 0.05);
  Dataset ds;
  for (const char* name : {"train", "test"}) {
    Split s;
    s.name = name;
    s.x_columns = {"q:joint0", "q:joint1", "q:joint2", "qd:joint0", "qd:joint1", "qd:joint2", "qdd:joint0", "qdd:joint1", "qdd:joint2"};
    s.y_columns = {"tau:joint0", "tau:joint1", "tau:joint2"};
    s.X.resize(500, 9);
    s.Y.resize(500, 3);
    for (int r = 0; r < 500; ++r) {
      for (int j = 0; j < 3; ++j) {
        s.X(r, j) = d->qpos[j] = 3 * u(rng);
        s.X(r, 3 + j) = d->qvel[j] = 2 * u(rng);
        s.X(r, 6 + j) = d->qacc[j] = 8 * u(rng);
      }
      mj_inverse(m.get(), d.get());
      for (int j = 0; j < 3; ++j) s.Y(r, j) = d->qfrc_inverse[j] + noise(rng);
    }
    ds.splits.push_back(s);
  }
  auto id = identify(reg, base, ds, "train");
  ASSERT_EQ(id.estimate.size(), 17);
  for (int i = 0; i < 17; ++i)
    EXPECT_LT(std::fabs(id.estimate[i] - base.model_values[i]), 3 * id.std_error[i] + 1e-9) << base.names[i];
  EXPECT_NEAR(id.sigma, 0.05, 0.01);
  ASSERT_EQ(id.errors.size(), 2u);
  EXPECT_EQ(id.errors[1].split, "test");
  EXPECT_LT(id.errors[1].relative_error, 0.01);
  // A dataset lacking a model joint's column is an error naming it.
  ds.splits[0].x_columns[7] = "qdd:elbow";
  try {
    identify(reg, base, ds, "train");
    FAIL();
  } catch (const DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("split 'train': no input column 'qdd:joint1' for model joint 'joint1'"), std::string::npos) << e.what();
  }
}
