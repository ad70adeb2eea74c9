// Stage 1, load: the model, its base parameters, the dataset and the splits diagnose works on.
#include <algorithm>
#include <cmath>
#include <iostream>

#include "diagnosis.h"
#include "spml/matrix_file.h"

namespace spml::diagnose_detail {

// Rows a fit or test split needs at the least (uniform steps, differences, a hold-out).
constexpr Eigen::Index kMinRows = 10;
// A declared force this many times the measured torques' RMS is said (a warning): a value off by
// orders of magnitude, not a model to diagnose.
constexpr double kImplausibleForce = 1e3;

void Diagnosis::load() {
  RegressorOptions ro;
  ro.coulomb_only_where_modelled = true;
  reg_ = std::make_unique<MjcfRegressor>(opt_.model, ro);
  base_ = reg_->base_parameters();
  // The base-parameter rank decision is said in every report (and warned about when close),
  // since the `parameters` cause and the written inertials rest on it.
  notes_.push_back("base parameters: " + rank_decision_text(base_, reg_->param_names().size()));
  if (const std::string w = rank_decision_warning(base_); !w.empty()) notes_.push_back(w);
  declared_ = std::make_unique<ForceEffects>(reg_->model(), opt_.model);
  for (const auto& in : declared_->instances())
    if (!in.plugin().regressor)
      notes_.push_back("plugin '" + in.decl.instance + "' (" + in.decl.type + ") has no regressor columns: its force is simulated along the data "
                       "as declared and belongs to the model as given (and to the written model's score)");
  find_own_levels();
  // The model's own inverse dynamics against the regressor: what the regressor leaves out
  // (frictionloss, a stateful plugin, constraints) is said, per joint, before anything is named.
  for (const auto& mm : reg_->inverse_mismatches()) {
    notes_.push_back(inverse_mismatch_text(mm));
    // Where only such plugins explain it, diagnose simulates their forces along the data (the
    // note above): expected, not a warning (a review read the 310 % it prints for every
    // extended.xml with LuGre as an error).
    if (!mm.plugins_only) std::cerr << "spml: warning: " << opt_.model << ": " << notes_.back() << "\n";
  }
  ds_ = read_dataset(opt_.data);
  const std::string where = opt_.data + ": ";
  Split fit_part, test_part;
  choose_splits(ds_, opt_.data, fit_part, test_part);
  test_part = in_column_order(test_part, fit_part.y_columns, opt_.data);
  std::vector<Eigen::Index> fit_runs, test_runs;
  load_more_records(fit_part, test_part, fit_runs, test_runs);
  fit_ = prepare(fit_part, fit_runs);
  map_outputs();
  plan_parallel_filter();
  test_ = prepare(test_part, test_runs, held_out_from_fit_ && fit_runs.empty() ? &fit_ : nullptr);
  load_cross();
  if (fit_.split.y_columns != test_.split.y_columns)
    throw DatasetError(where + "the fit and test splits have different torque columns");
  // Every torque zero is refused as each split is prepared (stacked_torques); one silent joint
  // would make its relative errors inf and its causes meaningless.
  for (const SplitData* s : {&fit_, &test_}) {
    for (Eigen::Index c = 0; c < s->split.Y.cols(); ++c)
      if (s->split.Y.col(c).cwiseAbs().maxCoeff() == 0)
        throw DatasetError(where + "split '" + s->name + "': column '" + s->split.y_columns[static_cast<size_t>(c)] +
                           "' is zero in every row: nothing to explain on that joint (a sensor not read? leave it out of the targets)");
  }
  const Eigen::Index eqs = fit_.b.size();
  if (eqs <= 2 * base_.rank)
    throw DatasetError(where + "split '" + opt_.fit_split + "': " + std::to_string(eqs) + " equations (" + std::to_string(fit_.N) +
                       " rows x " + std::to_string(fit_.split.Y.cols()) + " torques) for " + std::to_string(base_.rank) +
                       " base parameters: too few rows to diagnose anything");
  note_frictionloss();
  note_limits();
  // Joints that never move leave their friction and inertia undetermined.
  still_.assign(reg_->joint_names().size(), false);
  for (size_t j = 0; j < still_.size(); ++j) {
    const double vmax = fit_.split.X.col(fit_.cols->qd[j]).cwiseAbs().maxCoeff();
    still_[j] = vmax <= opt_.still_speed;
  }
}

// Rows past a limited joint's range in the model as given: the MJCF regressor's inverse dynamics
// holds no limit (nor contact) force, so there the residual is the limit's, which no cause
// writes. Said per joint, warned beyond 1 % of the rows (a seventeenth review drove an elbow into
// its `range` on 12 % of a log: the true model itself left 29.3 % of the torque held out).
void Diagnosis::note_limits() {
  const mjModel* m = reg_->model();
  for (size_t j = 0; j < reg_->joint_names().size(); ++j) {
    const int id = mj_name2id(m, mjOBJ_JOINT, reg_->joint_names()[j].c_str());
    if (id < 0 || !m->jnt_limited[id] || (m->jnt_type[id] != mjJNT_HINGE && m->jnt_type[id] != mjJNT_SLIDE)) continue;
    const double lo = m->jnt_range[2 * id], hi = m->jnt_range[2 * id + 1];
    const std::string unit = m->jnt_type[id] == mjJNT_HINGE ? " rad" : " m";   // MuJoCo's own units, whatever the MJCF's angle setting
    Eigen::Index past = 0, rows = 0;
    double deepest = 0;
    for (const SplitData* sd : {&fit_, &test_}) {
      const auto q = sd->split.X.col(sd->cols->q[j]);
      for (Eigen::Index i = 0; i < q.size(); ++i) {
        const double beyond = std::max(lo - q[i], q[i] - hi);
        if (beyond > 0) ++past, deepest = std::max(deepest, beyond);
      }
      rows += q.size();
    }
    if (past == 0) continue;
    const double share = static_cast<double>(past) / static_cast<double>(rows);
    notes_.push_back("joint '" + reg_->joint_names()[j] + "': " + std::to_string(past) + " of " + std::to_string(rows) + " rows (" +
                     fmt(100 * share, 3) + " %) lie past its range [" + fmt(lo, 4) + ", " + fmt(hi, 4) + "]" + unit + " in " + opt_.model +
                     " (by up to " + fmt(deepest, 3) + unit + "): the inverse dynamics diagnose fits holds no limit force, so there the residual is the limit's, "
                     "which no cause writes; leave those rows out, or read that joint's errors with it");
    if (share > 0.01) std::cerr << "spml: warning: " << opt_.data << ": " << notes_.back() << "\n";
  }
}

// The fit split, and the test split: the one named, else the first other split, else the
// last rows of the fit split.
void Diagnosis::choose_splits(const Dataset& ds, const std::string& file, Split& fit_part, Split& test_part) {
  const Split& fit = ds.get(opt_.fit_split);
  const std::string where = file + ": ";
  fit_part = fit;
  auto enough = [&](const Split& s) {
    if (s.rows() < kMinRows)
      throw DatasetError(where + "split '" + s.name + "' has " + std::to_string(s.rows()) + " rows; diagnose needs at least " +
                         std::to_string(kMinRows) + " in the fit and in the test split");
    return s;
  };
  enough(fit);
  if (!opt_.test_split.empty()) {
    if (opt_.test_split == opt_.fit_split)
      throw DatasetError(where + "the test split is the fit split ('" + opt_.fit_split +
                         "'): the gain must be measured on data the fit never saw");
    test_part = enough(ds.get(opt_.test_split));
    test_name_ = opt_.test_split;
    return;
  }
  for (const Split& s : ds.splits)
    if (s.name != opt_.fit_split) {
      test_part = enough(s);
      test_name_ = s.name;
      return;
    }
  // One split only: hold out its last rows, in time order (no shuffling: neighbouring
  // samples of a measured run are nearly equal, a random hold-out would flatter).
  const Eigen::Index n = fit.rows(), k = n - static_cast<Eigen::Index>(std::floor(opt_.holdout * static_cast<double>(n)));
  fit_part = fit.slice(0, k, opt_.fit_split);
  test_name_ = opt_.fit_split + "[last " + fmt(100 * opt_.holdout, 3) + "%]";
  // A hold-out of no rows left an empty test split that crashed the diagnosis (a 3-row file
  // from import --decimate 700 of 2000 rows).
  if (k < kMinRows || n - k < kMinRows)
    throw DatasetError(file + ": split '" + opt_.fit_split + "' has " + std::to_string(n) + " rows: holding out " + fmt(100 * opt_.holdout, 3) +
                       " % leaves " + std::to_string(k) + " to fit and " + std::to_string(n - k) + " to test; each needs at least " +
                       std::to_string(kMinRows));
  test_part = fit.slice(k, n, test_name_);
  held_out_from_fit_ = true;
  const std::string note = "the dataset has one split: its last " + fmt(100 * opt_.holdout, 3) + " % of rows (in time order) are held out as the test split";
  if (std::find(notes_.begin(), notes_.end(), note) == notes_.end()) notes_.push_back(note);
}

// The split with its torque columns in the fit split's order, matched by name.
Split in_column_order(const Split& s, const std::vector<std::string>& order, const std::string& file) {
  if (s.y_columns == order) return s;
  std::vector<std::string> a = s.y_columns, b = order;
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  if (a != b)
    throw DatasetError(file + ": split '" + s.name + "': its torque columns (" + join_list(s.y_columns) + ") differ from the fit split's (" +
                       join_list(order) + ")");
  Split out = s;
  for (size_t k = 0; k < order.size(); ++k) out.Y.col(static_cast<Eigen::Index>(k)) = s.Y.col(s.y_index(order[k]));
  out.y_columns = order;
  return out;
}

void Diagnosis::load_cross() {
  const Split& fit = ds_.get(opt_.fit_split);
  for (const auto& file : opt_.cross) {
    const Dataset other = read_dataset(file);
    for (const Split& sp : other.splits) {
      cross_.emplace_back(file, prepare(in_column_order(sp, fit.y_columns, file)));
    }
  }
}

// MuJoCo applies frictionloss as a soft constraint (a force up to the level, smaller near zero
// speed); the model as given is scored with MuJoCo's own (frictionloss_correction). Said, per joint.
void Diagnosis::note_frictionloss() {
  const mjModel* m = reg_->model();
  std::string joints;
  for (int j = 0; j < m->njnt; ++j)
    if (m->dof_frictionloss[m->jnt_dofadr[j]] != 0) joints += (joints.empty() ? "" : ", ") + reg_->joint_names()[static_cast<size_t>(j)];
  if (!joints.empty())
    notes_.push_back("frictionloss on " + joints + ": MuJoCo applies it as a soft constraint (below the level near zero speed); the model "
                     "as given and the written model are scored with MuJoCo's own friction force (mj_inverse at each row's q, qd, qdd), "
                     "candidates and a re-identified level with ideal Coulomb columns (level * sign(qd)); that force depends on qdd "
                     "near zero speed, so noisy accelerations leave more residual there");
}

// MuJoCo applies frictionloss as a soft constraint, the regressor as fl * sign(qd): at each
// row, MuJoCo's own friction torque of the model as given (mj_inverse at the row's q, qd, qdd:
// the friction rows of its constraint forces) minus the regressor's term, stacked like b. The
// model as given then predicts what MuJoCo would, and the soft zone near zero speed is not
// left in the residual for candidates to explain. Empty when the model has no frictionloss.
Eigen::VectorXd Diagnosis::frictionloss_correction(const SplitData& s, const mjModel* m) const {
  bool any = false;
  for (int v = 0; v < m->nv; ++v) any |= m->dof_frictionloss[v] != 0;
  if (!any) return {};
  const auto O = static_cast<Eigen::Index>(s.cols->output_dof.size());
  Eigen::VectorXd out = Eigen::VectorXd::Zero(s.N * O);
  DataPtr d = make_data(m);
  std::vector<double> friction(static_cast<size_t>(m->nv));
  for (Eigen::Index i = 0; i < s.N; ++i) {
    for (int j = 0; j < m->njnt; ++j) {
      d->qpos[m->jnt_qposadr[j]] = s.split.X(i, s.cols->q[static_cast<size_t>(j)]);
      d->qvel[m->jnt_dofadr[j]] = s.split.X(i, s.cols->qd[static_cast<size_t>(j)]);
      d->qacc[m->jnt_dofadr[j]] = s.split.X(i, s.cols->qdd[static_cast<size_t>(j)]);
    }
    mj_inverse(m, d.get());
    std::fill(friction.begin(), friction.end(), 0.0);
    for (int r = 0; r < d->nefc; ++r)
      if (d->efc_type[r] == mjCNSTR_FRICTION_DOF) friction[static_cast<size_t>(d->efc_id[r])] += d->efc_force[r];
    for (Eigen::Index o = 0; o < O; ++o) {
      const int v = s.cols->output_dof[static_cast<size_t>(o)];
      const double qd = d->qvel[v], ideal = m->dof_frictionloss[v] * (qd > 0 ? 1.0 : qd < 0 ? -1.0 : 0.0);
      out[o * s.N + i] = -friction[static_cast<size_t>(v)] - ideal;   // tau_inverse holds -J'f
    }
  }
  return out;
}

// Adds into `into` (stacked like b; empty: zeros) the forces of the model's declared plugins
// that the regressor leaves out (no regressor columns: a stateful stick_slip, a nonlinear
// effect), integrated along the split with their declared parameters (simulated_columns).
// Without them a model declaring stick_slip had its own friction named as `delay` and `offset`.
void Diagnosis::add_declared_forces(const SplitData& s, Eigen::VectorXd& into) const {
  for (const auto& in : declared_->instances()) {
    if (in.plugin().regressor) continue;
    const Eigen::VectorXd f = simulated_columns(in.object, s).dense().col(0);
    // A declaration the plugin accepts can still overflow along a log (LuGre with sigma1 = 1e300:
    // a force of 1e299, whose squares are inf and every score after them NaN; a review's draw
    // crashed on it).
    const double rms_torque = rms(s.b);
    const double peak = f.size() ? f.cwiseAbs().maxCoeff() : 0.0;
    const std::string what = opt_.model + ": " + in.decl.element + " (" + in.decl.type + "): its force along split '" + s.name + "' of " + opt_.data;
    if (!(peak <= kAbsurdTorqueRatio * rms_torque))
      throw DatasetError(what + " reaches " + fmt(peak) + " (" + fmt(kAbsurdTorqueRatio) + " times the measured torques' RMS, " + fmt(rms_torque) +
                         ", or more, or not finite): the declared values are off by orders of magnitude");
    if (peak > kImplausibleForce * rms_torque)
      std::cerr << "spml: warning: " << what << " reaches " << fmt(peak) << ", " << fmt(kImplausibleForce)
                << " times the measured torques' RMS or more: the model as given will be far from the data (check the declared values)\n";
    if (into.size()) into += f;
    else into = f;
  }
}

// Per output (Y column): the model joint it belongs to.
void Diagnosis::map_outputs() {
  for (int c : fit_.cols->output_dof) {
    for (int j = 0; j < reg_->model()->njnt; ++j)
      if (reg_->model()->jnt_dofadr[j] == c) {
        out_joints_.push_back(reg_->joint_names()[static_cast<size_t>(j)]);
        out_joint_index_.push_back(j);
      }
  }
}

}  // namespace spml::diagnose_detail
