// Stage 1, load: the model, its base parameters, the dataset and the splits diagnose works on.
#include <algorithm>
#include <cmath>

#include "diagnosis.h"
#include "spml/matrix_file.h"

namespace spml::diagnose_detail {

void Diagnosis::load() {
  RegressorOptions ro;
  ro.coulomb_only_where_modelled = true;
  reg_ = std::make_unique<MjcfRegressor>(opt_.model, ro);
  base_ = reg_->base_parameters();
  // The base-parameter rank decision is said in every report (and warned about when close),
  // since the `parameters` cause and the written inertials rest on it.
  notes_.push_back("base parameters: " + rank_decision_text(base_, reg_->param_names().size()));
  if (const std::string w = rank_decision_warning(base_); !w.empty()) notes_.push_back(w);
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
  test_ = prepare(test_part, test_runs);
  load_cross();
  if (fit_.split.y_columns != test_.split.y_columns)
    throw DatasetError(where + "the fit and test splits have different torque columns");
  for (const SplitData* s : {&fit_, &test_})
    if (s->split.Y.cwiseAbs().maxCoeff() == 0)
      throw DatasetError(where + "split '" + s->name + "': every torque is zero: there is nothing to explain (a sensor not read?)");
  const Eigen::Index eqs = fit_.b.size();
  if (eqs <= 2 * base_.rank)
    throw DatasetError(where + "split '" + opt_.fit_split + "': " + std::to_string(eqs) + " equations (" + std::to_string(fit_.N) +
                       " rows x " + std::to_string(fit_.split.Y.cols()) + " torques) for " + std::to_string(base_.rank) +
                       " base parameters: too few rows to diagnose anything");
  note_frictionloss();
  // Joints that never move leave their friction and inertia undetermined.
  still_.assign(reg_->joint_names().size(), false);
  for (size_t j = 0; j < still_.size(); ++j) {
    const double vmax = fit_.split.X.col(fit_.cols->qd[j]).cwiseAbs().maxCoeff();
    still_[j] = vmax <= opt_.still_speed;
  }
}

// The fit split, and the test split: the one named, else the first other split, else the
// last rows of the fit split.
void Diagnosis::choose_splits(const Dataset& ds, const std::string& file, Split& fit_part, Split& test_part) {
  const Split& fit = ds.get(opt_.fit_split);
  const std::string where = file + ": ";
  fit_part = fit;
  if (!opt_.test_split.empty()) {
    if (opt_.test_split == opt_.fit_split)
      throw DatasetError(where + "the test split is the fit split ('" + opt_.fit_split +
                         "'): the gain must be measured on data the fit never saw");
    test_part = ds.get(opt_.test_split);
    test_name_ = opt_.test_split;
    return;
  }
  for (const Split& s : ds.splits)
    if (s.name != opt_.fit_split) {
      test_part = s;
      test_name_ = s.name;
      return;
    }
  // One split only: hold out its last rows, in time order (no shuffling: neighbouring
  // samples of a measured run are nearly equal, a random hold-out would flatter).
  const Eigen::Index n = fit.rows(), k = n - static_cast<Eigen::Index>(std::floor(opt_.holdout * static_cast<double>(n)));
  fit_part = fit.slice(0, k, opt_.fit_split);
  test_name_ = opt_.fit_split + "[last " + fmt(100 * opt_.holdout, 3) + "%]";
  test_part = fit.slice(k, n, test_name_);
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
// speed); the regressor reads it as ideal Coulomb friction, level * sign(qd). Said, per joint.
void Diagnosis::note_frictionloss() {
  const mjModel* m = reg_->model();
  std::string joints;
  for (int j = 0; j < m->njnt; ++j)
    if (m->dof_frictionloss[m->jnt_dofadr[j]] != 0) joints += (joints.empty() ? "" : ", ") + reg_->joint_names()[static_cast<size_t>(j)];
  if (!joints.empty())
    notes_.push_back("frictionloss on " + joints + ": MuJoCo applies it as a soft constraint, diagnose as ideal Coulomb friction "
                     "(level * sign(qd)); near zero speed the two differ, so data simulated by MuJoCo from this model do not fit "
                     "exactly there (the written model is scored by the same regressor)");
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
