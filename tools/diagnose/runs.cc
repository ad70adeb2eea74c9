// Several records of one robot (--data given more than once): each record's fit and test parts
// are chosen as for one record, then stacked - fit parts into the fit split, test parts into
// the test split - with the record boundaries kept (SplitData::runs), so that the parallel
// filter and the rollouts never run across the junction of two records. Time stamps of a later
// record are shifted to follow the earlier one's by one median step (rollout and filter windows
// need increasing time); the filter's sections come from the stacked split's median step, so the
// records should share one sampling rate.
#include "diagnosis.h"
#include "spml/signal.h"

namespace spml::diagnose_detail {
namespace {

// b's rows appended to a's, columns matched by name; b's time shifted after a's.
Split append_record(const Split& a, const Split& b, const std::string& file) {
  Split out = in_column_order(b, a.y_columns, file);
  if (out.x_columns != a.x_columns) {
    RowMatrix X(out.rows(), static_cast<Eigen::Index>(a.x_columns.size()));
    for (size_t k = 0; k < a.x_columns.size(); ++k) {
      const int c = out.x_index(a.x_columns[k]);
      if (c < 0) throw DatasetError(file + ": split '" + b.name + "' has no column '" + a.x_columns[k] + "' that the first record has");
      X.col(static_cast<Eigen::Index>(k)) = out.X.col(c);
    }
    out.X = X;
    out.x_columns = a.x_columns;
  }
  if ((a.t.size() == 0) != (b.t.size() == 0)) throw DatasetError(file + ": split '" + b.name + "': one record has time stamps, the other not");
  Split joined = a;
  joined.X.conservativeResize(a.rows() + out.rows(), Eigen::NoChange);
  joined.X.bottomRows(out.rows()) = out.X;
  joined.Y.conservativeResize(a.rows() + out.rows(), Eigen::NoChange);
  joined.Y.bottomRows(out.rows()) = out.Y;
  if (a.t.size() > 0) {
    const double step = a.rows() > 1 ? median_step(a.t) : 1.0;
    joined.t.conservativeResize(a.rows() + out.rows());
    joined.t.tail(out.rows()) = out.t.array() - out.t[0] + a.t[a.rows() - 1] + step;
  }
  return joined;
}

}  // namespace

// The further records' parts, appended to the first record's; their first rows go to *_runs.
void Diagnosis::load_more_records(Split& fit_part, Split& test_part, std::vector<Eigen::Index>& fit_runs,
                                  std::vector<Eigen::Index>& test_runs) {
  for (const auto& file : opt_.more_data) {
    const Dataset other = read_dataset(file);
    if (other.provenance.count("filter") != ds_.provenance.count("filter") ||
        (ds_.provenance.count("filter") && other.provenance.at("filter") != ds_.provenance.at("filter")))
      throw DatasetError(file + ": its recorded filter differs from " + opt_.data + "'s: records diagnosed together must be conditioned alike");
    Split f, t;
    choose_splits(other, file, f, t);
    fit_runs.push_back(fit_part.rows());
    test_runs.push_back(test_part.rows());
    fit_part = append_record(fit_part, f, file);
    test_part = append_record(test_part, in_column_order(t, fit_part.y_columns, file), file);
  }
}

}  // namespace spml::diagnose_detail
