// Scenario generation: split layout, determinism, where the injected effects show up, and
// that the regenerated data sit in the paper's error regime (LLS RMSE vs the published one).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <complex>
#include <fstream>

#include "spml/envs/parametric_model.h"
#include "spml/envs/planar_arm3.h"
#include "spml/envs/scenarios.h"

using namespace spml;

namespace {

const Dataset& cached(const std::string& name) {
  static std::map<std::string, Dataset> cache;
  auto it = cache.find(name);
  if (it == cache.end()) it = cache.emplace(name, generate_scenario(name, GenerateOptions{})).first;
  return it->second;
}

// LLS on the stacked train regressor, RMSE per output on `split`.
Eigen::VectorXd lls_rmse(const Dataset& ds, const std::string& split) {
  const Split& tr = ds.get("train");
  auto pm = make_parametric_model(ds, tr);
  Eigen::VectorXd theta = pm->stacked(tr.X).colPivHouseholderQr().solve(stacked_targets(tr.Y));
  const Split& s = ds.get(split);
  RowMatrix P = pm->predict(s.X, theta);
  return ((P - s.Y).colwise().squaredNorm() / static_cast<double>(s.rows())).cwiseSqrt().transpose();
}

// The paper's published mean RMSE of an algorithm in one of data/published's CSVs.
double published(const std::string& file, const std::string& algo) {
  std::ifstream in(SPML_SOURCE_DIR "/data/published/" + file);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(algo + ",", 0) == 0) return std::stod(line.substr(algo.size() + 1));
  ADD_FAILURE() << algo << " not in " << file;
  return 0;
}

}  // namespace

TEST(Scenarios, SimDynSplitsAndTimes) {
  const Dataset& ds = cached("simdyn-ll");
  const Split& tr = ds.get("train");
  const Split& ti = ds.get("test_interp");
  const Split& te = ds.get("test_extrap");
  EXPECT_EQ(tr.rows(), 5000);                       // first 50 s at 100 Hz
  EXPECT_NEAR(tr.t[0], 0.0, 1e-12);
  EXPECT_NEAR(tr.t[1] - tr.t[0], 0.01, 1e-12);
  EXPECT_LT(tr.t[tr.rows() - 1], 50.0);
  EXPECT_EQ(ti.rows(), 50000);                      // last 50 s at 1 kHz
  EXPECT_NEAR(ti.t[0], 50.0, 1e-9);
  EXPECT_NEAR(ti.t[ti.rows() - 1], 99.999, 1e-9);
  EXPECT_EQ(te.rows(), 50000);
  EXPECT_EQ(tr.x_columns, (std::vector<std::string>{"q:joint0", "q:joint1", "q:joint2", "qd:joint0", "qd:joint1",
                                                    "qd:joint2", "qdd:joint0", "qdd:joint1", "qdd:joint2"}));
  EXPECT_NEAR(ti.X.col(0).mean(), 0.0, 0.05);       // oscillates around offset 0 ...
  EXPECT_NEAR(te.X.col(0).mean(), 0.3, 0.05);       // ... and 0.3 rad for extrapolation
  EXPECT_EQ(ds.model.param_names.size(), 17u);
  GenerateOptions sub;
  sub.test_stride = 10;
  Dataset coarse = generate_scenario("simdyn-ll", sub);
  EXPECT_EQ(coarse.get("test_interp").rows(), 5000);
}

// The paper's test_interp retraces the training path (the reference repeats every 50 s);
// simdyn-ll-fresh keeps train and test_extrap and puts a new path through the same region.
TEST(Scenarios, FreshInterpolationIsANewPathThroughTheSameRegion) {
  const Dataset& paper = cached("simdyn-ll");
  const Dataset& fresh = cached("simdyn-ll-fresh");
  EXPECT_TRUE(paper.get("train").X == fresh.get("train").X);
  EXPECT_TRUE(paper.get("test_extrap").Y == fresh.get("test_extrap").Y);
  const Split& tr = paper.get("train");
  // Row k of the 1 kHz interpolation test sits at t = 50 + k ms, train row i at t = 10 i ms:
  // train row i and test row 10 i lie at the same phase of the 50 s period.
  auto distance_to_training_path = [&](const Split& ti) {
    double worst = 0;
    for (Eigen::Index i = 0; i < tr.rows(); ++i)
      worst = std::max(worst, (ti.X.row(10 * i).head(3) - tr.X.row(i).head(3)).cwiseAbs().maxCoeff());
    return worst;
  };
  EXPECT_LT(distance_to_training_path(paper.get("test_interp")), 1e-3);   // retraced (sensor noise, tracking)
  EXPECT_GT(distance_to_training_path(fresh.get("test_interp")), 0.2);    // not retraced
  const Split& ti = fresh.get("test_interp");
  for (int j = 0; j < 3; ++j) {   // but within the training range of every joint (+-5 %)
    const double lo = tr.X.col(j).minCoeff(), hi = tr.X.col(j).maxCoeff(), pad = 0.05 * (hi - lo);
    EXPECT_GE(ti.X.col(j).minCoeff(), lo - pad) << j;
    EXPECT_LE(ti.X.col(j).maxCoeff(), hi + pad) << j;
  }
  EXPECT_NE(fresh.provenance.at("sampling").find("new phases"), std::string::npos);
}

TEST(Scenarios, ViaAndToyLayout) {
  const Dataset& inst = cached("via-inst");
  const Dataset& ar = cached("via-ar");
  const Split& tr = inst.get("train");
  const Split& te = inst.get("test");
  double frac = static_cast<double>(tr.rows()) / static_cast<double>(tr.rows() + te.rows());
  EXPECT_NEAR(frac, 0.64, 0.001);
  EXPECT_EQ(tr.X.cols(), 2);
  EXPECT_EQ(ar.get("train").X.cols(), 10);
  EXPECT_NEAR(tr.t[1] - tr.t[0], 0.01, 1e-12);      // 100 Hz
  // The AR history column 10 ms back equals the previous row's current value.
  const Split& a = ar.get("train");
  EXPECT_EQ(a.X(5, 2), a.X(4, 0));
  EXPECT_EQ(a.X(5, 9), a.X(1, 1));

  const Dataset& toy = cached("toy");
  EXPECT_EQ(toy.get("train").rows(), 400);
  EXPECT_GE(toy.get("train").X.minCoeff(), 0.0);
  EXPECT_LE(toy.get("train").X.maxCoeff(), 12.0);
  for (Eigen::Index i = 0; i < toy.get("test_extrap").rows(); ++i) {
    double x = toy.get("test_extrap").X(i, 0);
    EXPECT_TRUE((x >= -4 && x <= 0) || (x >= 12 && x <= 16)) << x;
  }
}

TEST(Scenarios, SameSeedSameArraysOtherSeedOtherArrays) {
  for (const char* name : {"toy", "via-ar", "simdyn-gl"}) {
    GenerateOptions a, b, c;
    a.seed = b.seed = 11;
    c.seed = 12;
    a.test_stride = b.test_stride = c.test_stride = 50;
    Dataset x = generate_scenario(name, a), y = generate_scenario(name, b), z = generate_scenario(name, c);
    for (size_t s = 0; s < x.splits.size(); ++s) {
      EXPECT_EQ(x.splits[s].X, y.splits[s].X) << name;
      EXPECT_EQ(x.splits[s].Y, y.splits[s].Y) << name;
      EXPECT_NE(x.splits[s].X, z.splits[s].X) << name;
    }
  }
}

// With the true coefficients the only error on joint 0 of SimDyn-Ll is the band (plus
// differentiation noise): the residual is large inside 0.15..0.25 rad and small outside.
TEST(Scenarios, BandResidualOnlyInsideInterval) {
  const Dataset& ds = cached("simdyn-ll");
  const Split& s = ds.get("test_interp");
  auto pm = make_parametric_model(ds, s);
  RowMatrix pred = pm->predict(s.X, ds.model.truth);
  double in = 0, out = 0;
  int nin = 0, nout = 0;
  for (Eigen::Index i = 0; i < s.rows(); ++i) {
    double r = s.Y(i, 0) - pred(i, 0), q = s.X(i, 0);
    if (q > 0.16 && q < 0.24 && std::fabs(s.X(i, 3)) > 0.05) in += r * r, ++nin;
    else if (q < 0.14 || q > 0.26) out += r * r, ++nout;
  }
  double rms_in = std::sqrt(in / nin), rms_out = std::sqrt(out / nout);
  EXPECT_GT(nin, 1000);
  EXPECT_GT(rms_in, 100.0);    // band level 125 Nm
  EXPECT_LT(rms_out, 15.0);    // differentiation noise only
}

// SimDyn-Gl: the residual of joint 1 (no band there) against the true model, as a function
// of joint position, has its strongest spectral line at 2*30 = 60 rad^-1 and the next
// distinct one at 8*30 = 240 rad^-1.
TEST(Scenarios, RippleResidualSpectrumPeaksAt60And240) {
  const Dataset& ds = cached("simdyn-gl");
  const Split& s = ds.get("test_interp");
  auto pm = make_parametric_model(ds, s);
  RowMatrix pred = pm->predict(s.X, ds.model.truth);
  std::vector<double> amp(301, 0.0);
  for (int w = 1; w <= 300; ++w) {
    std::complex<double> acc = 0;
    for (Eigen::Index i = 0; i < s.rows(); ++i) acc += (s.Y(i, 1) - pred(i, 1)) * std::polar(1.0, -w * s.X(i, 1));
    amp[w] = 2 * std::abs(acc) / static_cast<double>(s.rows());
  }
  int best = static_cast<int>(std::max_element(amp.begin(), amp.end()) - amp.begin());
  EXPECT_EQ(best, 60);
  int best_high = static_cast<int>(std::max_element(amp.begin() + 120, amp.end()) - amp.begin());
  EXPECT_EQ(best_high, 240);
}

TEST(Scenarios, LlsInThePapersErrorRegime) {
  // Toy: the paper's LLS 1.29 / 1.63; our bump is tuned to that, within 20 %.
  const Dataset& toy = cached("toy");
  EXPECT_NEAR(lls_rmse(toy, "test_interp")[0], published("toy_interp_w_noise.csv", "LLS"), 0.2 * 1.29);
  EXPECT_NEAR(lls_rmse(toy, "test_extrap")[0], published("toy_extrap_w_noise.csv", "LLS"), 0.2 * 1.63);
  // SimDyn-Ll joint 0: paper 38.43, within 15 %.
  const Dataset& ll = cached("simdyn-ll");
  double p = published("simdyn_stats_exp_interp_SENSING_dist_local_dim_0.csv", "LLS");
  EXPECT_NEAR(lls_rmse(ll, "test_interp")[0], p, 0.15 * p);
  // VIA-Instantaneous: paper 3.96, within 35 % (a simulated stand-in for a real test-bed).
  double v = published("vda_instant.csv", "LLS");
  EXPECT_NEAR(lls_rmse(cached("via-inst"), "test")[0], v, 0.35 * v);
}
