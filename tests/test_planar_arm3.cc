#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <sstream>

#include "spml/envs/mujoco_model.h"
#include "spml/envs/planar_arm3.h"

using namespace spml;

// The closed-form 17-parameter regressor times the MJCF's regrouped coefficients must equal
// MuJoCo's inverse dynamics of the same MJCF (no plugins) on arbitrary states.
TEST(PlanarArm3, RegressorTimesTruthEqualsMjInverse) {
  for (const char* file : {"planar_arm3.xml", "planar_arm3_prior.xml"}) {
    ModelPtr m = load_mjcf(mjcf_path(file));
    DataPtr d = make_data(m.get());
    auto theta = planar_arm3::coefficients(m.get());
    auto geo = planar_arm3::geometry(m.get());
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> pos(-M_PI, M_PI), vel(-3, 3), acc(-20, 20);
    double worst = 0;
    for (int trial = 0; trial < 200; ++trial) {
      Eigen::Vector3d q, qd, qdd;
      for (int i = 0; i < 3; ++i) {
        q[i] = d->qpos[i] = pos(rng);
        qd[i] = d->qvel[i] = vel(rng);
        qdd[i] = d->qacc[i] = acc(rng);
      }
      mj_inverse(m.get(), d.get());
      Eigen::Vector3d tau = planar_arm3::regressor(q, qd, qdd, geo) * theta;
      for (int i = 0; i < 3; ++i) worst = std::max(worst, std::fabs(tau[i] - d->qfrc_inverse[i]));
    }
    EXPECT_LT(worst, 1e-8) << file;
  }
}

// The MJCF models carry exactly the paper's coefficients (Table simdyn_model_coeffs).
TEST(PlanarArm3, ModelsMatchPublishedCoefficients) {
  std::ifstream csv(SPML_SOURCE_DIR "/data/published/simdyn_model_coeffs.csv");
  ASSERT_TRUE(csv) << "data/published/simdyn_model_coeffs.csv missing";
  std::string line;
  std::getline(csv, line);   // prior,groundtruth,names,deviationperc
  auto truth = planar_arm3::coefficients(load_mjcf(mjcf_path("planar_arm3.xml")).get());
  auto prior = planar_arm3::coefficients(load_mjcf(mjcf_path("planar_arm3_prior.xml")).get());
  const auto& names = planar_arm3::param_names();
  int rows = 0;
  while (std::getline(csv, line)) {
    std::stringstream ss(line);
    std::string p, t, name;
    std::getline(ss, p, ',');
    std::getline(ss, t, ',');
    std::getline(ss, name, ',');
    auto it = std::find(names.begin(), names.end(), name);
    ASSERT_NE(it, names.end()) << name;
    int i = static_cast<int>(it - names.begin());
    EXPECT_NEAR(truth[i], std::stod(t), 1e-12) << name;
    EXPECT_NEAR(prior[i], std::stod(p), 1e-12) << name;
    ++rows;
  }
  EXPECT_EQ(rows, planar_arm3::kParams);
}
