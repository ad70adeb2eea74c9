// The processing chain's own bias in the base parameters, measured by replaying the chain on
// the model's own motion. The import differentiates low-passed positions by central
// differences, whose gain on the accelerations falls as (w h)^2 / 3; diagnose filters the
// model's columns a second time; the instrumental variables weigh the rows their own way. Each
// stage moves an exact model's base parameters by a few hundredths of a per cent, and a long log
// resolves that: an exact hinge under 3-8 Hz moves read its inertia 0.17 % high, 266 standard
// errors without noise and 21 at 1 % torque noise, and `parameters` was named (README, Known
// wrong answers). The chain is known from the dataset's provenance, so its bias can be measured
// rather than argued: the model as given makes the torques of a motion like the log's, exactly,
// at the log's own rate; torques and positions go through the import's chain and diagnose's
// preparation; and what the estimate reads there, against the model's own values, is the
// chain's alone. decide_parameters takes it out of the estimates before it tests them.
#include <cmath>

#include "diagnosis.h"
#include "spml/signal.h"

namespace spml::diagnose_detail {
namespace {

// Half-stencils of central differences of orders 2, 4, 6, 8 (Fornberg's coefficients): the
// first derivative is sum_k c_k (x[i+k] - x[i-k]) / h, the second (c_0 x[i] + sum_k c_k (x[i+k]
// + x[i-k])) / h^2. At order 8 their gains are within 4e-5 and 7e-6 of the exact ones up to a
// tenth of the node rate (w h = 0.63: a 20 Hz band at 200 Hz), where the biases they stand in
// for are 1e-4 and more: the replay's motion is smoother than what it measures.
constexpr double kFirst[4][4] = {{1. / 2}, {2. / 3, -1. / 12}, {3. / 4, -3. / 20, 1. / 60}, {4. / 5, -1. / 5, 4. / 105, -1. / 280}};
constexpr double kSecondCentre[4] = {-2., -5. / 2, -49. / 18, -205. / 72};
constexpr double kSecond[4][4] = {{1.}, {4. / 3, -1. / 12}, {3. / 2, -3. / 20, 1. / 90}, {8. / 5, -1. / 5, 8. / 315, -1. / 560}};
constexpr Eigen::Index kStencilHalf = 4;

// Node derivatives of `x` (step h): the highest order whose stencil fits, the two end nodes
// their neighbour's (the rows there are left out of the replay's fit).
void node_derivatives(const Eigen::VectorXd& x, double h, Eigen::VectorXd& v, Eigen::VectorXd& a) {
  const Eigen::Index n = x.size();
  v.setZero(n);
  a.setZero(n);
  for (Eigen::Index i = 1; i + 1 < n; ++i) {
    const Eigen::Index m = std::min({kStencilHalf, i, n - 1 - i});
    double d1 = 0, d2 = kSecondCentre[m - 1] * x[i];
    for (Eigen::Index k = 1; k <= m; ++k) {
      d1 += kFirst[m - 1][k - 1] * (x[i + k] - x[i - k]);
      d2 += kSecond[m - 1][k - 1] * (x[i + k] + x[i - k]);
    }
    v[i] = d1 / h;
    a[i] = d2 / (h * h);
  }
  if (n >= 3) {
    v[0] = v[1], a[0] = a[1];
    v[n - 1] = v[n - 2], a[n - 1] = a[n - 2];
  }
}

// Quintic Hermite through (p, v, a) at s = 0 and 1 of an interval of length h: the value and its
// first two time derivatives at s. Continuous to the second derivative across the nodes, so the
// torques it makes have no steps a low-pass would ring on.
struct Hermite {
  double p, v, a;
};
Hermite quintic(double s, double h, double p0, double v0, double a0, double p1, double v1, double a1) {
  const double s2 = s * s, s3 = s2 * s, s4 = s3 * s, s5 = s4 * s;
  const double h0 = 1 - 10 * s3 + 15 * s4 - 6 * s5, h1 = s - 6 * s3 + 8 * s4 - 3 * s5, h2 = 0.5 * (s2 - 3 * s3 + 3 * s4 - s5);
  const double h3 = 10 * s3 - 15 * s4 + 6 * s5, h4 = -4 * s3 + 7 * s4 - 3 * s5, h5 = 0.5 * (s3 - 2 * s4 + s5);
  const double d0 = -30 * s2 + 60 * s3 - 30 * s4, d1 = 1 - 18 * s2 + 32 * s3 - 15 * s4, d2 = 0.5 * (2 * s - 9 * s2 + 12 * s3 - 5 * s4);
  const double d3 = -d0, d4 = -12 * s2 + 28 * s3 - 15 * s4, d5 = 0.5 * (3 * s2 - 8 * s3 + 5 * s4);
  const double e0 = -60 * s + 180 * s2 - 120 * s3, e1 = -36 * s + 96 * s2 - 60 * s3, e2 = 0.5 * (2 - 18 * s + 36 * s2 - 20 * s3);
  const double e3 = -e0, e4 = -24 * s + 84 * s2 - 60 * s3, e5 = 0.5 * (6 * s - 24 * s2 + 20 * s3);
  const double hv0 = h * v0, hv1 = h * v1, ha0 = h * h * a0, ha1 = h * h * a1;
  return {h0 * p0 + h1 * hv0 + h2 * ha0 + h3 * p1 + h4 * hv1 + h5 * ha1,
          (d0 * p0 + d1 * hv0 + d2 * ha0 + d3 * p1 + d4 * hv1 + d5 * ha1) / h,
          (e0 * p0 + e1 * hv0 + e2 * ha0 + e3 * p1 + e4 * hv1 + e5 * ha1) / (h * h)};
}

}  // namespace

Diagnosis::ImportChain Diagnosis::import_chain() const {
  ImportChain c;
  if (ds_.provenance.count("filter")) c.lowpass = parse_lowpass_record(ds_.provenance.at("filter"));
  if (ds_.provenance.count("decimation"))
    if (const auto d = parse_decimation_record(ds_.provenance.at("decimation"))) c.decimation = *d;
  return c;
}

// The import's low-pass, anti-alias and decimation reach this many of a split's rows at each
// end of a record, and diagnose's own filter (settling, in rows) this many more.
Eigen::Index Diagnosis::chain_edge_rows(const SplitData& s) const {
  const ImportChain chain = import_chain();
  const int keep = chain.keep();
  const double step = s.split.t.size() > 1 ? median_step(s.split.t) : 0;
  if (!(step > 0)) return 0;
  const double raw_rate = keep / step;
  Eigen::Index settle = 0;   // raw samples the import's passes start up over
  for (const auto& f : {chain.lowpass, chain.decimation.anti_alias})
    if (f && f->cutoff_hz < 0.5 * raw_rate) settle += settling_samples(butterworth_lowpass(f->order, f->cutoff_hz, raw_rate));
  return settle / keep + (s.sos.empty() ? 0 : settling_samples(s.sos.sections)) + 2;
}

// The split replayed through the chain (see the top): along a motion through its positions
// (quintic Hermite between the rows, the node derivatives by 8th-order central stencils), at the
// rate the import ran at, the model's torques as given (its inverse dynamics as prepare() forms
// them, MuJoCo's frictionloss and declared forces included) and the positions go through the
// import's chain - its recorded low-pass on everything, central differences for the states it
// derived (spml/1 `derived_columns`), the low-pass in their place for the states it was given,
// the decimation - and the result is prepared like the split. Null, with `why`, where the chain
// is not known.
std::unique_ptr<SplitData> Diagnosis::replayed_chain(const SplitData& s, std::string& why) {
  const auto& prov = ds_.provenance;
  if (!prov.count("derivatives") || prov.at("derivatives") != "central-difference" || !prov.count("derived_columns")) {
    why = prov.count("derivatives") && prov.at("derivatives") == "central-difference"
              ? "the dataset does not record which states the import derived (spml/1 `derived_columns`, written since stop 61)"
              : "the dataset's states were not derived by spml import (no `derivatives` = \"central-difference\"): their chain is not known";
    return nullptr;
  }
  std::set<std::string> derived;
  {
    std::istringstream in(prov.at("derived_columns"));
    for (std::string c; in >> c;) derived.insert(c);
  }
  const ImportChain chain = import_chain();
  const int keep = chain.keep();
  // Where the parallel filter decides column by column (its probe: smooth columns left as the
  // states made them, switching ones filtered again), the replay's columns, free of the log's
  // noise, are not decided alike: a review's fast moves through a 10 Hz import read the replayed
  // inertia +62 % where the log read +0.26 %, and named `parameters` on an exact arm.
  if (s.sos.probe_hz > 0) {
    why = "the parallel filter leaves smooth columns as the states made them and decides column by column (above " + fmt(s.sos.probe_hz, 4) +
          " Hz): the replay's noise-free columns would not be filtered as the log's are";
    return nullptr;
  }
  const Split& in = s.split;
  if (in.t.size() != in.rows() || in.rows() < 8 * kStencilHalf) {
    why = "the split has no time stamps or fewer than " + std::to_string(8 * kStencilHalf) + " rows";
    return nullptr;
  }
  const double raw_rate = keep / median_step(in.t);
  const std::vector<std::string>& joints = reg_->joint_names();
  Split out = in;
  const std::vector<Eigen::Index> bounds = segment_bounds(in.rows(), s.runs);
  // The replay starts the chain at each record's ends, where the log did not: those rows are
  // left out of its fit, and a record must keep at least as many between them (a review's fit
  // split of 58 rows read a chain bias of 36 standard errors from its ends alone).
  const Eigen::Index edge = chain_edge_rows(s) + kStencilHalf;
  for (size_t r = 0; r + 1 < bounds.size(); ++r) {
    const Eigen::Index b = bounds[r], L = bounds[r + 1] - bounds[r], Lr = (L - 1) * keep + 1;
    if (L < std::max<Eigen::Index>(8 * kStencilHalf, 4 * edge)) {
      why = "a record of the split has " + std::to_string(L) + " rows, fewer than four times the " + std::to_string(edge) +
            " at each end the replayed chain starts up over";
      return nullptr;
    }
    const double h = (in.t[b + L - 1] - in.t[b]) / static_cast<double>(L - 1);
    Split raw;
    raw.name = in.name + " (replayed at " + fmt(raw_rate) + " Hz)";
    raw.x_columns = in.x_columns;
    raw.y_columns = in.y_columns;
    raw.X.resize(Lr, in.X.cols());
    raw.Y.resize(Lr, in.Y.cols());
    raw.t.resize(Lr);
    const auto& cols = *s.cols;
    std::vector<Eigen::VectorXd> p(joints.size()), v(joints.size()), a(joints.size());   // per joint: the nodes
    for (size_t j = 0; j < joints.size(); ++j) {
      p[j] = in.X.col(cols.q[j]).segment(b, L);
      node_derivatives(p[j], h, v[j], a[j]);
    }
    for (Eigen::Index i = 0; i < Lr; ++i) {
      const Eigen::Index n = std::min<Eigen::Index>(i / keep, L - 2);
      const double f = static_cast<double>(i - n * keep) / keep;
      // Linear between the rows: the time, the torques (prepare() checks the model's against
      // them), any column that is no joint state; the joints' states on the quintic.
      raw.t[i] = (1 - f) * in.t[b + n] + f * in.t[b + n + 1];
      raw.X.row(i) = (1 - f) * in.X.row(b + n) + f * in.X.row(b + n + 1);
      raw.Y.row(i) = (1 - f) * in.Y.row(b + n) + f * in.Y.row(b + n + 1);
      for (size_t j = 0; j < joints.size(); ++j) {
        const Hermite m = quintic(f, h, p[j][n], v[j][n], a[j][n], p[j][n + 1], v[j][n + 1], a[j][n + 1]);
        raw.X(i, cols.q[j]) = m.p, raw.X(i, cols.qd[j]) = m.v, raw.X(i, cols.qdd[j]) = m.a;
      }
    }
    SplitData exact;
    try {
      exact = prepare(raw, {}, nullptr, false);
    } catch (const std::exception& e) {
      why = std::string("the model's torques along the replayed motion could not be formed (") + e.what() + ")";
      return nullptr;
    }
    for (Eigen::Index o = 0; o < in.Y.cols(); ++o)
      out.Y.col(o).segment(b, L) = condition_like_import(exact.given.segment(o * Lr, Lr), raw_rate, chain.lowpass, chain.decimation);
    for (size_t j = 0; j < joints.size(); ++j) {
      const int qc = cols.q[j], vc = cols.qd[j], ac = cols.qdd[j];
      const Eigen::VectorXd v = raw.X.col(vc), a = raw.X.col(ac);
      const bool dv = derived.count("qd:" + joints[j]) > 0, da = derived.count("qdd:" + joints[j]) > 0;
      const DerivedSignals d = derive_like_import(raw.X.col(qc), raw_rate, chain.lowpass, chain.decimation, dv ? nullptr : &v, da ? nullptr : &a);
      out.X.col(qc).segment(b, L) = d.q;
      out.X.col(vc).segment(b, L) = d.qd;
      out.X.col(ac).segment(b, L) = d.qdd;
    }
  }
  out.name = in.name + " (replayed)";
  try {
    return std::make_unique<SplitData>(prepare(out, s.runs));
  } catch (const std::exception& e) {
    why = std::string("the replayed split could not be prepared (") + e.what() + ")";
    return nullptr;
  }
}

// What the chain alone reads in the base parameters with `causes` free beside them: the fit
// decide_parameters makes (instrumental variables or least squares), on the replayed fit split,
// its rows within chain_edge_rows of a record's ends left out (the replay starts the chain
// there; the log did not) and so are those `mask` leaves out. Nothing (the reason in
// chain_why_) where the chain is not known.
std::optional<Eigen::VectorXd> Diagnosis::chain_bias(const std::vector<int>& causes, const Eigen::VectorXd& mask) {
  const bool first = !replay_tried_;
  if (first) {
    replay_tried_ = true;
    replayed_ = replayed_chain(fit_, chain_why_);
  }
  if (!replayed_) return std::nullopt;
  const SplitData& R = *replayed_;
  const auto O = static_cast<Eigen::Index>(R.y0.size() / std::max<Eigen::Index>(R.N, 1));
  const Eigen::Index edge = chain_edge_rows(R) + kStencilHalf;   // each record holds 4 (replayed_chain)
  Eigen::VectorXd inner = Eigen::VectorXd::Ones(R.y0.size());
  const std::vector<Eigen::Index> bounds = segment_bounds(R.N, R.runs);
  for (Eigen::Index o = 0; o < O; ++o)
    for (size_t r = 0; r + 1 < bounds.size(); ++r) {
      const Eigen::Index b = bounds[r], L = bounds[r + 1] - bounds[r];
      inner.segment(o * R.N + b, edge).setZero();
      inner.segment(o * R.N + b + L - edge, edge).setZero();
    }
  if (first) {
    // The chain alone can leave no more than the log's residual with the model as given, which
    // holds it and the noise: where it leaves more on a joint, the replay is not the log's chain.
    for (Eigen::Index o = 0; o < O; ++o) {
      const auto seg = [&](const Eigen::VectorXd& v) { return v.segment(o * R.N, R.N).cwiseProduct(inner.segment(o * R.N, R.N)).norm(); };
      if (seg(R.y0) > seg(fit_.y0)) {
        chain_why_ = "the replayed chain leaves joint " + out_joints_[static_cast<size_t>(o)] + " more residual than the log does with the model as given (" +
                     fmt(seg(R.y0) / std::max(seg(fit_.y0), 1e-300), 3) + " times): it is not the log's chain";
        replayed_.reset();
        return std::nullopt;
      }
    }
  }
  if (mask.size() == inner.size()) inner = inner.cwiseProduct(mask);
  const Fit f = iv_refit(causes, inner, &R);
  Eigen::VectorXd bias = f.coef.head(base_.rank);
  for (int i = 0; i < base_.rank; ++i)
    if (!f.determined[static_cast<size_t>(i)] || !std::isfinite(bias[i])) bias[i] = 0;
  return bias;
}

}  // namespace spml::diagnose_detail
