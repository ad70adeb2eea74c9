// Stage 2, prepare: one split made ready for the least squares - its joint columns, the stacked
// base regressor, the stacked torques and what the model as given predicts.
#include "diagnosis.h"

namespace spml::diagnose_detail {

SplitData Diagnosis::prepare(const Split& s) {
  SplitData d;
  d.name = s.name;
  d.split = s;
  const std::string where = opt_.data + ": ";
  try {
    d.cols = std::make_unique<JointColumns>(*reg_, s);
  } catch (const DatasetError& e) {
    std::string msg = e.what();
    if (msg.find("qdd:") != std::string::npos) msg += " (measured data: `spml import --derive` adds qd:/qdd: by filtered differentiation)";
    throw DatasetError(where + msg);
  }
  if (!s.X.allFinite() || !s.Y.allFinite()) throw DatasetError(where + "split '" + s.name + "': holds NaN or Inf values");
  d.N = s.rows();
  {
    // The base block touches every output: kept whole.
    const Eigen::MatrixXd A = stacked_base_regressor(*reg_, base_, s.X, *d.cols, where + "split " + s.name);
    d.base.rows_per_output = d.N;
    d.base.outputs = static_cast<int>(s.Y.cols());
    d.base.cols = static_cast<int>(A.cols());
    for (int o = 0; o < d.base.outputs; ++o) {
      d.base.active.push_back(o);
      d.base.parts.emplace_back(A.middleRows(o * d.N, d.N));
    }
  }
  d.b = stacked_targets(s.Y);
  d.given = d.base.times(base_.model_values);
  d.y0 = d.b - d.given;
  return d;
}

}  // namespace spml::diagnose_detail
