// The positions' quantization, replayed: a split's motion quantized once more to the encoder
// steps spml import recorded (`position_steps`), on grids shifted against the first, and sent
// through the import's own chain (derive_like_import) - errors of the kind the measured states
// carry, drawn afresh. Two readers: the floor a joint's residual cannot go below
// (resolution_floor, read by `unexplained`), and the errors in variables the delay search
// takes out of its normal equations (delay.cc, noise_gram).
#include <algorithm>
#include <cmath>
#include <iterator>

#include "diagnosis.h"
#include "spml/signal.h"

namespace spml::diagnose_detail {

// The grids, shifted by these shares of a step, the motion is quantized on. The filtered
// positions keep the slow part of their own quantization error: quantized again on the same
// grid they sit on its steps where the motion is slow, and a yaw joint's floor read 0.19 N m
// where 0.68 was measured. On grids shifted by a quarter to three quarters of a step the mean
// was within 0.77-1.24 times the true chain's on 28 columns of a logged arm at 10-16 bits
// (a SciPy check of the same chain).
constexpr double kGridOffsets[] = {0.25, 0.375, 0.5, 0.625, 0.75};

// The split's states with each record's motion, interpolated back to the log's rate (cubic
// Hermite through the positions and velocities), quantized to the recorded steps on the grid
// shifted by `offset` of a step, and derived as the import derived it: the error added to q:,
// qd: and qdd: of every joint with a recorded step. Records shorter than 8 rows are left as
// they are. `edge_rows`: the rows at each record's ends the chain's start-up reaches, which
// the readers leave out. Empty (no states) where the dataset records no steps.
Diagnosis::Requantized Diagnosis::requantized(const SplitData& split, const std::vector<double>& offsets) const {
  Requantized out;
  const auto steps = parse_position_steps(ds_.provenance.count("position_steps") ? ds_.provenance.at("position_steps") : "");
  const RowMatrix& X = split.split.X;
  const Eigen::VectorXd& t = split.split.t;
  if (steps.empty() || t.size() != X.rows() || X.rows() < 8) return out;
  const ImportChain chain = import_chain();
  const int keep = chain.keep();
  const double raw_rate = keep / median_step(t);
  out.edge_rows = chain_edge_rows(split);
  const std::vector<std::string>& joints = reg_->joint_names();
  const std::vector<Eigen::Index> bounds = segment_bounds(X.rows(), split.runs);
  for (const double offset : offsets) {
    RowMatrix E = X;
    for (size_t r = 0; r + 1 < bounds.size(); ++r) {
      const Eigen::Index b = bounds[r], L = bounds[r + 1] - bounds[r];
      if (L < 8) continue;
      for (size_t k = 0; k < joints.size(); ++k) {
        const auto found = steps.find("q:" + joints[k]);
        if (found == steps.end()) continue;
        const double step = found->second, shift = offset * step;
        const int qc = split.cols->q[k], vc = split.cols->qd[k];
        auto error = [&](double q) { return step * std::round((q + shift) / step) - (q + shift); };
        Eigen::VectorXd err((L - 1) * keep + 1);
        for (Eigen::Index i = 0; i + 1 < L; ++i) {
          const double h = t[b + i + 1] - t[b + i];
          for (int m = 0; m < keep; ++m) {
            const double s = static_cast<double>(m) / keep, s2 = s * s, s3 = s2 * s;
            err[i * keep + m] = error((2 * s3 - 3 * s2 + 1) * X(b + i, qc) + (s3 - 2 * s2 + s) * h * X(b + i, vc) + (-2 * s3 + 3 * s2) * X(b + i + 1, qc) +
                                      (s3 - s2) * h * X(b + i + 1, vc));
          }
        }
        err[err.size() - 1] = error(X(b + L - 1, qc));
        const DerivedSignals d = derive_like_import(err, raw_rate, chain.lowpass, chain.decimation);
        E.col(qc).segment(b, L) += d.q;
        E.col(vc).segment(b, L) += d.qd;
        E.col(split.cols->qdd[k]).segment(b, L) += d.qdd;
      }
    }
    out.states.push_back(std::move(E));
  }
  return out;
}

// What the positions' quantization alone leaves in each joint's residual on `split` (RMS per
// output joint; none where the dataset records no `position_steps`; the floor follows the
// motion and the postures, and differs between splits): the requantized states' torques through
// the model as given, less the measured states', through diagnose's own filter, the mean over
// kGridOffsets. A twenty-second review's 12-bit encoders left 5-48 % of model-exact joints'
// torques `left_unexplained`, said as a load or a stop.
std::map<std::string, double> Diagnosis::resolution_floor(const SplitData& split) const {
  std::map<std::string, double> out;
  const Requantized Q = requantized(split, std::vector<double>(std::begin(kGridOffsets), std::end(kGridOffsets)));
  if (Q.states.empty()) return out;
  const RowMatrix& X = split.split.X;
  const auto O = static_cast<Eigen::Index>(out_joints_.size());
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(O);
  double rows = 0;
  const std::vector<Eigen::Index> bounds = segment_bounds(X.rows(), split.runs);
  const std::string where = opt_.data + ": resolution floor";
  for (size_t r = 0; r + 1 < bounds.size(); ++r) {
    const Eigen::Index b = bounds[r], L = bounds[r + 1] - bounds[r];
    if (L < 8) continue;
    const Eigen::VectorXd at_rest = stacked_base_regressor(*reg_, base_, X.middleRows(b, L), *split.cols, where) * base_.model_values;
    const Eigen::Index edge = std::min<Eigen::Index>(L / 4, Q.edge_rows);
    for (const RowMatrix& E : Q.states) {
      Eigen::VectorXd dtau = stacked_base_regressor(*reg_, base_, E.middleRows(b, L), *split.cols, where) * base_.model_values - at_rest;
      filter_stacked(split.sos, dtau, L);
      for (Eigen::Index o = 0; o < O; ++o) sum[o] += dtau.segment(o * L + edge, L - 2 * edge).squaredNorm() / static_cast<double>(Q.states.size());
    }
    rows += static_cast<double>(L - 2 * edge);
  }
  if (rows > 0)
    for (Eigen::Index o = 0; o < O; ++o) out[out_joints_[static_cast<size_t>(o)]] = std::sqrt(sum[o] / rows);
  return out;
}

}  // namespace spml::diagnose_detail
