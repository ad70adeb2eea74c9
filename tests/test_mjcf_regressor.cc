#include <gtest/gtest.h>

#include <algorithm>

#include <Eigen/Dense>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <regex>
#include <sstream>
#include <tuple>

#include "spml/envs/mjcf_regressor.h"
#include "spml/parse.h"
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

// ---------------------------------------------------------------------------------------------
// Base parameters of real robot descriptions (issue #26).

namespace {

// Shared files beside the clone: $SPML_SHARED_DATA (default ../shared/data) for the Panda,
// $SPML_SHARED_MODELS (default ../shared/models) for vendor robot files.
std::string shared(const char* env, const char* fallback) {
  const char* v = std::getenv(env);
  return v && *v ? v : std::string(SPML_SOURCE_DIR) + fallback;
}
std::string panda_file() { return shared("SPML_SHARED_DATA", "/../shared/data") + "/panda/panda_nohand.xml"; }
std::string gen3_file() { return shared("SPML_SHARED_MODELS", "/../shared/models") + "/kinova_gen3/gen3.urdf"; }

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string map_numbers(const std::string& list, const std::function<double(double)>& f) {
  std::istringstream in(list);
  std::string out;
  for (double v; in >> v;) out += (out.empty() ? "" : " ") + exact_text(f(v));
  return out;
}

// The file with every angle passed through f: URDF rpy and MJCF euler values, and MJCF quats,
// which become axisangle with the angle passed through f (radians; degrees where the file
// keeps MuJoCo's default angle unit).
std::string map_angles(const std::string& xml, const std::function<double(double)>& f) {
  const bool radian = xml.find("angle=\"radian\"") != std::string::npos;
  std::string out;
  const std::regex attr("(rpy|euler|quat)=\"([^\"]*)\"");
  auto it = std::sregex_iterator(xml.begin(), xml.end(), attr);
  size_t last = 0;
  for (; it != std::sregex_iterator(); ++it) {
    const auto& m = *it;
    out += xml.substr(last, static_cast<size_t>(m.position()) - last);
    last = static_cast<size_t>(m.position() + m.length());
    if (m[1] != "quat") {
      out += m[1].str() + "=\"" + map_numbers(m[2], f) + "\"";
      continue;
    }
    std::istringstream in(m[2]);
    Eigen::Vector4d q;
    in >> q[0] >> q[1] >> q[2] >> q[3];
    q.normalize();
    const Eigen::Vector3d v = q.tail<3>();
    if (v.norm() == 0) { out += "quat=\"1 0 0 0\""; continue; }
    const double angle = f(2 * std::atan2(v.norm(), q[0]));
    const Eigen::Vector3d axis = v.normalized();
    out += "axisangle=\"" + exact_text(axis.x()) + " " + exact_text(axis.y()) + " " + exact_text(axis.z()) + " " +
           exact_text(radian ? angle : angle * 180 / M_PI) + "\"";
  }
  return out + xml.substr(last);
}

double round4(double v) { return std::round(v * 1e4) / 1e4; }
// What a rounded angle stood for: a multiple of pi/2 within 1e-3, else the value itself.
double exact_right_angle(double v) {
  const double k = std::round(v / M_PI_2);
  return std::fabs(v - k * M_PI_2) < 1e-3 ? k * M_PI_2 : v;
}

// `xml` written as `name` in a temporary folder (beside nothing: the models used here
// reference no other files).
std::string write_model(const std::string& name, const std::string& xml) {
  const auto path = (test::temp_dir("base") / name).string();
  std::ofstream(path) << xml;
  return path;
}

// Checks of issue #26 on one description: base values within 10x the largest standard
// parameter, coefficients within 1e3, and a clear decision.
void expect_sane_base(const MjcfRegressor& reg, const MjcfRegressor::Base& base, const std::string& what) {
  const double largest = reg.model_params().cwiseAbs().maxCoeff();
  EXPECT_LE(base.model_values.cwiseAbs().maxCoeff(), 10 * largest) << what;
  if (base.Kd.size()) {
    EXPECT_LE(base.Kd.cwiseAbs().maxCoeff(), 1e3) << what;
  }
  EXPECT_FALSE(base.close_call()) << what << ": " << rank_decision_text(base, reg.param_names().size());
  std::cout << what << ": " << rank_decision_text(base, reg.param_names().size()) << "; largest |base value| "
            << base.model_values.cwiseAbs().maxCoeff() << ", largest |coefficient| "
            << (base.Kd.size() ? base.Kd.cwiseAbs().maxCoeff() : 0.0) << "\n";
}

}  // namespace

// The vendor's Gen3 file rotates its joint frames by 1.5708 and 3.1416; with the exact
// angles it is the same robot and must have the same base parameters' count.
TEST(BaseParameters, Gen3AsShippedAndWithExactAnglesAgree) {
  if (!std::filesystem::exists(gen3_file())) GTEST_SKIP() << "Gen3 model not found at " << gen3_file() << " (set SPML_SHARED_MODELS)";
  MjcfRegressor shipped(gen3_file());
  MjcfRegressor exact(write_model("gen3_exact.urdf", map_angles(read_text(gen3_file()), exact_right_angle)));
  const auto bs = shipped.base_parameters(), be = exact.base_parameters();
  EXPECT_EQ(bs.rank, be.rank);
  expect_sane_base(shipped, bs, "gen3.urdf as shipped");
  expect_sane_base(exact, be, "gen3.urdf, exact angles");
}

// A written extended.xml of a realistic draw (RealisticDraws set 4, level 0 draw 3: four bodies
// with full inertias, every regressor column finite): Eigen 3.4.0's divide-and-conquer SVD
// indexed out of range while deflating its scaled regressor's singular values, returned NaN,
// and the rank read 0 ("the regressor is zero in every sampled state"); the same chain as the
// user gave it has 35 base parameters. Both must have the same count.
TEST(BaseParameters, AWrittenChainKeepsItsRank) {
  const char* kGiven = R"(<mujoco model="chain">
  <option gravity="-4.34771 7.82439 -4.01404"/>
  <worldbody>
    <body name="b0" pos="0 0 0">
      <joint name="j0" type="hinge" axis="-0.786377 -0.616807 -0.0340704" armature="0.05" damping="0.5"/>
      <inertial pos="0.235261 -0.0102511 0" mass="1.10906" diaginertia="0.00387361241654 0.00492659168117 0.00462375540129"/>
      <body name="b1" pos="0.307094 0 0">
        <joint name="j1" type="hinge" axis="-0.0368234 -0.19436 -0.980239" armature="0.05" damping="0.5"/>
        <inertial pos="0.184596 -0.0132685 0" mass="2.54603" diaginertia="0.0354823970157 0.0343277040882 0.0427010439454"/>
        <body name="b2" pos="0.48307 0 0">
          <joint name="j2" type="hinge" axis="-0.97415 -0.184182 0.130804" armature="0.05" damping="0.5"/>
          <inertial pos="0.156548 -0.0122219 0" mass="2.53391" diaginertia="0.0256181613802 0.0295969800738 0.0334866270316"/>
          <body name="b3" pos="0.203986 0 0">
            <joint name="j3" type="hinge" axis="0.971162 0.238167 -0.0110008" armature="0.05" damping="0.5"/>
            <inertial pos="0.236097 -0.027887 0" mass="1.35924" diaginertia="0.00714462261908 0.00565447151211 0.00568064257402"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>)";
  const char* kWritten = R"(<mujoco model="chain">
<option gravity="-4.34771 7.82439 -4.01404"/>
<worldbody>
<body name="b0" pos="0 0 0">
<inertial pos="0.23516730783381493 -0.010175455594021342 -1.076259306245428e-05" mass="1.1183865432957292" fullinertia="0.003867181807636218 0.004919044262190406 0.0046186266390388225 -2.4966928862525488e-06 -1.6125157480867541e-07 -7.964360809710696e-08"/>
<joint name="j0" type="hinge" axis="-0.786377 -0.616807 -0.0340704" armature="0.04997917647554042" damping="0.4971636111850916"/>
<body name="b1" pos="0.307094 0 0">
<inertial pos="0.18387238786456678 -0.01407091459414849 -0.0001926926839440487" mass="2.50194537041615" fullinertia="0.035336827351719544 0.03409754685316803 0.04285477417758385 -0.0004185034023105969 6.548554192613064e-05 -0.0003499548597976676"/>
<joint name="j1" type="hinge" axis="-0.0368234 -0.19436 -0.980239" armature="0.05004356219084071" damping="0.49704203815445713"/>
<body name="b2" pos="0.48307 0 0">
<inertial pos="0.15697490648919765 -0.011739313486604024 0.00023375508146281117" mass="2.581419573057353" fullinertia="0.025708529490805772 0.02987199456529839 0.033056112509327815 -0.0004713215676260367 5.047760893856857e-05 0.00023792768510699552"/>
<joint name="j2" type="hinge" axis="-0.97415 -0.184182 0.130804" armature="0.049833946489629466" damping="0.689956464870608"/>
<body name="b3" pos="0.203986 0 0">
<inertial pos="0.235884532167936 -0.029522916407179543 6.009520499269509e-05" mass="1.3373197025983692" fullinertia="0.007011401804276627 0.0052608787224500825 0.005957130396640142 -3.113113503509443e-06 -0.00017015686507012982 -3.537824871117231e-05"/>
<joint name="j3" type="hinge" axis="0.971162 0.238167 -0.0110008" armature="0.05010993648345675" damping="0.49983997781978246"/>
</body>
</body>
</body>
</body>
</worldbody>
</mujoco>)";
  const auto given = MjcfRegressor(write_model("chain_given.xml", kGiven)).base_parameters();
  const auto written = MjcfRegressor(write_model("chain_written.xml", kWritten)).base_parameters();
  EXPECT_TRUE(written.singular_values.allFinite());
  EXPECT_EQ(written.rank, given.rank);
}

// Rounding every angle to 4 decimals, as URDF exporters do, leaves the rank as it is.
// The same arm in millimetres (lengths x 1e3, inertias, armature and damping x 1e6, gravity
// x 1e3): physically the same robot, so the same base parameters (values x 1e6).
TEST(BaseParameters, LengthUnitDoesNotChangeTheRank) {
  const char* kArmMm = R"(<mujoco model="arm_mm">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option gravity="0 0 -9810"/>
  <default><joint type="hinge" axis="0 -1 0" armature="1e6" damping="1e7"/></default>
  <worldbody>
    <body name="link0"><joint name="joint0"/><inertial pos="566 0 0" mass="5" diaginertia="1e4 828220 828220"/>
      <body name="link1" pos="1000 0 0"><joint name="joint1"/><inertial pos="566 0 0" mass="5" diaginertia="1e4 828220 828220"/>
        <body name="link2" pos="1000 0 0"><joint name="joint2"/><inertial pos="100 0 0" mass="1" diaginertia="1e4 9e4 9e4"/>
  </body></body></body></worldbody></mujoco>)";
  MjcfRegressor si(mjcf_path("planar_arm3.xml")), mm(write_model("arm_mm.xml", kArmMm));
  const auto a = si.base_parameters(), b = mm.base_parameters();
  ASSERT_EQ(a.rank, b.rank);
  EXPECT_FALSE(b.close_call());
  // Same singular values up to rounding: the decision is unit-free.
  for (int i = 0; i < a.rank; ++i) EXPECT_NEAR(a.singular_values[i], b.singular_values[i], 1e-6 * a.singular_values[0]) << i;
}

TEST(BaseParameters, RoundingAnglesToFourDecimalsKeepsTheRank) {
  std::vector<std::string> files = {mjcf_path("planar_arm3.xml"), mjcf_path("planar_arm3_ll.xml"),
                                    mjcf_path("planar_arm3_gl.xml"), mjcf_path("via_joint.xml")};
  for (const auto& f : {panda_file(), gen3_file()}) {
    if (std::filesystem::exists(f)) files.push_back(f);
    else std::cout << "not found, not checked: " << f << " (set SPML_SHARED_DATA / SPML_SHARED_MODELS)\n";
  }
  files.push_back(write_model("branched.xml", kBranched));
  for (const auto& file : files) {
    const std::string text = read_text(file), rounded = map_angles(text, round4);
    const std::string name = std::filesystem::path(file).filename().string();
    // Files without angles (the arm and the VIA joint set axes only) are their own rounding.
    const std::string other = rounded == text ? file : write_model("rounded_" + name, rounded);
    MjcfRegressor a(file), b(other);
    const auto ba = a.base_parameters(), bb = b.base_parameters();
    EXPECT_EQ(ba.rank, bb.rank) << name;
    expect_sane_base(a, ba, name);
    expect_sane_base(b, bb, name + ", angles rounded to 4 decimals");
  }
}

namespace {

// An n-link chain whose joint axes are parallel in exact arithmetic, horizontal, under
// gravity; every second link is flipped about its x axis by `flip` (pi, or 3.1416 as a
// rounded file has it, which tilts that axis by 7e-6 rad).
std::string planar_chain(int n, const std::string& flip) {
  std::string xml = "<mujoco><compiler angle=\"radian\"/><worldbody><body name=\"b0\" euler=\"1.5708 0 0\">";
  for (int i = 0; i < n; ++i) {
    if (i > 0) xml += "<body name=\"b" + std::to_string(i) + "\" pos=\"0.4 0 0\"" + (i % 2 ? " euler=\"" + flip + " 0 0\"" : "") + ">";
    xml += "<joint name=\"j" + std::to_string(i) + "\" axis=\"0 0 1\" damping=\"0.5\" armature=\"0.01\"/>"
           "<inertial pos=\"0.2 0.03 0.01\" mass=\"" + std::to_string(1.0 + 0.3 * i) +
           "\" fullinertia=\"0.02 0.03 0.025 0.001 0.002 0.003\"/>";
  }
  for (int i = 0; i < n; ++i) xml += "</body>";
  return xml + "</worldbody></mujoco>";
}

// Two hinges, the first vertical, the second horizontal through the same point; `angle` turns
// the second body's frame (pi/2 exact, or 1.5708).
std::string rr_arm(const std::string& angle) {
  return "<mujoco><compiler angle=\"radian\"/><worldbody><body name=\"b1\" pos=\"0 0 0.3\">"
         "<joint name=\"j1\" axis=\"0 0 1\" damping=\"0.5\"/>"
         "<inertial pos=\"0.01 0.02 0.05\" mass=\"2\" fullinertia=\"0.02 0.03 0.025 0.001 0.002 0.003\"/>"
         "<body name=\"b2\" pos=\"0 0 0.1\" euler=\"" + angle + " 0 0\"><joint name=\"j2\" axis=\"0 0 1\" damping=\"0.5\"/>"
         "<inertial pos=\"0.2 0.03 0.01\" mass=\"1.5\" fullinertia=\"0.02 0.03 0.025 0.001 0.002 0.003\"/>"
         "</body></body></worldbody></mujoco>";
}

int rank_of(const std::string& name, const std::string& xml) {
  MjcfRegressor reg(write_model(name, xml));
  const auto base = reg.base_parameters();
  expect_sane_base(reg, base, name);
  return base.rank;
}

}  // namespace

// Counts the closed-form regrouping of Gautier & Khalil (1990) gives. An n-link chain with
// parallel horizontal axes identifies per link ZZR, MXR, MY (its motion is planar), and per
// joint damping, Coulomb and armature, the first joint's armature grouped into ZZR1: 6n - 1.
// An RR arm, vertical then horizontal axis through one point: link 1 only ZZR1; link 2
// XXR2 = XX2 - YY2, XY2, XZ2, YZ2, MX2, MY2 and ZZ2, which turns at q2' only (the axes are
// perpendicular), so it is grouped with armature 2 as armature 1 is with ZZR1; M2 and MZ2
// act through the fixed intersection point and drop out: 8 inertial + 2 damping + 2 Coulomb.
TEST(BaseParameters, CountsMatchGautierKhalilRegrouping) {
  const std::string pi = exact_text(M_PI), half = exact_text(M_PI_2);
  for (int n = 1; n <= 5; ++n) {
    EXPECT_EQ(rank_of("chain_exact.xml", planar_chain(n, pi)), 6 * n - 1) << n << " links";
    EXPECT_EQ(rank_of("chain_rounded.xml", planar_chain(n, "3.1416")), 6 * n - 1) << n << " links, rounded";
  }
  EXPECT_EQ(rank_of("rr_exact.xml", rr_arm(half)), 12);
  EXPECT_EQ(rank_of("rr_rounded.xml", rr_arm("1.5708")), 12);
}

namespace {

// Exact torques of `file` (MuJoCo's inverse dynamics at random states within its joint
// ranges) as a dataset with train and test splits.
Dataset simulated(const MjcfRegressor& reg, const std::string& file, int rows) {
  ModelPtr m = load_mjcf(file);
  DataPtr d = make_data(m.get());
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1, 1);
  Dataset ds;
  const int n = m->njnt;
  for (const char* name : {"train", "test"}) {
    Split s;
    s.name = name;
    for (const char* p : {"q:", "qd:", "qdd:"})
      for (const auto& j : reg.joint_names()) s.x_columns.push_back(p + j);
    for (const auto& j : reg.joint_names()) s.y_columns.push_back("tau:" + j);
    s.X.resize(rows, 3 * n);
    s.Y.resize(rows, n);
    for (int r = 0; r < rows; ++r) {
      for (int j = 0; j < n; ++j) {
        const double lo = m->jnt_limited[j] ? m->jnt_range[2 * j] : -M_PI, hi = m->jnt_limited[j] ? m->jnt_range[2 * j + 1] : M_PI;
        s.X(r, j) = d->qpos[j] = lo + (hi - lo) * 0.5 * (u(rng) + 1);
        s.X(r, n + j) = d->qvel[j] = 2 * u(rng);
        s.X(r, 2 * n + j) = d->qacc[j] = 6 * u(rng);
      }
      mj_inverse(m.get(), d.get());
      for (int j = 0; j < n; ++j) s.Y(r, j) = d->qfrc_inverse[j];
    }
    ds.splits.push_back(s);
  }
  return ds;
}

}  // namespace

// Exact data of the Gen3 (exact angles): identification recovers the model's base parameters
// to 1e-6 of the largest and its torques to 1e-8. The shipped file's rounded angles tilt axes
// by up to 7.3e-6 rad; what that adds to the torques lies below the rank tolerance (largest
// dropped singular value 1.4e-6 of the largest) and is not carried by the base parameters, so
// its exact torques are reproduced to that 1e-6, not to rounding (measured 2.3e-8).
TEST(BaseParameters, IdentifyRecoversTheGen3) {
  if (!std::filesystem::exists(gen3_file())) GTEST_SKIP() << "Gen3 model not found at " << gen3_file() << " (set SPML_SHARED_MODELS)";
  const std::string exact = write_model("gen3_exact.urdf", map_angles(read_text(gen3_file()), exact_right_angle));
  for (const auto& [file, torque_tol, param_tol] : {std::tuple<std::string, double, double>{exact, 1e-8, 1e-6}, {gen3_file(), 1e-6, 1e-6}}) {
    MjcfRegressor reg(file);
    const auto base = reg.base_parameters();
    const auto id = identify(reg, base, simulated(reg, file, 400), "train");
    const double scale = base.model_values.cwiseAbs().maxCoeff();
    for (int i = 0; i < base.rank; ++i)
      EXPECT_LE(std::fabs(id.estimate[i] - base.model_values[i]), param_tol * scale) << file << ": " << base.names[i];
    ASSERT_EQ(id.errors.size(), 2u);
    for (const auto& e : id.errors) EXPECT_LT(e.relative_error, torque_tol) << file << ": " << e.split;
    std::cout << file << ": parameters within " << (id.estimate - base.model_values).cwiseAbs().maxCoeff() / scale
              << " of the largest, torques within " << id.errors[0].relative_error << " / " << id.errors[1].relative_error
              << " (fit / held out)\n";
  }
}

// Models the regressor cannot take are refused with the joint's index, type and body,
// through the command line: an unnamed hinge, a free joint.
TEST(BaseParameters, UnnamedAndFreeJointsAreRefusedByName) {
  const std::string unnamed = write_model("unnamed.xml",
      "<mujoco><worldbody><body name=\"a\"><joint name=\"j0\" axis=\"0 1 0\"/><geom size=\"0.1\"/>"
      "<body name=\"b\" pos=\"0.3 0 0\"><joint axis=\"0 1 0\"/><geom size=\"0.1\"/></body></body></worldbody></mujoco>");
  const std::string free = write_model("free.xml",
      "<mujoco><worldbody><body><freejoint/><geom size=\"0.1\"/></body></worldbody></mujoco>");
  for (const char* cmd : {"regressor", "identify --data nowhere.h5"}) {
    auto r = test::run(test::spml_bin() + " " + cmd + " --model " + unnamed);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("spml: error: " + unnamed + ": joint 1 (hinge, unnamed, in body 'b') has no name"), std::string::npos) << r.output;
    r = test::run(test::spml_bin() + " " + cmd + " --model " + free);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("spml: error: " + free + ": joint 0 (free, unnamed, in body #1): the regressor supports hinge and slide joints only"),
              std::string::npos) << r.output;
  }
}

// An unnamed body is body#<id> in parameter names ('#' keeps it apart from a body named
// "body2"; the names collided before); a model naming another body so is refused.
TEST(BaseParameters, UnnamedBodiesGetNamesNoRealBodyHas) {
  auto chain = [](const std::string& first) {
    return "<mujoco><worldbody><body name=\"" + first + "\"><joint name=\"j0\" axis=\"0 1 0\"/><geom size=\"0.1\"/>"
           "<body pos=\"0.3 0 0\"><joint name=\"j1\" axis=\"0 1 0\"/><geom size=\"0.1\"/></body></body></worldbody></mujoco>";
  };
  const std::string file = write_model("unnamed-body.xml", chain("body2"));
  const MjcfRegressor reg(file);
  const auto& names = reg.param_names();
  EXPECT_NE(std::find(names.begin(), names.end(), "m:body2"), names.end());
  EXPECT_NE(std::find(names.begin(), names.end(), "m:body#2"), names.end());
  // identify --write-model: the unnamed body's inertial is a note; the run used to fail with
  // "MuJoCo compiles body 'body2' of the written model to other parameters".
  const std::string data = file + ".h5", written = file + ".identified.xml";
  write_dataset(data, simulated(reg, file, 400));
  const auto r = test::run(test::spml_bin() + " identify --estimator consistent --model " + file + " --data " + data + " --write-model " + written);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("body 2 has no name in the MJCF"), std::string::npos) << r.output;
  EXPECT_NO_THROW(MjcfRegressor{written});
  const std::string clash = write_model("clash.xml", chain("body#2"));
  try {
    MjcfRegressor r(clash);
    FAIL() << "two bodies under one name accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("body 2 has no name and another body is named 'body#2'"), std::string::npos) << e.what();
  }
}

// regressor and identify say how the rank was decided, and warn when a singular value lies
// near the tolerance: here a chain flipped by 3.14 instead of pi (axis tilted by 1.6e-3).
TEST(BaseParameters, RankDecisionIsReportedAndCloseCallsWarned) {
  auto r = test::run(test::spml_bin() + " regressor --json --model " + mjcf_path("planar_arm3.xml") + " 2>/dev/null");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  const auto& d = j["rank_decision"];
  EXPECT_EQ(j["rank"], 17);
  EXPECT_EQ(d["tolerance"], MjcfRegressor::kRankTolerance);
  EXPECT_EQ(d["singular_values"].size(), 39u);
  EXPECT_EQ(d["smallest_kept"], d["singular_values"][16]);
  EXPECT_EQ(d["largest_dropped"], d["singular_values"][17]);
  EXPECT_LT(d["largest_dropped"].get<double>(), 1e-12);   // the arm's dependencies are exact
  EXPECT_FALSE(d["close_call"].get<bool>());
  r = test::run(test::spml_bin() + " regressor --model " + mjcf_path("planar_arm3.xml"));
  EXPECT_NE(r.output.find("rank 17 of 39: smallest kept singular value "), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("warning"), std::string::npos) << r.output;
  r = test::run(test::spml_bin() + " regressor --model " + write_model("tilted.xml", planar_chain(3, "3.14")));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("spml: warning: the base-parameter rank is a close call"), std::string::npos) << r.output;
}

// A subnormal number is finite: "1e-310" is read, as is an underflow to zero (rounding, as for
// any decimal); overflow, inf and nan stay refused.
TEST(ParseNumber, AcceptsSubnormalsAndUnderflow) {
  ASSERT_TRUE(parse_number("1e-310"));
  EXPECT_EQ(*parse_number("1e-310"), 1e-310);
  EXPECT_EQ(std::fpclassify(*parse_number("-2.5e-315")), FP_SUBNORMAL);
  EXPECT_EQ(*parse_number("4.9406564584124654e-324"), std::numeric_limits<double>::denorm_min());
  EXPECT_EQ(*parse_number("1e-400"), 0.0);
  EXPECT_EQ(*parse_numbers("1e-310,2"), (std::vector<double>{1e-310, 2}));
  for (const char* bad : {"1e400", "-1e400", "inf", "nan", "1e-310x", ""}) EXPECT_FALSE(parse_number(bad)) << bad;
}

// The regressor against mj_inverse on load (envs/regressor_check.cc): silent where it is exact,
// and where the model holds what it does not express, the joint named with the likely reason.
namespace {
std::vector<spml::InverseMismatch> mismatches_of(const std::string& xml) {
  auto dir = spml::test::temp_dir("inverse-check");
  const std::string file = (dir / "m.xml").string();
  std::ofstream(file) << xml;
  MjcfRegressor reg(file);
  auto out = reg.inverse_mismatches();
  std::filesystem::remove_all(dir);
  return out;
}
std::string arm_with(const std::string& joint1_extra, const std::string& before_end) {
  std::ifstream in(mjcf_path("planar_arm3.xml"));
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  xml.replace(xml.find("<joint name=\"joint1\"/>"), 22, "<joint name=\"joint1\" " + joint1_extra + "/>");
  xml.replace(xml.find("</mujoco>"), 9, before_end + "</mujoco>");
  return xml;
}
}  // namespace

TEST(MjcfRegressor, InverseCheckIsSilentWhereTheRegressorIsExact) {
  for (const char* f : {"planar_arm3.xml", "planar_arm3_gl.xml"}) {
    MjcfRegressor reg(mjcf_path(f));
    const auto mm = reg.inverse_mismatches();
    EXPECT_TRUE(mm.empty()) << f << ": " << (mm.empty() ? "" : spml::inverse_mismatch_text(mm[0]));
  }
}

TEST(MjcfRegressor, InverseCheckNamesFrictionlossStatefulPluginsAndConstraints) {
  // frictionloss 5 on joint1: MuJoCo's soft constraint, not 5 sign(qd).
  auto fl = mismatches_of(arm_with("frictionloss=\"5\"", ""));
  ASSERT_EQ(fl.size(), 1u);
  std::printf("%s\n", spml::inverse_mismatch_text(fl[0]).c_str());
  EXPECT_EQ(fl[0].joint, "joint1");
  EXPECT_GT(fl[0].relative, 1e-3);   // the constraint force differs from 5 sign(qd) by up to 10 Nm on ~50 Nm RMS
  EXPECT_NE(spml::inverse_mismatch_text(fl[0]).find("frictionloss (MuJoCo applies it as a soft constraint"), std::string::npos)
      << spml::inverse_mismatch_text(fl[0]);
  // A stateful plugin (LuGre stick-slip) has no regressor columns.
  auto ss = mismatches_of(arm_with("", "<custom><text name=\"spml.plugin.ss\" data=\"type=stick_slip joints=joint1 fc=3 fs=4.5 "
                                       "vs=0.05 sigma0=20000 sigma1=10 sigma2=0.1\"/></custom>"));
  ASSERT_EQ(ss.size(), 1u);
  std::printf("%s\n", spml::inverse_mismatch_text(ss[0]).c_str());
  EXPECT_EQ(ss[0].joint, "joint1");
  EXPECT_NE(spml::inverse_mismatch_text(ss[0]).find("the declared plugin 'ss' (stick_slip, stateful) has no regressor columns"),
            std::string::npos)
      << spml::inverse_mismatch_text(ss[0]);
  // Explained by the plugin alone (diagnose simulates it: a note, no warning); frictionloss is not.
  EXPECT_TRUE(ss[0].plugins_only);
  EXPECT_FALSE(fl[0].plugins_only);
  // An equality constraint couples joint1 and joint2.
  auto eq = mismatches_of(arm_with("", "<equality><joint joint1=\"joint1\" joint2=\"joint2\"/></equality>"));
  ASSERT_FALSE(eq.empty());
  for (const auto& mm : eq) {
    EXPECT_NE(spml::inverse_mismatch_text(mm).find("an equality constraint"), std::string::npos) << mm.joint;
    EXPECT_FALSE(mm.plugins_only) << mm.joint;
  }
}
