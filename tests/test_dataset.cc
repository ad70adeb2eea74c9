#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "spml/dataset.h"
#include "spml/import.h"
#include "spml/signal.h"
#include "test_util.h"

using namespace spml;

namespace {

Dataset small_dataset() {
  Dataset ds;
  Split s;
  s.name = "train";
  s.x_columns = {"q:a", "qd:a"};
  s.y_columns = {"tau:a"};
  s.X = RowMatrix::Random(5, 2);
  s.Y = RowMatrix::Random(5, 1);
  s.t = Eigen::VectorXd::LinSpaced(5, 0.0, 0.4);
  ds.splits.push_back(s);
  s.name = "test";
  ds.splits.push_back(s);
  ds.model.name = "m";
  ds.model.param_names = {"p1", "p2"};
  ds.model.prior = Eigen::Vector2d(1, 2);
  ds.model.truth = Eigen::Vector2d(3, 4);
  ds.provenance["seed"] = "42";
  return ds;
}

}  // namespace

TEST(Dataset, RoundTripKeepsEverythingAndSplitOrder) {
  auto dir = test::temp_dir("roundtrip");
  Dataset ds = small_dataset();
  ds.splits[1].name = "a_test";   // alphabetically first, written second
  write_dataset((dir / "d.h5").string(), ds);
  Dataset back = read_dataset((dir / "d.h5").string());
  ASSERT_EQ(back.splits.size(), 2u);
  EXPECT_EQ(back.splits[0].name, "train");
  EXPECT_EQ(back.splits[1].name, "a_test");
  EXPECT_EQ(back.splits[0].X, ds.splits[0].X);
  EXPECT_EQ(back.splits[0].Y, ds.splits[0].Y);
  EXPECT_EQ(back.splits[0].t, ds.splits[0].t);
  EXPECT_EQ(back.splits[0].x_columns, ds.splits[0].x_columns);
  EXPECT_EQ(back.model.param_names, ds.model.param_names);
  EXPECT_EQ(back.model.truth, ds.model.truth);
  EXPECT_EQ(back.provenance.at("seed"), "42");
  std::filesystem::remove_all(dir);
}

TEST(Dataset, WriteIsAtomicAndLeavesNoTemporaryFiles) {
  auto dir = test::temp_dir("atomic");
  Dataset ds = small_dataset();
  write_dataset((dir / "d.h5").string(), ds);
  // An invalid dataset must not replace the good file nor leave a partial one.
  ds.splits[0].Y.resize(4, 1);
  EXPECT_THROW(write_dataset((dir / "d.h5").string(), ds), DatasetError);
  EXPECT_NO_THROW(read_dataset((dir / "d.h5").string()));
  int files = 0;
  for (auto& e : std::filesystem::directory_iterator(dir)) {
    ++files;
    EXPECT_EQ(e.path().filename(), "d.h5");
  }
  EXPECT_EQ(files, 1);
  EXPECT_THROW(write_dataset((dir / "missing" / "d.h5").string(), small_dataset()), DatasetError);
  std::filesystem::remove_all(dir);
}

TEST(Dataset, ValidationNamesTheProblem) {
  Dataset ds = small_dataset();
  ds.splits[0].X(2, 1) = std::nan("");
  try {
    validate(ds, "f.h5");
    FAIL() << "NaN accepted";
  } catch (const DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("group 'train': dataset 'X': non-finite values (NaN/Inf) in 1 row(s): 2"),
              std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(validate(ds, "f.h5", ReadOptions{true}));
}

TEST(Import, CsvWithPercentSplitsAndScaledColumn) {
  auto dir = test::temp_dir("csv");
  std::ofstream((dir / "in.csv").string()) << "t,pos,volt\n0,1,2\n0.1,2,4\n0.2,3,6\n0.3,4,8\n";
  Table t = read_csv_table((dir / "in.csv").string());
  ImportSpec spec;
  spec.x = {"q:j=pos"};
  spec.y = {"tau:j=volt*10"};
  spec.t = "t";
  spec.splits = {parse_split_range("train:0:75%"), parse_split_range("test:75%:")};
  Dataset ds = table_to_dataset(t, spec);
  ASSERT_EQ(ds.splits.size(), 2u);
  EXPECT_EQ(ds.splits[0].rows(), 3);
  EXPECT_EQ(ds.splits[1].rows(), 1);
  EXPECT_EQ(ds.splits[0].x_columns[0], "q:j");
  EXPECT_DOUBLE_EQ(ds.splits[1].Y(0, 0), 80.0);
  EXPECT_DOUBLE_EQ(ds.splits[1].t[0], 0.3);
  std::ofstream((dir / "bad.csv").string()) << "a,b\n1,x\n";
  try {
    read_csv_table((dir / "bad.csv").string());
    FAIL();
  } catch (const DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.csv:2: column 'b': 'x' is not a finite number"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

// ---- signal conditioning for measured data (spml import --lowpass/--derive/...) ----


TEST(Signal, ZeroPhaseButterworthIsMinus6dBAtTheCutoffAndPassesDc) {
  const double fs = 1000, fc = 50;
  const auto sos = spml::butterworth_lowpass(4, fc, fs);
  Eigen::VectorXd dc = Eigen::VectorXd::Constant(2000, 3.25);
  EXPECT_LT((spml::filtfilt(sos, dc).array() - 3.25).abs().maxCoeff(), 1e-12);
  // Forward-backward squares |H|: a sine at the cut-off leaves with half its amplitude, in phase.
  Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(4000, 0, 3999 / fs);
  Eigen::VectorXd x = (2 * M_PI * fc * t).array().sin();
  Eigen::VectorXd y = spml::filtfilt(sos, x);
  const Eigen::VectorXd mid_y = y.segment(1000, 2000), mid_x = x.segment(1000, 2000);
  EXPECT_NEAR(mid_y.cwiseAbs().maxCoeff(), 0.5, 0.005);
  EXPECT_NEAR(mid_y.dot(mid_x) / mid_x.squaredNorm(), 0.5, 0.005);   // no phase shift: all in phase
  // A tone at a fifth of the cut-off passes: |H|^2 = 1 / (1 + 0.2^8) ~ 1.
  Eigen::VectorXd slow = (2 * M_PI * 10 * t).array().sin();
  EXPECT_LT((spml::filtfilt(sos, slow) - slow).segment(500, 3000).cwiseAbs().maxCoeff(), 1e-3);
}

// A log that ends while the joint moves: each filter pass starts with a transient that the
// second differences amplify. Beyond settling_samples from each end (what import's warning
// asks --drop-edges to drop) the accelerations hold to 1 % of their peak. (A review's log,
// 50 samples dropped after a 20 Hz pass at 1 kHz, kept a 2.5 N m error in its last 0.1 s and
// diagnose missed a 3 ms delay for it.)
TEST(Signal, BeyondTheSettlingTheEndsOfAMovingLogKeepTheirAccelerations) {
  const double fs = 1000, fc = 20;
  const auto sos = spml::butterworth_lowpass(4, fc, fs);
  const Eigen::Index settle = spml::settling_samples(sos);
  EXPECT_GT(settle, 200);   // 20 Hz rings for about a fifth of a second at 1 kHz
  EXPECT_LT(settle, 500);
  const Eigen::Index n = 3000;
  const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(n, 0, (n - 1) / fs);
  // 1.3 Hz and 0.7 Hz: moving fast at both ends; qdd = -(w1^2 sin w1 t + 0.5 w2^2 sin(w2 t + 0.4)).
  const double w1 = 2 * M_PI * 1.3, w2 = 2 * M_PI * 0.7;
  const Eigen::VectorXd q = (w1 * t.array()).sin() + 0.5 * (w2 * t.array() + 0.4).sin();
  const Eigen::VectorXd qdd_true = -(w1 * w1 * (w1 * t.array()).sin() + 0.5 * w2 * w2 * (w2 * t.array() + 0.4).sin()).matrix();
  const Eigen::VectorXd qdd = spml::central_difference(spml::central_difference(spml::filtfilt(sos, q), 1 / fs), 1 / fs);
  const double peak = qdd_true.cwiseAbs().maxCoeff();
  EXPECT_LT((qdd - qdd_true).segment(settle, n - 2 * settle).cwiseAbs().maxCoeff(), 0.01 * peak);
}

TEST(Signal, ImportDerivesAccelerationsFromUnevenNoisyPositions) {
  // q = sin(2 pi 0.5 t) sampled about every 1 ms with jitter, plus 1e-5 rad noise: the
  // derived qdd must follow -(pi)^2 sin(pi t) within 1 % RMS once edges are dropped.
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> jitter(0.7e-3, 1.3e-3);
  std::normal_distribution<double> noise(0, 1e-5);
  std::vector<double> tv{0.0};
  while (tv.back() < 6.0) tv.push_back(tv.back() + jitter(rng));
  spml::Table table;
  table.source = "synthetic";
  table.names = {"time", "pos", "torque"};
  Eigen::VectorXd t = Eigen::Map<Eigen::VectorXd>(tv.data(), static_cast<Eigen::Index>(tv.size()));
  Eigen::VectorXd q(t.size()), tau(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    q[i] = std::sin(M_PI * t[i]) + noise(rng);
    tau[i] = std::cos(M_PI * t[i]);
  }
  table.columns = {t, q, tau};
  spml::ImportSpec spec;
  spec.x = {"q:j=pos"};
  spec.y = {"tau:j=torque"};
  spec.t = "time";
  spec.conditioning.lowpass_hz = 10;
  spec.conditioning.derive = true;
  spec.conditioning.drop_edges = 200;
  spec.conditioning.decimate = 5;
  const spml::Dataset ds = spml::table_to_dataset(table, spec);
  const spml::Split& s = ds.get("train");
  ASSERT_EQ(s.x_columns, (std::vector<std::string>{"q:j", "qd:j", "qdd:j"}));
  const double dt = s.t[1] - s.t[0];
  EXPECT_NEAR(dt, 5 * spml::median_step(t), 1e-12);   // uniform grid, decimated by 5
  double err = 0, ref = 0, verr = 0, vref = 0;
  for (Eigen::Index i = 0; i < s.rows(); ++i) {
    const double a = -M_PI * M_PI * std::sin(M_PI * s.t[i]), v = M_PI * std::cos(M_PI * s.t[i]);
    err += std::pow(s.X(i, 2) - a, 2), ref += a * a;
    verr += std::pow(s.X(i, 1) - v, 2), vref += v * v;
  }
  EXPECT_LT(std::sqrt(verr / vref), 0.002);
  EXPECT_LT(std::sqrt(err / ref), 0.01);
  EXPECT_NEAR(s.t[0], 200 * spml::median_step(t), 1e-9);   // 200 edge samples dropped
}

// derive_like_import and condition_like_import restate the import's chain for diagnose (its
// resolution floor and its chain bias replay a known motion through it): on the same raw log
// they give what the import wrote, a given velocity included, and the import records which
// states it derived (`derived_columns`).
TEST(Signal, TheImportsChainRestatedGivesWhatTheImportWrote) {
  const double fs = 1000;
  const Eigen::Index n = 4001;
  const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(n, 0, (n - 1) / fs);
  const Eigen::VectorXd q = (2 * M_PI * 3.1 * t.array()).sin() + 0.3 * (2 * M_PI * 7.3 * t.array() + 0.5).sin();
  const Eigen::VectorXd qd_b = 0.5 * (2 * M_PI * 1.7 * t.array()).cos(), q_b = (2 * M_PI * 1.1 * t.array()).sin();
  const Eigen::VectorXd tau = (2 * M_PI * 4.4 * t.array()).cos() + 0.1 * (2 * M_PI * 60 * t.array()).sin();
  spml::Table table;
  table.source = "synthetic";
  table.names = {"t", "qa", "qb", "vb", "tau"};
  table.columns = {t, q, q_b, qd_b, tau};
  spml::ImportSpec spec;
  spec.x = {"q:a=qa", "q:b=qb", "qd:b=vb"};
  spec.y = {"tau:a=tau"};
  spec.t = "t";
  spec.conditioning.lowpass_hz = 20;
  spec.conditioning.derive = true;
  spec.conditioning.decimate = 5;
  const spml::Dataset ds = spml::table_to_dataset(table, spec);
  EXPECT_EQ(ds.provenance.at("derived_columns"), "qd:a qdd:a qdd:b");
  const spml::Split& s = ds.get("train");
  const spml::LowpassRecord lowpass = *spml::parse_lowpass_record(ds.provenance.at("filter"));
  const spml::DecimationRecord decimation = *spml::parse_decimation_record(ds.provenance.at("decimation"));
  const spml::DerivedSignals a = spml::derive_like_import(q, fs, lowpass, decimation), b = spml::derive_like_import(q_b, fs, lowpass, decimation, &qd_b);
  const Eigen::VectorXd torque = spml::condition_like_import(tau, fs, lowpass, decimation);
  ASSERT_EQ(a.q.size(), s.rows());
  auto column = [&](const std::string& name) { return Eigen::VectorXd(s.X.col(s.x_index(name))); };
  for (const auto& [name, restated] : std::vector<std::pair<std::string, Eigen::VectorXd>>{
           {"q:a", a.q}, {"qd:a", a.qd}, {"qdd:a", a.qdd}, {"q:b", b.q}, {"qd:b", b.qd}, {"qdd:b", b.qdd}})
    EXPECT_LT((column(name) - restated).cwiseAbs().maxCoeff(), 1e-9 * (1 + restated.cwiseAbs().maxCoeff())) << name;
  EXPECT_LT((Eigen::VectorXd(s.Y.col(0)) - torque).cwiseAbs().maxCoeff(), 1e-12);
  // Given, the velocity is only filtered: the difference of its filtered position would differ.
  EXPECT_GT((b.qd - spml::derive_like_import(q_b, fs, lowpass, decimation).qd).cwiseAbs().maxCoeff(), 0.1);
}

// Raw central differences of an 18-bit encoder at 1 kHz: the acceleration's noise (a central
// difference of a central difference, / 4 dt^2: about 4 rad/s^2, 0.6 of the RMS of a 0.5 Hz,
// 1 rad sine's acceleration; 0.61 measured) lies near 500 Hz. Keeping every 10th sample alone folds it into the 50 Hz band; the
// decimation's anti-alias low-pass (40 Hz) keeps the share of a sin^4 spectrum below it,
// about 1e-5 of the power: under 1 % RMS error.
TEST(Import, DecimationLowPassesFirstUnlessToldNotTo) {
  const double step = 2 * M_PI / (1 << 18);
  spml::Table table;
  table.source = "synthetic";
  table.names = {"time", "pos", "torque"};
  Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(10000, 0, 9.999), q(t.size()), tau(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    q[i] = step * std::round(std::sin(M_PI * t[i]) / step);
    tau[i] = std::cos(M_PI * t[i]);
  }
  table.columns = {t, q, tau};
  auto relative_error = [&](bool anti_alias) {
    spml::ImportSpec spec;
    spec.x = {"q:j=pos"};
    spec.y = {"tau:j=torque"};
    spec.t = "time";
    spec.conditioning.derive = true;
    spec.conditioning.drop_edges = 100;
    spec.conditioning.decimate = 10;
    spec.conditioning.anti_alias = anti_alias;
    const spml::Dataset ds = spml::table_to_dataset(table, spec);
    const std::string record = ds.provenance.at("decimation");
    const auto d = spml::parse_decimation_record(record);
    EXPECT_TRUE(d && d->keep == 10) << record;
    if (anti_alias) {
      EXPECT_TRUE(d && d->anti_alias && d->anti_alias->order == 8 && std::fabs(d->anti_alias->cutoff_hz - 40) < 1e-9) << record;
    } else {
      EXPECT_EQ(record, "keep=10 plain");
    }
    EXPECT_EQ(ds.provenance.count("filter"), 0u);   // only --lowpass is the user's filter
    const spml::Split& s = ds.get("train");
    double err = 0, ref = 0;
    for (Eigen::Index i = 0; i < s.rows(); ++i) {
      const double a = -M_PI * M_PI * std::sin(M_PI * s.t[i]);
      err += std::pow(s.X(i, 2) - a, 2), ref += a * a;
    }
    return std::sqrt(err / ref);
  };
  EXPECT_FALSE(spml::parse_decimation_record("keep=x plain"));
  EXPECT_FALSE(spml::parse_decimation_record("keep=5 after nothing"));
  EXPECT_FALSE(spml::parse_decimation_record("keep=0 plain"));
  const double anti_aliased = relative_error(true), plain = relative_error(false);
  EXPECT_LT(anti_aliased, 0.01);
  EXPECT_GT(plain, 30 * anti_aliased);   // 0.61: the slow sine's quantization error is not white
}

// The encoder's step, found in the raw log, goes into the dataset (`position_steps`): diagnose
// judges what the quantization alone leaves in a joint's torque by it. A continuous column (a
// position with noise) has none; a log that changes too few times is not judged.
TEST(Import, AnEncodersStepIsFoundInTheRawLogAndRecorded) {
  const double step = 2 * M_PI / (1 << 12);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0, 1e-6);
  spml::Table table;
  table.source = "synthetic";
  table.names = {"time", "a", "b", "ta", "tb"};
  Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(4000, 0, 3.999), a(t.size()), b(t.size()), tau(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    a[i] = 0.3 + step * std::round(std::sin(M_PI * t[i]) / step);   // on a grid, about an offset
    b[i] = std::sin(M_PI * t[i]) + noise(rng);
    tau[i] = std::cos(M_PI * t[i]);
  }
  table.columns = {t, a, b, tau, tau};
  spml::ImportSpec spec;
  spec.x = {"q:a=a", "q:b=b"};
  spec.y = {"tau:a=ta", "tau:b=tb"};
  spec.t = "time";
  spec.conditioning.derive = true;
  spec.conditioning.lowpass_hz = 20;
  spec.conditioning.drop_edges = 307;
  const spml::Dataset ds = spml::table_to_dataset(table, spec);
  ASSERT_EQ(ds.provenance.count("position_steps"), 1u);
  const auto steps = spml::parse_position_steps(ds.provenance.at("position_steps"));
  ASSERT_EQ(steps.size(), 1u) << ds.provenance.at("position_steps");
  EXPECT_NEAR(steps.at("q:a"), step, 1e-9 * step);
  EXPECT_EQ(spml::parse_position_steps(spml::position_steps_text(steps)), steps);
  EXPECT_TRUE(spml::parse_position_steps("q:a=x").empty());
  EXPECT_TRUE(spml::parse_position_steps("q:a=-1").empty());
  // Ten changes are too few to tell a grid from chance.
  Eigen::VectorXd few = Eigen::VectorXd::Zero(100);
  for (int i = 0; i < 10; ++i) few.tail(10 * (i + 1)).array() += step;
  EXPECT_FALSE(spml::quantization_step(few));
  EXPECT_FALSE(spml::quantization_step(b));
}

TEST(Import, TextLogsWithSeveralValuesPerSample) {
  auto dir = spml::test::temp_dir("textlog");
  std::ofstream((dir / "pos.txt").string()) << "1\n2\n3\n4\n5\n6\n";
  std::ofstream((dir / "time.txt").string()) << "0 0.1 0.2\n";
  EXPECT_EQ(spml::expand_names("q:joint{1..3},t"), (std::vector<std::string>{"q:joint1", "q:joint2", "q:joint3", "t"}));
  spml::Table t = spml::read_text_logs({(dir / "pos.txt").string() + "=a,b", (dir / "time.txt").string() + "=time"});
  ASSERT_EQ(t.names, (std::vector<std::string>{"a", "b", "time"}));
  EXPECT_EQ(t.columns[1], (Eigen::Vector3d(2, 4, 6)));
  try {
    spml::read_text_logs({(dir / "pos.txt").string() + "=q:joint{1..4}"});
    FAIL();
  } catch (const spml::DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("pos.txt: 6 values are not a whole number of samples of 4"), std::string::npos) << e.what();
  }
}

namespace {

// The message of the DatasetError `f` throws ("" when it throws none).
template <class F>
std::string error_of(F f) {
  try {
    f();
  } catch (const spml::DatasetError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

// Issue #21: a log whose lines hold different counts shifted values between columns; an
// empty name list divided by zero.
TEST(Import, RaggedTextLogsAndEmptyNameListsAreRefused) {
  auto dir = spml::test::temp_dir("textlog-ragged");
  const std::string log = (dir / "pos.txt").string();
  std::ofstream(log) << "1 2 3\n4 5 6\n7 8\n9 10 11 12\n";   // 12 values: 4 samples of 3 by count alone
  EXPECT_NE(error_of([&] { read_text_logs({log + "=a,b,c"}); }).find("pos.txt:3: 2 values, but line 1 and those after it hold 3"),
            std::string::npos);
  EXPECT_NE(error_of([&] { read_text_logs({log + "="}); }).find("pos.txt: no column names after '='"), std::string::npos);
  EXPECT_NE(error_of([&] { read_text_logs({log + "=a,,b"}); }).find("empty column name"), std::string::npos);
  std::ofstream(log) << "1 2\n3 4\n5 6\n";   // two values a line, three names: no sample layout fits
  EXPECT_NE(error_of([&] { read_text_logs({log + "=a,b,c"}); }).find("pos.txt:1: 2 values on a line, but a sample has 3"),
            std::string::npos);
}

TEST(Import, QuotedCsvCellsAndByteOrderMark) {
  auto dir = spml::test::temp_dir("csv-quotes");
  const std::string csv = (dir / "in.csv").string();
  std::ofstream(csv) << "\xEF\xBB\xBFt,\"a,b\",\"say \"\"hi\"\"\"\n0,1,2\n0.1, 3 ,\"4\"\n";
  const Table t = read_csv_table(csv);
  ASSERT_EQ(t.names, (std::vector<std::string>{"t", "a,b", "say \"hi\""}));
  EXPECT_EQ(t.columns[1], Eigen::Vector2d(1, 3));
  EXPECT_EQ(t.columns[2], Eigen::Vector2d(2, 4));
  std::ofstream(csv) << "t,a\n0,\"1\n";
  EXPECT_NE(error_of([&] { read_csv_table(csv); }).find("in.csv:2: a quoted cell is not closed"), std::string::npos);
}

TEST(Import, TargetLeaksUnsortedTimeAndStrayTimeStampsAreRefused) {
  Table t;
  t.source = "log.csv";
  t.names = {"t", "a", "y"};
  const Eigen::Index n = 1000;
  Eigen::VectorXd time = Eigen::VectorXd::LinSpaced(n, 0.0, 0.999);
  t.columns = {time, Eigen::VectorXd::Random(n), Eigen::VectorXd::Random(n)};
  ImportSpec spec;
  spec.x = {"a"};
  spec.y = {"b=a*2"};
  EXPECT_NE(error_of([&] { table_to_dataset(t, spec); }).find("log.csv: column 'a' is both an input (--x a) and a target (--y b=a*2)"),
            std::string::npos);
  spec.y = {"y"};
  spec.t = "t";
  std::swap(t.columns[0][10], t.columns[0][11]);
  EXPECT_NE(error_of([&] { table_to_dataset(t, spec); }).find("log.csv: column 't': rows are not in time order (data row 12"),
            std::string::npos);
  std::swap(t.columns[0][10], t.columns[0][11]);
  t.columns[0][n - 1] = 1e5;   // one stray stamp: a 1 ms grid to 1e5 s would be 1e8 rows
  spec.conditioning.lowpass_hz = 50;
  EXPECT_NE(error_of([&] { table_to_dataset(t, spec); }).find("would make 1e+08 rows from 1000 (the largest gap: row 999"),
            std::string::npos);
  t.columns[0][n - 1] = 0.999;
  spec.conditioning.lowpass_hz = 600;   // above the 500 Hz Nyquist rate of 1 kHz samples
  EXPECT_NE(error_of([&] { table_to_dataset(t, spec); }).find("log.csv: --lowpass 600 Hz: the cut-off must lie below half the sampling rate, 500 Hz"),
            std::string::npos);
  spec.conditioning.lowpass_hz = 50;
  EXPECT_EQ(table_to_dataset(t, spec).splits[0].rows(), n);
}

TEST(Dataset, TimeOrderAndUtf8NamesAreChecked) {
  Dataset ds = small_dataset();
  ds.splits[1].t[3] = 0.05;
  EXPECT_NE(error_of([&] { validate(ds, "f.h5"); }).find("f.h5: group 'test': dataset 't': rows are not in time order (row 3"),
            std::string::npos);
  ds = small_dataset();
  ds.splits[0].x_columns[1] = "qd:\xe9";   // Latin-1, not UTF-8
  EXPECT_NE(error_of([&] { validate(ds, "f.h5"); }).find("f.h5: group 'train': dataset 'X': attribute 'columns': not valid UTF-8 (byte 0xe9 at offset 3"),
            std::string::npos);
  EXPECT_EQ(utf8_problem("q:\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80"), "");   // é, €, an emoji
  EXPECT_NE(utf8_problem("\xed\xa0\x80"), "");                               // a UTF-16 surrogate
  EXPECT_NE(utf8_problem("\xc0\xaf"), "");                                   // overlong
}

TEST(Dataset, OutputThatIsAFolderIsNamedAsGiven) {
  auto dir = spml::test::temp_dir("out-folder");
  const std::string folder = (dir / "sub").string();
  std::filesystem::create_directories(folder);
  EXPECT_EQ(error_of([&] { write_dataset(folder, small_dataset()); }), folder + ": is a directory; give a file name to write");
  for (const auto& e : std::filesystem::directory_iterator(dir)) EXPECT_EQ(e.path().filename(), "sub");
}

// --delimiter and --comment: a ';'-separated export with a '#' block above the header (and a
// quoted name holding the delimiter), and a tab-separated log whose missing cell is named.
TEST(Import, CsvDelimiterAndCommentLines) {
  auto dir = test::temp_dir("csv-dialect");
  std::ofstream((dir / "semi.csv").string()) << "# logger v2\n  # rate 1 kHz\nt;\"q;raw\";tau\n0;1.5;2\n# pause\n0.1; 2 ;4\n";
  CsvDialect d;
  d.delimiter = ';';
  d.comment = "#";
  const Table t = read_csv_table((dir / "semi.csv").string(), d);
  ASSERT_EQ(t.names, (std::vector<std::string>{"t", "q;raw", "tau"}));
  ASSERT_EQ(t.columns[2].size(), 2);
  EXPECT_DOUBLE_EQ(t.columns[1][0], 1.5);
  EXPECT_DOUBLE_EQ(t.columns[1][1], 2.0);
  EXPECT_DOUBLE_EQ(t.columns[2][1], 4.0);
  // without --comment the first '#' line is the header: refused naming the line that differs
  EXPECT_NE(error_of([&] { read_csv_table((dir / "semi.csv").string(), CsvDialect{';', ""}); }).find("semi.csv:3: 3 fields, header has 1"),
            std::string::npos);
  std::ofstream((dir / "tab.csv").string()) << "t\tq\n0\t1\n0.1\t\n";
  EXPECT_NE(error_of([&] { read_csv_table((dir / "tab.csv").string(), CsvDialect{'\t', ""}); }).find("tab.csv:3: column 'q': '' is not"),
            std::string::npos);
  EXPECT_NE(error_of([&] { read_csv_table((dir / "tab.csv").string(), CsvDialect{'"', ""}); }).find("delimiter cannot be a quote"),
            std::string::npos);
}
