// Stage 1, load: the model, its base parameters, the dataset and the splits diagnose works on.
#include <cmath>

#include "diagnosis.h"
#include "spml/matrix_file.h"

namespace spml::diagnose_detail {

void Diagnosis::load() {
  RegressorOptions ro;
  ro.coulomb_only_where_modelled = true;
  reg_ = std::make_unique<MjcfRegressor>(opt_.model, ro);
  base_ = reg_->base_parameters();
  ds_ = read_dataset(opt_.data);
  const std::string where = opt_.data + ": ";
  Split fit_part, test_part;
  choose_splits(fit_part, test_part);
  fit_ = prepare(fit_part);
  map_outputs();
  test_ = prepare(test_part);
  load_cross();
  if (fit_.split.y_columns != test_.split.y_columns)
    throw DatasetError(where + "the fit and test splits have different torque columns");
  const Eigen::Index eqs = fit_.b.size();
  if (eqs <= 2 * base_.rank)
    throw DatasetError(where + "split '" + opt_.fit_split + "': " + std::to_string(eqs) + " equations (" + std::to_string(fit_.N) +
                       " rows x " + std::to_string(fit_.split.Y.cols()) + " torques) for " + std::to_string(base_.rank) +
                       " base parameters: too few rows to diagnose anything");
  // Joints that never move leave their friction and inertia undetermined.
  still_.assign(reg_->joint_names().size(), false);
  for (size_t j = 0; j < still_.size(); ++j) {
    const double vmax = fit_.split.X.col(fit_.cols->qd[j]).cwiseAbs().maxCoeff();
    still_[j] = vmax <= opt_.still_speed;
  }
}

// The fit split, and the test split: the one named, else the first other split, else the
// last rows of the fit split.
void Diagnosis::choose_splits(Split& fit_part, Split& test_part) {
  const Split& fit = ds_.get(opt_.fit_split);
  const std::string where = opt_.data + ": ";
  fit_part = fit;
  if (!opt_.test_split.empty()) {
    if (opt_.test_split == opt_.fit_split)
      throw DatasetError(where + "the test split is the fit split ('" + opt_.fit_split +
                         "'): the gain must be measured on data the fit never saw");
    test_part = ds_.get(opt_.test_split);
    test_name_ = opt_.test_split;
    return;
  }
  for (const Split& s : ds_.splits)
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
  notes_.push_back("the dataset has one split: its last " + fmt(100 * opt_.holdout, 3) + " % of rows (in time order) are held out as the test split");
}

void Diagnosis::load_cross() {
  const Split& fit = ds_.get(opt_.fit_split);
  for (const auto& file : opt_.cross) {
    const Dataset other = read_dataset(file);
    for (const Split& sp : other.splits) {
      if (sp.y_columns != fit.y_columns)
        throw DatasetError(file + ": split '" + sp.name + "': its torque columns differ from the fit split's");
      cross_.emplace_back(file, prepare(sp));
    }
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
