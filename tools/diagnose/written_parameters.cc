// Stage 6a, the parameters extended.xml states when `parameters` is named. The decision rests on
// base parameters (selection.cc: instrumental variables by default); base parameters do not define
// bodies, and turned back into per-body values they can be no mass distribution at all (the
// Panda's links: negative principal moments). What is written comes from the physically
// consistent fit of spml identify --estimator consistent (envs/identification/: log-Cholesky
// bodies, Rucker & Wensing 2022; joint terms >= 0; a prior toward the MJCF), made on the same
// fit split through the same parallel filter, with the effects found fitted jointly as free
// columns, so that every fitted body is written and the effects' amplitudes go with it.
#include "diagnosis.h"
#include "spml/envs/identified_model.h"

namespace spml::diagnose_detail {

WrittenParameters Diagnosis::consistent_parameters() const {
  Eigen::MatrixXd W = stacked_standard_regressor(*reg_, fit_.split.X, *fit_.cols, opt_.data + ": split " + fit_.name);
  filter_stacked(fit_.sos, W, fit_.N, fit_.runs);
  const std::vector<int> effects = kept_effects();
  // The offset between torques and states goes free beside them, last (decide_parameters says
  // why): it is the data's, not the model's, so it is left out of the written prediction.
  const BlockColumns offset = offset_column(fit_);
  Eigen::Index ne = 0;
  for (int k : effects) ne += cands_[static_cast<size_t>(k)].fit_cols.cols;
  Eigen::MatrixXd E(W.rows(), ne + offset.cols);
  Eigen::Index at = 0;
  for (int k : effects) {
    const BlockColumns& c = cands_[static_cast<size_t>(k)].fit_cols;
    E.middleCols(at, c.cols) = c.dense();
    at += c.cols;
  }
  if (offset.cols > 0) E.rightCols(offset.cols) = offset.dense();
  ConsistentOptions o;
  o.prior_weight = opt_.prior_weight;
  WrittenParameters w;
  if (twin_ && filter_plan_.source != FilterPlan::Source::recorded) {
    // Two-stage least squares, the consistent fit's form of the IV estimate that named
    // `parameters`: the columns are replaced by their projections onto the instruments' span
    // (the same columns on the model's simulated states), so the noise of differentiated
    // accelerations does not shrink the written inertias (a 2 kg payload on a 4-joint arm, raw
    // differences: least squares wrote the link masses 5.10 / 3.20 / 1.13 kg for 2.5 / 1.5 / 2.8).
    // Not through a recorded low-pass, where that noise is gone and the projection only costs
    // efficiency (the Panda: joint 7's rollouts 22.7 mrad two-stage, 21.0 one-stage, 22.0 shipped).
    Eigen::MatrixXd Z(W.rows(), W.cols() + E.cols());
    Z.leftCols(W.cols()) = stacked_standard_regressor(*reg_, twin_->split.X, *twin_->cols, opt_.data + ": split " + fit_.name + " (simulated)");
    filter_stacked(twin_->sos, Z, twin_->N, twin_->runs);
    at = W.cols();
    for (int k : effects) {
      const BlockColumns c = columns_of(cands_[static_cast<size_t>(k)], *twin_);
      Z.middleCols(at, c.cols) = c.dense();
      at += c.cols;
    }
    if (offset.cols > 0) {
      const BlockColumns zo = offset_column(*twin_);
      Z.rightCols(offset.cols) = zo.cols == offset.cols ? zo.dense() : offset.dense();
    }
    const BlockColumns zb = BlockColumns::from_dense(Z, fit_.N, fit_.base.outputs);
    const Eigen::MatrixXd Q = fit_blocks({&zb}, Eigen::VectorXd::Zero(Z.rows()), true).Q();   // the span Z determines
    const Eigen::MatrixXd Wp = Q * (Q.transpose() * W), Ep = Q * (Q.transpose() * E);
    w.id = fit_consistent(*reg_, Wp, fit_.b, o, Ep);
    w.two_stage = true;
  } else {
    w.id = fit_consistent(*reg_, W, fit_.b, o, E);
  }
  w.prediction_fit = W * w.id.pi;
  if (ne > 0) w.prediction_fit += E.leftCols(ne) * w.id.extra.head(ne);
  return w;
}

// What report.json says about the written parameters (the `parameters` cause's "written").
nlohmann::json written_parameters_json(const WrittenParameters& w) {
  const ConsistentIdentification& id = w.id;
  nlohmann::json bodies = nlohmann::json::object(), terms = nlohmann::json::object();
  for (const auto& b : id.bodies) {
    if (!b.fitted) continue;
    const auto f = b.identified.fullinertia();
    bodies[b.name] = {{"mass", b.identified.mass}, {"com", {b.identified.com[0], b.identified.com[1], b.identified.com[2]}},
                      {"fullinertia", f}, {"prior_mass", b.prior.mass}, {"std_error", std::vector<double>(b.std_error.data(), b.std_error.data() + 10)},
                      {"changed", b.changed}};
  }
  for (const auto& t : id.terms)
    if (t.fitted) terms[t.name] = {{"value", t.value}, {"prior", t.prior}, {"std_error", t.std_error}};
  return {{"estimator", w.two_stage ? "consistent, two-stage (instruments of iv)" : "consistent"}, {"prior_weight", id.prior_weight}, {"bodies", bodies}, {"terms", terms},
          {"evaluations", id.evaluations}, {"stop", id.stop}, {"seconds", id.seconds}};
}

}  // namespace spml::diagnose_detail
