// Physically consistent identification: the log-Cholesky map, payload recovery on a 6-joint
// spatial arm from exact and from noisy torques, the written model, and the Panda.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>

#include "../envs/identification/consistent_objective.h"
#include "spml/envs/body_inertial.h"
#include "spml/envs/consistent_identification.h"
#include "spml/envs/identified_model.h"
#include "spml/envs/log_cholesky.h"
#include "spml/envs/mjcf_edit.h"
#include "spml/envs/mjcf_regressor.h"
#include "spml/matrix_file.h"
#include <nlohmann/json.hpp>
#include "test_util.h"

using namespace spml;

namespace {

// A realizable body: mass, centre of mass, principal moments within the triangle inequality,
// principal axes rotated at random; in MjcfRegressor's order (inertia about the body origin).
Vector10d random_body(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1), mass(0.2, 5), moment(0.7, 1.0);
  const double m = mass(rng), i0 = 0.01 + 0.05 * (u(rng) + 1);
  const Eigen::Vector3d c(0.2 * u(rng), 0.2 * u(rng), 0.2 * u(rng)), l(i0 * moment(rng), i0 * moment(rng), i0 * moment(rng));
  const Eigen::Matrix3d R = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
  const Eigen::Matrix3d I = R * l.asDiagonal() * R.transpose() + m * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
  Vector10d p;
  p << m, m * c, I(0, 0), I(1, 1), I(2, 2), I(0, 1), I(0, 2), I(1, 2);
  return p;
}

}  // namespace

TEST(LogCholesky, AnyPsiGivesAPositiveDefinitePseudoInertia) {
  std::mt19937_64 rng(11);
  std::normal_distribution<double> n(0, 1.5);
  for (int i = 0; i < 1000; ++i) {
    Vector10d psi;
    for (int k = 0; k < 10; ++k) psi[k] = n(rng);
    const Vector10d pi = params_from_log_cholesky(psi);
    const Eigen::SelfAdjointEigenSolver<Matrix4d> eig(pseudo_inertia(pi));
    ASSERT_GT(eig.eigenvalues().minCoeff(), 0) << psi.transpose();
    ASSERT_TRUE(realizable(pi));
    EXPECT_NEAR(pi[0], std::exp(2 * psi[0]), 1e-12 * pi[0]);   // m = e^(2 alpha)
  }
}

TEST(LogCholesky, InverseRoundTripsARealizableBody) {
  std::mt19937_64 rng(12);
  for (int i = 0; i < 500; ++i) {
    const Vector10d pi = random_body(rng);
    ASSERT_TRUE(realizable(pi));
    const Vector10d psi = log_cholesky_from_params(pi);
    EXPECT_LT((params_from_log_cholesky(psi) - pi).cwiseAbs().maxCoeff(), 1e-10 * pi.cwiseAbs().maxCoeff());
    EXPECT_LT((log_cholesky_from_params(params_from_log_cholesky(psi)) - psi).cwiseAbs().maxCoeff(), 1e-10);
  }
  Vector10d bad = random_body(rng);
  bad[0] = -1;
  EXPECT_FALSE(realizable(bad));
  EXPECT_THROW(log_cholesky_from_params(bad), std::domain_error);
  // Principal moments 1, 1, 3 break the triangle inequality: no mass distribution has them.
  Vector10d rod;
  rod << 1, 0, 0, 0, 1, 1, 3, 0, 0, 0;
  EXPECT_FALSE(realizable(rod));
}

TEST(LogCholesky, JacobianMatchesFiniteDifferences) {
  std::mt19937_64 rng(13);
  for (int i = 0; i < 50; ++i) {
    const Vector10d psi = log_cholesky_from_params(random_body(rng));
    Matrix10d J;
    params_from_log_cholesky(psi, &J);
    for (int k = 0; k < 10; ++k) {
      const double h = 1e-6;
      Vector10d a = psi, b = psi;
      a[k] += h;
      b[k] -= h;
      const Vector10d fd = (params_from_log_cholesky(a) - params_from_log_cholesky(b)) / (2 * h);
      EXPECT_LT((fd - J.col(k)).norm(), 1e-6 * (1 + J.col(k).norm())) << "psi " << k;
    }
  }
}

// The full objective (data, log-det prior, joint-term prior): analytic gradient = central differences.
TEST(LogCholesky, ObjectiveGradientMatchesFiniteDifferences) {
  std::mt19937_64 rng(14);
  std::normal_distribution<double> n(0, 1);
  identification::Layout L;
  L.bodies = {0, 1};
  L.terms = {20, 21};
  L.bounded = {true, false};
  Eigen::VectorXd pi0(22);
  pi0 << random_body(rng), random_body(rng), 0.1, 0.3;
  Eigen::MatrixXd R(22, 22);
  for (int i = 0; i < R.size(); ++i) R.data()[i] = n(rng);
  Eigen::VectorXd z(22);
  for (int i = 0; i < 22; ++i) z[i] = n(rng);
  const identification::ConsistentObjective obj(L, R, z, 0.7, pi0, Eigen::Vector2d(2.0, 3.0), 1.5);
  Eigen::VectorXd theta = obj.start();
  EXPECT_LT((obj.standard(theta) - pi0).norm(), 1e-12 * pi0.norm());
  for (int i = 0; i < theta.size(); ++i) theta[i] += 0.1 * n(rng);
  Eigen::VectorXd g;
  obj.value(theta, &g);
  for (int k = 0; k < theta.size(); ++k) {
    const double h = 1e-6;
    Eigen::VectorXd a = theta, b = theta;
    a[k] += h;
    b[k] -= h;
    const double fd = (obj.value(a) - obj.value(b)) / (2 * h);
    EXPECT_NEAR(fd, g[k], 1e-5 * (1 + std::fabs(g[k]))) << "theta " << k;
  }
}

TEST(BodyInertial, ReadsBackWhatMujocoCompiled) {
  const auto dir = test::temp_dir("consistent-inertial");
  const std::string path = (dir / "one.xml").string();
  std::ofstream(path) << "<mujoco><worldbody><body name=\"b\"><joint name=\"j\" axis=\"0 1 0\"/>"
                         "<inertial pos=\"0.1 -0.2 0.05\" mass=\"2.5\" fullinertia=\"0.04 0.05 0.06 0.001 -0.002 0.003\"/>"
                         "</body></worldbody></mujoco>";
  const MjcfRegressor reg(path);
  const BodyInertial b = body_inertial(reg.model_params().head<10>());
  EXPECT_NEAR(b.mass, 2.5, 1e-12);
  EXPECT_LT((b.com - Eigen::Vector3d(0.1, -0.2, 0.05)).norm(), 1e-12);
  const std::array<double, 6> want{0.04, 0.05, 0.06, 0.001, -0.002, 0.003};
  for (size_t k = 0; k < 6; ++k) EXPECT_NEAR(b.fullinertia()[k], want[k], 1e-9);
  // Principal axes and moments reproduce the inertia.
  const Eigen::Matrix3d R = b.orientation.toRotationMatrix();
  EXPECT_LT((R * b.principal.asDiagonal() * R.transpose() - b.inertia).norm(), 1e-12);
  // The delta-method Jacobian: central differences.
  const Vector10d p = reg.model_params().head<10>();
  const Matrix10d D = body_inertial_jacobian(p);
  auto q = [](const Vector10d& x) { return mjcf_quantities(body_inertial(x)); };
  for (int k = 0; k < 10; ++k) {
    Vector10d a = p, c = p;
    a[k] += 1e-7;
    c[k] -= 1e-7;
    EXPECT_LT(((q(a) - q(c)) / 2e-7 - D.col(k)).norm(), 1e-5 * (1 + D.col(k).norm())) << k;
  }
}

namespace {

// A 6-joint spatial arm (random hinge axes, links 0.2-0.5 m, 0.5-3 kg) and the same arm with a
// payload welded to its last body: a child body without a joint, which the prior model lacks.
std::string arm_xml(std::uint64_t seed, double payload) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1), len(0.2, 0.5), mass(0.5, 3.0), inertia(0.005, 0.05), f(0.7, 1.0);
  std::ostringstream x;
  x.precision(17);
  x << "<mujoco model=\"arm\">\n  <worldbody>\n";
  const int n = 6;
  for (int j = 0; j < n; ++j) {
    Eigen::Vector3d axis(u(rng), u(rng), u(rng));
    axis.normalize();
    const double l = len(rng), i0 = inertia(rng);
    x << "<body name=\"b" << j << "\" pos=\"" << (j ? l : 0.0) << " 0 0\">\n"
      << "<joint name=\"j" << j << "\" axis=\"" << axis.transpose() << "\" armature=\"0.05\" damping=\"0.5\"/>\n"
      << "<inertial pos=\"" << 0.5 * len(rng) << " " << 0.05 * u(rng) << " 0\" mass=\"" << mass(rng) << "\" diaginertia=\""
      << i0 * f(rng) << " " << i0 * f(rng) << " " << i0 * f(rng) << "\"/>\n";
  }
  if (payload > 0)
    x << "<body name=\"payload\" pos=\"0.15 0.04 -0.03\"><inertial pos=\"0 0 0\" mass=\"" << payload
      << "\" diaginertia=\"0.004 0.003 0.002\"/></body>\n";
  for (int j = 0; j < n; ++j) x << "</body>\n";
  x << "  </worldbody>\n</mujoco>\n";
  return x.str();
}

// Inverse dynamics of a model along a multi-sine per joint (3 harmonics, 0.1-0.6 Hz); torque
// noise with standard deviation noise_rel times each joint's RMS torque.
Split measure(const std::string& model_path, std::uint64_t seed, int rows, double noise_rel, const std::string& name) {
  auto m = load_mjcf(model_path);
  auto d = make_data(m.get());
  const int J = m->nv;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> amp(0.3, 0.8), freq(0.1, 0.6), phase(0, 2 * M_PI);
  std::vector<std::array<double, 9>> w(static_cast<size_t>(J));
  for (auto& a : w)
    for (int k = 0; k < 3; ++k) a[3 * k] = amp(rng), a[3 * k + 1] = 2 * M_PI * freq(rng), a[3 * k + 2] = phase(rng);
  Split s;
  s.name = name;
  s.X.resize(rows, 3 * J);
  s.Y.resize(rows, J);
  for (const char* p : {"q:", "qd:", "qdd:"})
    for (int j = 0; j < J; ++j) s.x_columns.push_back(p + std::string("j") + std::to_string(j));
  for (int j = 0; j < J; ++j) s.y_columns.push_back("tau:j" + std::to_string(j));
  for (int r = 0; r < rows; ++r) {
    const double t = 0.01 * r;
    for (int j = 0; j < J; ++j) {
      double q = 0, qd = 0, qdd = 0;
      for (int k = 0; k < 3; ++k) {
        const double A = w[j][3 * k] / (k + 1), om = w[j][3 * k + 1], ph = w[j][3 * k + 2];
        q += A * std::sin(om * t + ph), qd += A * om * std::cos(om * t + ph), qdd -= A * om * om * std::sin(om * t + ph);
      }
      d->qpos[j] = s.X(r, j) = q;
      d->qvel[j] = s.X(r, J + j) = qd;
      d->qacc[j] = s.X(r, 2 * J + j) = qdd;
    }
    mj_inverse(m.get(), d.get());
    for (int j = 0; j < J; ++j) s.Y(r, j) = d->qfrc_inverse[j];
  }
  if (noise_rel > 0) {
    std::normal_distribution<double> n(0, 1);
    for (int j = 0; j < J; ++j) {
      const double sd = noise_rel * std::sqrt(s.Y.col(j).squaredNorm() / rows);
      for (int r = 0; r < rows; ++r) s.Y(r, j) += sd * n(rng);
    }
  }
  return s;
}

// Torques of a model file at the states of a split (MuJoCo's own inverse dynamics).
RowMatrix model_torques(const std::string& model_path, const Split& s) {
  auto m = load_mjcf(model_path);
  auto d = make_data(m.get());
  const int J = m->nv;
  RowMatrix tau(s.rows(), J);
  for (Eigen::Index r = 0; r < s.rows(); ++r) {
    for (int j = 0; j < J; ++j) d->qpos[j] = s.X(r, j), d->qvel[j] = s.X(r, J + j), d->qacc[j] = s.X(r, 2 * J + j);
    mj_inverse(m.get(), d.get());
    for (int j = 0; j < J; ++j) tau(r, j) = d->qfrc_inverse[j];
  }
  return tau;
}

struct Payload {
  std::filesystem::path dir;
  std::string prior_path, true_path;
  double true_mass = 0;   // of the last body with its payload
  Eigen::Vector3d true_com;
};
Payload payload_arm(const std::string& name) {
  Payload p;
  p.dir = test::temp_dir(name);
  p.prior_path = (p.dir / "prior.xml").string();
  p.true_path = (p.dir / "true.xml").string();
  std::ofstream(p.prior_path) << arm_xml(21, 0);
  std::ofstream(p.true_path) << arm_xml(21, 1.5);
  const MjcfRegressor prior(p.prior_path);
  const BodyInertial b5 = body_inertial(prior.model_params().segment<10>(50));
  p.true_mass = b5.mass + 1.5;
  p.true_com = (b5.mass * b5.com + 1.5 * Eigen::Vector3d(0.15, 0.04, -0.03)) / p.true_mass;
  return p;
}

Dataset arm_data(const Payload& p, double noise_rel) {
  Dataset ds;
  ds.splits.push_back(measure(p.true_path, 31, 3000, noise_rel, "train"));
  ds.splits.push_back(measure(p.true_path, 32, 1000, 0.0, "test"));   // held out, noise free
  return ds;
}

void print_bodies(const ConsistentIdentification& id) {
  for (const auto& b : id.bodies)
    std::cout << "  " << b.name << ": mass " << b.prior.mass << " -> " << b.identified.mass << " +- " << b.std_error[0]
              << ", com " << b.identified.com.transpose() << " (max z " << b.max_z << (b.changed ? ", changed" : "") << ")\n";
  for (const auto& e : id.errors) std::cout << "  " << e.split << ": relative error " << e.relative_error << "\n";
  std::cout << "  " << id.evaluations << " evaluations, " << id.seconds << " s, stop " << id.stop << "\n";
}

}  // namespace

// Exact inverse-dynamics data of the arm with its payload; the prior model lacks the payload.
TEST(ConsistentIdentification, RecoversAPayloadFromExactTorques) {
  const Payload p = payload_arm("consistent-payload");
  const MjcfRegressor reg(p.prior_path);
  const Dataset ds = arm_data(p, 0.0);
  const ConsistentIdentification id = identify_consistent(reg, ds, "train");
  print_bodies(id);
  ASSERT_EQ(id.bodies.size(), 6u);
  for (int b = 0; b < 6; ++b) {
    EXPECT_TRUE(id.bodies[b].fitted);
    EXPECT_TRUE(realizable(id.pi.segment<10>(10 * b))) << id.bodies[b].name;
  }
  const ConsistentBody& last = id.bodies.back();
  EXPECT_NEAR(last.identified.mass, p.true_mass, 0.05 * p.true_mass);
  EXPECT_TRUE(last.changed);
  EXPECT_LT(id.errors[1].relative_error, 1e-3);
  // The written model: MuJoCo's inverse dynamics of it on the held-out states.
  std::vector<std::string> notes;
  const std::string out = (p.dir / "identified.xml").string();
  write_text_atomic(out, edit_mjcf(p.prior_path, identified_model_edits(reg, id, notes), notes));
  EXPECT_TRUE(notes.empty()) << notes.front();
  const Split& test = ds.get("test");
  const RowMatrix tau = model_torques(out, test);
  const double rel = (tau - test.Y).norm() / test.Y.norm();
  std::cout << "  written model, held out: relative error " << rel << "; last body mass " << last.identified.mass << " (true "
            << p.true_mass << "), com " << last.identified.com.transpose() << " (true " << p.true_com.transpose() << ")\n";
  EXPECT_LT(rel, 1e-3);
  // MuJoCo compiles the written file to the identified parameters (its compiler diagonalises
  // fullinertia by Jacobi sweeps, good to about 1e-9 of the largest entry).
  const MjcfRegressor written(out);
  EXPECT_LT((written.model_params() - id.pi).cwiseAbs().maxCoeff(), 1e-8 * id.pi.cwiseAbs().maxCoeff());
  EXPECT_LT((last.identified.com - p.true_com).norm(), 0.01) << last.identified.com.transpose() << " vs " << p.true_com.transpose();
}

// Torques with noise of 1 % of each joint's RMS: every body still realizable, and the payload's
// mass and centre of mass within 4 standard errors of the truth (a 4-sigma band: a false alarm
// once in 16 000 draws if the errors are as Gaussian as the SEs assume).
TEST(ConsistentIdentification, RecoversAPayloadFromNoisyTorquesWithinItsStandardErrors) {
  const Payload p = payload_arm("consistent-noisy");
  const MjcfRegressor reg(p.prior_path);
  const Dataset ds = arm_data(p, 0.01);
  const ConsistentIdentification id = identify_consistent(reg, ds, "train");
  print_bodies(id);
  for (int b = 0; b < 6; ++b) EXPECT_TRUE(realizable(id.pi.segment<10>(10 * b))) << id.bodies[b].name;
  const ConsistentBody& last = id.bodies.back();
  EXPECT_TRUE(last.changed);
  EXPECT_LT(std::fabs(last.identified.mass - p.true_mass), 4 * last.std_error[0]) << "SE " << last.std_error[0];
  // An all-hinge chain's data never fix a link's mass alone (a point mass on a joint axis may
  // sit on either side of it; Gautier & Khalil 1990); its SE here is mostly the prior's width.
  // Realizability of both bodies is what puts the payload on the last one.
  EXPECT_NEAR(last.identified.mass, p.true_mass, 0.05 * p.true_mass);
  for (int k = 0; k < 3; ++k)
    EXPECT_LT(std::fabs(last.identified.com[k] - p.true_com[k]), 4 * last.std_error[1 + k]) << "com " << k;
  // The noise level is estimated: the pooled standard deviation of the added noise.
  const Split& train = ds.get("train");
  const RowMatrix clean = measure(p.true_path, 31, 3000, 0.0, "clean").Y;
  const double noise = std::sqrt((train.Y - clean).squaredNorm() / static_cast<double>(clean.size()));
  EXPECT_NEAR(id.sigma, noise, 0.05 * noise);
  // Held out against noise-free torques: the parameter error's share of the prediction error,
  // about sigma * sqrt(rank / equations) for a linear fit; allowed three times that.
  const double bound = 3 * noise * std::sqrt(static_cast<double>(id.rank) / static_cast<double>(train.Y.size()));
  const double rms_test = std::sqrt(ds.get("test").Y.squaredNorm() / static_cast<double>(ds.get("test").Y.size()));
  std::cout << "  held-out RMSE " << id.errors[1].rmse << " (bound " << bound << ", torque RMS " << rms_test << ")\n";
  EXPECT_LT(id.errors[1].rmse, bound);
}

namespace {

std::string shared_data() {
  const char* env = std::getenv("SPML_SHARED_DATA");
  return env && *env ? env : std::string(SPML_SOURCE_DIR) + "/../shared/data";
}

// Per output joint: ||tau - prediction|| / ||tau|| over one split (rows output-major).
Eigen::VectorXd per_joint_error(const Eigen::VectorXd& tau, const Eigen::VectorXd& pred, Eigen::Index outputs) {
  const Eigen::Index N = tau.size() / outputs;
  Eigen::VectorXd e(outputs);
  for (Eigen::Index o = 0; o < outputs; ++o)
    e[o] = (tau.segment(o * N, N) - pred.segment(o * N, N)).norm() / tau.segment(o * N, N).norm();
  return e;
}

}  // namespace

// The Panda's measured run (README's import): every body realizable, the held-out error no worse
// than least squares' on base parameters by more than 10 % of it, per-joint errors printed.
TEST(ConsistentIdentification, PandaEveryBodyRealizableAndHeldOutAsGoodAsLeastSquares) {
  const std::string P = shared_data() + "/panda";
  if (!std::filesystem::exists(P + "/panda_nohand.xml")) GTEST_SKIP() << "Panda data not found at " << P << " (set SPML_SHARED_DATA)";
  const auto dir = test::temp_dir("consistent-panda");
  const std::string data = (dir / "panda.h5").string();
  const auto r = test::run(test::spml_bin() + " import --text " + P + "/exciting_traj_positions.txt='q:joint{1..7}' --text " + P +
                           "/exciting_traj_velocity.txt='qd:joint{1..7}' --text " + P + "/exciting_traj_torques.txt='tau:joint{1..7}' --text " +
                           P + "/exciting_traj_time.txt=t --x 'q:joint{1..7},qd:joint{1..7}' --y 'tau:joint{1..7}' --t t --lowpass 20 "
                           "--derive --drop-edges 100 --decimate 5 --split train:0:70% --split test:70%: -o " + data);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Dataset ds = read_dataset(data);
  const MjcfRegressor reg(P + "/panda_nohand.xml");
  const auto base = reg.base_parameters();
  const Identification ls = identify(reg, base, ds, "train");
  const ConsistentIdentification id = identify_consistent(reg, ds, "train");
  print_bodies(id);
  for (const auto& b : id.bodies)
    if (b.fitted) {
      EXPECT_TRUE(realizable(id.pi.segment<10>(10 * (b.body_id - 1)))) << b.name;
    }
  for (const auto& t : id.terms)
    if (t.name.rfind("armature:", 0) == 0 || t.name.rfind("damping:", 0) == 0 || t.name.rfind("coulomb:", 0) == 0) {
      EXPECT_GE(t.value, 0) << t.name;
    }
  const double ls_test = ls.errors[1].relative_error, c_test = id.errors[1].relative_error;
  std::cout << "  held out: least squares " << 100 * ls_test << " %, consistent " << 100 * c_test << " %\n";
  EXPECT_LT(c_test, 1.1 * ls_test);
  // Per joint, held out: the shipped model, least squares, consistent.
  const Split& test = ds.get("test");
  const JointColumns cols(reg, test);
  const Eigen::MatrixXd W = stacked_standard_regressor(reg, test.X, cols, "test");
  const Eigen::VectorXd tau = stacked_targets(test.Y);
  const Eigen::VectorXd shipped = per_joint_error(tau, W * reg.model_params(), test.Y.cols()),
                        lsj = per_joint_error(tau, stacked_base_regressor(reg, base, test.X, cols, "test") * ls.estimate, test.Y.cols()),
                        cj = per_joint_error(tau, W * id.pi, test.Y.cols());
  std::cout << "  held-out relative error per joint (shipped / least squares / consistent), %:\n";
  for (Eigen::Index j = 0; j < cj.size(); ++j) {
    std::cout << "    " << test.y_columns[static_cast<size_t>(j)] << ": " << 100 * shipped[j] << " / " << 100 * lsj[j] << " / " << 100 * cj[j] << "\n";
    EXPECT_LT(cj[j], shipped[j]) << test.y_columns[static_cast<size_t>(j)];
  }
}

// The command: `spml identify --write-model` runs the consistent estimator, prints the payload's
// body as changed and writes a model MuJoCo loads; wrong combinations are refused.
TEST(ConsistentIdentification, CommandWritesTheIdentifiedModelAndRefusesBadInput) {
  const Payload p = payload_arm("consistent-cli");
  const std::string data = (p.dir / "arm.h5").string(), out = (p.dir / "identified.xml").string();
  write_dataset(data, arm_data(p, 0.0));
  const std::string base = test::spml_bin() + " identify -m " + p.prior_path + " -d " + data;
  auto r = test::run(base + " --write-model " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("body b5  CHANGED"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("written: " + out), std::string::npos) << r.output;
  const MjcfRegressor written(out);
  EXPECT_NEAR(written.model()->body_mass[6], p.true_mass, 0.05 * p.true_mass);
  r = test::run(base + " --estimator consistent --json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j["estimator"], "consistent");
  EXPECT_EQ(j["bodies"].size(), 6u);
  EXPECT_TRUE(j["bodies"][5]["changed"].get<bool>());
  EXPECT_LT(j["errors"][1]["relative_error"].get<double>(), 1e-3);
  // --write-model needs the consistent estimator; an unwritable path fails cleanly.
  r = test::run(base + " --estimator ls --write-model " + out);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--write-model"), std::string::npos) << r.output;
  r = test::run(base + " --write-model " + (p.dir / "no-such-folder" / "x.xml").string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("spml: error:"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(p.dir / "no-such-folder"));
  r = test::run(base + " --estimator consistent --prior-weight 0");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = test::run(base + " --prior-weight 10");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--estimator consistent only"), std::string::npos) << r.output;
  // The library refuses a regressor that does not match the model, naming the sizes.
  const MjcfRegressor reg(p.prior_path);
  try {
    fit_consistent(reg, Eigen::MatrixXd::Ones(10, 3), Eigen::VectorXd::Ones(10));
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("3 columns and 10 rows for " + std::to_string(reg.param_names().size()) + " parameters"),
              std::string::npos) << e.what();
  }
}

// A declared linear plugin's re-identified parameter is written into its own declaration (a
// model that a previous diagnosis extended with a Coulomb friction, its level fitted again):
// before, it was a note "has no MJCF attribute written here: edit it by hand". Its other
// parameters and joints stay as declared; a model MuJoCo loads holds the new value.
TEST(ConsistentIdentification, ADeclaredPluginsParameterIsWrittenIntoItsDeclaration) {
  const auto dir = test::temp_dir("consistent-plugin");
  const std::string model = (dir / "declared.xml").string(), out = (dir / "written.xml").string();
  std::ofstream(model) << R"(<mujoco model="two">
  <compiler angle="radian" inertiafromgeom="false"/>
  <worldbody>
    <body name="a" pos="0 0 0.2">
      <joint name="j1" type="hinge" axis="0 0 1" damping="0.3"/>
      <inertial pos="0.1 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
      <body name="b" pos="0.2 0 0">
        <joint name="j2" type="hinge" axis="0 0 1" damping="0.2"/>
        <inertial pos="0.1 0 0" mass="0.5" diaginertia="0.005 0.005 0.005"/>
      </body>
    </body>
  </worldbody>
  <custom><text name="spml.plugin.c" data="type=coulomb joints=j1,j2 fc=0.3,0.2 smooth=0"/></custom>
</mujoco>
)";
  const MjcfRegressor reg(model);
  ConsistentIdentification id;
  ConsistentTerm t;
  t.name = "plugin:c.j2.fc";
  t.prior = 0.2;
  t.value = 0.45;
  t.fitted = true;
  id.terms.push_back(t);
  std::vector<std::string> notes;
  const MjcfEdits e = identified_model_edits(reg, id, notes);
  ASSERT_EQ(e.replaced_texts.count("spml.plugin.c"), 1u) << notes.size() << " notes";
  EXPECT_EQ(e.replaced_texts.at("spml.plugin.c"), "type=coulomb joints=j1,j2 fc=0.3,0.45 smooth=0");
  for (const auto& n : notes) EXPECT_EQ(n.find("edit it by hand"), std::string::npos) << n;
  std::ofstream(out) << edit_mjcf(model, e, notes);
  const MjcfRegressor written(out);
  const auto names = written.param_names();
  const auto at = std::find(names.begin(), names.end(), "plugin:c.j2.fc") - names.begin();
  ASSERT_LT(static_cast<size_t>(at), names.size());
  EXPECT_DOUBLE_EQ(written.model_params()[at], 0.45);
}
