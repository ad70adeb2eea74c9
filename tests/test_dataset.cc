#include <gtest/gtest.h>

#include <fstream>

#include "spml/dataset.h"
#include "spml/import.h"
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
