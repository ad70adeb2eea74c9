#include "spml/diagnose.h"

#include <Eigen/Dense>
#include <nlopt.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <sstream>
#include <unistd.h>

#include "design.h"
#include "extended_mjcf.h"
#include "report.h"
#include "rollout.h"
#include "spml/envs/mjcf_regressor.h"
#include "spml/force_effects.h"
#include "spml/matrix_file.h"
#include "spml/parse.h"

namespace spml {
namespace {

using namespace diagnose_detail;
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// One split as diagnose uses it: its rows, the stacked base regressor, the stacked torques and
// what the model as given predicts.
struct SplitData {
  std::string name;
  Split split;
  std::unique_ptr<JointColumns> cols;
  BlockColumns base;
  Eigen::VectorXd b, given, y0;   // targets, prediction of the model as given, b - given
  Eigen::Index N = 0;
};

// A candidate cause: one plugin on one joint, with its shape chosen.
struct Candidate {
  const spml_force_plugin* plugin = nullptr;
  int joint = -1;                 // model joint index
  std::string joint_name;
  std::vector<const spml_shape_param*> shape;
  std::vector<std::pair<std::string, std::string>> fixed;   // non-shape keys it is made with
  std::vector<double> shape_values;                         // absolute values, chosen
  std::vector<std::pair<double, double>> shape_range;       // absolute search range
  BlockColumns fit_cols;
  bool searched = false;
  Gain gain;
  double delta_bic = -std::numeric_limits<double>::infinity();
};

struct Cause {
  int candidate;
  double delta_bic;
  std::string superseded_by;
};

std::string fmt(double v, int precision = 4) {
  std::ostringstream s;
  s.precision(precision);
  s << v;
  return s.str();
}

// Evidence for the larger of two nested fits (Bayesian information criterion, n equations,
// dk more parameters): positive when the drop of the residual sum of squares pays for them.
double delta_bic(double n, double rss_smaller, double rss_larger, double dk) {
  return n * std::log(rss_smaller / std::max(rss_larger, 1e-300)) - dk * std::log(n);
}

// The held-out test: the residual sum of squares falls by at least the fraction min_gain.
bool gains_on_test(double rss_before, double rss_after, double min_gain) {
  return rss_before > 0 && (rss_before - rss_after) / rss_before >= min_gain;
}

std::string integer_text(double v) { return std::to_string(static_cast<long long>(std::llround(v))); }

class Diagnosis {
 public:
  Diagnosis(const DiagnoseOptions& o) : opt_(o) {}
  DiagnoseResult run(const std::string& out_dir);

 private:
  void load();
  SplitData prepare(const Split& s);
  void find_candidates();
  std::vector<std::pair<std::string, std::string>> config_of(const Candidate& c, const std::vector<double>& shape) const;
  BlockColumns columns(const PluginInstance& inst, const SplitData& s) const;
  double search_shape(Candidate& c, const Fit& current);
  std::vector<const BlockColumns*> blocks(const std::vector<int>& causes, bool base_free) const;
  Fit refit(const std::vector<int>& causes, bool base_free) const;
  Eigen::VectorXd residual_on(const SplitData& s, const std::vector<int>& causes, bool base_free, const Fit& f) const;
  double rss_on(const Eigen::VectorXd& r, const std::vector<int>& outputs, Eigen::Index N) const;
  std::vector<int> outputs_of(int candidate) const;
  // "" when the plugin accepts its fitted parameters (written back through write_config and
  // created again), else its reason: a negative band level is not a friction band.
  std::string refused(int candidate, const Eigen::VectorXd& theta) const;
  void select();
  nlohmann::json metrics(const Eigen::VectorXd& r_fit, const Eigen::VectorXd& r_test) const;
  nlohmann::json per_joint(const Eigen::VectorXd& r, Eigen::Index N) const;
  void decide_parameters();
  // Candidate indices of the causes not superseded, in the order chosen.
  std::vector<int> kept_effects() const {
    std::vector<int> out;
    for (const auto& c : causes_)
      if (c.superseded_by.empty()) out.push_back(c.candidate);
    return out;
  }
  // Relative error (all joints) of a fit on every cross split.
  nlohmann::json cross_errors(const std::vector<int>& causes, bool base_free, const Fit& f) const {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& [file, s] : cross_) out.push_back(residual_on(s, causes, base_free, f).norm() / s.b.norm());
    return out;
  }
  void build_report(const std::string& out_dir);

  DiagnoseOptions opt_;
  DiagnoseResult result_;
  std::unique_ptr<MjcfRegressor> reg_;
  MjcfRegressor::Base base_;
  Dataset ds_;
  std::string test_name_;
  SplitData fit_, test_;
  std::vector<std::pair<std::string, SplitData>> cross_;   // (file, split)
  std::vector<std::string> out_joints_;   // per output: joint name
  std::vector<int> out_joint_index_;      // per output: model joint index
  std::vector<bool> still_;               // per model joint
  std::vector<Candidate> cands_;
  nlohmann::json not_tried_ = nlohmann::json::array();
  std::vector<Cause> causes_;
  bool parameters_named_ = false;
  double parameters_delta_bic_ = 0;
  std::vector<std::string> notes_;
};

void Diagnosis::load() {
  RegressorOptions ro;
  ro.coulomb_only_where_modelled = true;
  reg_ = std::make_unique<MjcfRegressor>(opt_.model, ro);
  base_ = reg_->base_parameters();
  ds_ = read_dataset(opt_.data);
  const Split& fit = ds_.get(opt_.fit_split);
  const std::string where = opt_.data + ": ";
  Split fit_part = fit, test_part;
  if (!opt_.test_split.empty()) {
    if (opt_.test_split == opt_.fit_split)
      throw DatasetError(where + "the test split is the fit split ('" + opt_.fit_split +
                         "'): the gain must be measured on data the fit never saw");
    test_part = ds_.get(opt_.test_split);
    test_name_ = opt_.test_split;
  } else {
    for (const Split& s : ds_.splits)
      if (s.name != opt_.fit_split) {
        test_part = s;
        test_name_ = s.name;
        break;
      }
    if (test_name_.empty()) {
      // One split only: hold out its last rows, in time order (no shuffling: neighbouring
      // samples of a measured run are nearly equal, a random hold-out would flatter).
      const Eigen::Index n = fit.rows(), k = n - static_cast<Eigen::Index>(std::floor(opt_.holdout * static_cast<double>(n)));
      fit_part = fit.slice(0, k, opt_.fit_split);
      test_name_ = opt_.fit_split + "[last " + fmt(100 * opt_.holdout, 3) + "%]";
      test_part = fit.slice(k, n, test_name_);
      notes_.push_back("the dataset has one split: its last " + fmt(100 * opt_.holdout, 3) + " % of rows (in time order) are held out as the test split");
    }
  }
  fit_ = prepare(fit_part);
  test_ = prepare(test_part);
  for (const auto& file : opt_.cross) {
    const Dataset other = read_dataset(file);
    for (const Split& sp : other.splits) {
      if (sp.y_columns != fit.y_columns)
        throw DatasetError(file + ": split '" + sp.name + "': its torque columns differ from the fit split's");
      cross_.emplace_back(file, prepare(sp));
    }
  }
  if (fit_.split.y_columns != test_.split.y_columns)
    throw DatasetError(where + "the fit and test splits have different torque columns");
  for (int c : fit_.cols->output_dof) {
    for (int j = 0; j < reg_->model()->njnt; ++j)
      if (reg_->model()->jnt_dofadr[j] == c) {
        out_joints_.push_back(reg_->joint_names()[static_cast<size_t>(j)]);
        out_joint_index_.push_back(j);
      }
  }
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

// The configuration a candidate is made with: its shape values, and for every other required
// key a neutral value (0 clipped into the key's range): linear parameters do not change the
// regressor columns, so their values do not matter here.
void Diagnosis::find_candidates() {
  for (const std::string& name : available_force_plugins()) {
    const spml_force_plugin& p = load_force_plugin(name);
    if (!p.regressor) {
      not_tried_.push_back({{"effect", name},
                            {"reason", std::string(p.advance ? "stateful" : "not linear in its parameters") +
                                           ": its force is not a regressor of the measured state, so inverse dynamics cannot fit it"}});
      continue;
    }
    std::vector<const spml_shape_param*> shape;
    for (const spml_shape_param* sp = p.shape_params; sp && sp->key; ++sp) shape.push_back(sp);
    std::vector<std::pair<std::string, std::string>> fixed;
    std::string problem;
    for (const spml_config_key* k = p.config_keys; k && k->name; ++k) {
      bool is_shape = false;
      for (auto* sp : shape) is_shape |= std::string(sp->key) == k->name;
      if (is_shape || k->default_value) continue;
      if (k->type == SPML_VALUE_TEXT) {
        problem = "required text key '" + std::string(k->name) + "' has no default and no search description";
        break;
      }
      const double v = std::clamp(0.0, k->min, k->max);
      fixed.emplace_back(k->name, k->type == SPML_VALUE_INTEGER ? integer_text(v) : exact_text(v));
    }
    if (!problem.empty()) {
      not_tried_.push_back({{"effect", name}, {"reason", problem}});
      continue;
    }
    for (size_t o = 0; o < out_joint_index_.size(); ++o) {
      const int j = out_joint_index_[o];
      if (still_[static_cast<size_t>(j)]) continue;
      Candidate c;
      c.plugin = &p;
      c.joint = j;
      c.joint_name = out_joints_[o];
      c.shape = shape;
      c.fixed = fixed;
      const auto q = fit_.split.X.col(fit_.cols->q[static_cast<size_t>(j)]);
      const double vmax = fit_.split.X.col(fit_.cols->qd[static_cast<size_t>(j)]).cwiseAbs().maxCoeff();
      for (auto* sp : shape) {
        double lo = sp->lo, hi = sp->hi;
        if (sp->domain == SPML_SHAPE_POSITION) {
          const double a = q.minCoeff(), span = q.maxCoeff() - a;
          lo = a + sp->lo * span;
          hi = a + sp->hi * span;
        } else if (sp->domain == SPML_SHAPE_SPEED) {
          lo = sp->lo * vmax;
          hi = sp->hi * vmax;
        }
        c.shape_range.emplace_back(lo, hi);
      }
      cands_.push_back(std::move(c));
    }
  }
}

std::vector<std::pair<std::string, std::string>> Diagnosis::config_of(const Candidate& c, const std::vector<double>& shape) const {
  auto config = c.fixed;
  for (size_t k = 0; k < c.shape.size(); ++k)
    config.emplace_back(c.shape[k]->key, c.shape[k]->integer ? integer_text(shape[k]) : exact_text(shape[k]));
  return config;
}

BlockColumns Diagnosis::columns(const PluginInstance& inst, const SplitData& s) const {
  const mjModel* m = reg_->model();
  const int np = inst.nparam(), O = static_cast<int>(s.split.Y.cols());
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(s.N * O, np);
  std::vector<mjtNum> qpos(m->qpos0, m->qpos0 + m->nq), qvel(static_cast<size_t>(m->nv), 0.0),
      R(static_cast<size_t>(m->nv) * static_cast<size_t>(np));
  for (Eigen::Index i = 0; i < s.N; ++i) {
    for (int j = 0; j < m->njnt; ++j) {
      qpos[static_cast<size_t>(m->jnt_qposadr[j])] = s.split.X(i, s.cols->q[static_cast<size_t>(j)]);
      qvel[static_cast<size_t>(m->jnt_dofadr[j])] = s.split.X(i, s.cols->qd[static_cast<size_t>(j)]);
    }
    std::fill(R.begin(), R.end(), 0.0);
    inst.plugin().regressor(inst.state(), m, qpos.data(), qvel.data(), R.data());
    // Inverse dynamics: tau = ... - force, and force = R theta.
    for (int o = 0; o < O; ++o)
      for (int k = 0; k < np; ++k) C(o * s.N + i, k) = -R[static_cast<size_t>(s.cols->output_dof[static_cast<size_t>(o)] * np + k)];
  }
  if (!C.allFinite())
    throw PluginError("plugin '" + std::string(inst.plugin().name) + "' gave non-finite regressor values on split '" + s.name + "'");
  return BlockColumns::from_dense(C, s.N, O);
}

// Variable projection over the shape: for each shape the amplitudes are the least-squares
// ones, so only the drop of the residual sum of squares is searched - on a grid over the
// plugin's own ranges, then refined locally (continuous parameters only). Returns the best drop.
double Diagnosis::search_shape(Candidate& c, const Fit& current) {
  const std::string where = "diagnose candidate " + std::string(c.plugin->name) + " on joint '" + c.joint_name + "'";
  auto evaluate = [&](const std::vector<double>& shape, BlockColumns* keep) -> Gain {
    try {
      PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, shape), where);
      BlockColumns cols = columns(inst, fit_);
      Gain g = gain_of(cols, current.Q, current.residual);
      if (keep) *keep = std::move(cols);
      return g;
    } catch (const PluginError&) {
      return Gain{};   // a shape the plugin refuses (lower >= upper): not a candidate
    }
  };
  const size_t ns = c.shape.size();
  if (ns == 0) {
    if (!c.searched) {
      PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, {}), where);
      c.fit_cols = columns(inst, fit_);
      c.searched = true;
    }
    c.gain = gain_of(c.fit_cols, current.Q, current.residual);
    return c.gain.rss_drop;
  }
  // Grid: every whole number of a small integer range, else points per axis so that the
  // whole grid stays a few hundred shapes.
  const int per_axis = ns == 1 ? 40 : ns == 2 ? 16 : 6;
  std::vector<std::vector<double>> axes(ns);
  for (size_t k = 0; k < ns; ++k) {
    auto [lo, hi] = c.shape_range[k];
    const auto* sp = c.shape[k];
    if (sp->integer && std::ceil(lo) <= std::floor(hi) && std::floor(hi) - std::ceil(lo) < 250) {
      for (double v = std::ceil(lo); v <= std::floor(hi); v += 1) axes[k].push_back(v);
      continue;
    }
    for (int i = 0; i < per_axis; ++i) {
      const double f = per_axis == 1 ? 0.5 : static_cast<double>(i) / (per_axis - 1);
      double v = sp->log_scale ? lo * std::pow(hi / lo, f) : lo + f * (hi - lo);
      if (sp->integer) v = std::round(v);
      if (axes[k].empty() || axes[k].back() != v) axes[k].push_back(v);
    }
  }
  std::vector<double> best(ns), point(ns);
  double best_drop = -1;
  std::vector<size_t> idx(ns, 0);
  for (;;) {
    for (size_t k = 0; k < ns; ++k) point[k] = axes[k][idx[k]];
    const Gain g = evaluate(point, nullptr);
    if (g.rank > 0 && g.rss_drop > best_drop) best_drop = g.rss_drop, best = point;
    size_t k = 0;
    while (k < ns && ++idx[k] == axes[k].size()) idx[k++] = 0;
    if (k == ns) break;
  }
  if (best_drop < 0) {
    c.gain = Gain{};
    return 0;
  }
  // Local refinement of the continuous shape parameters. First zoomed scans per parameter
  // around the best grid point: the objective is piecewise constant in parameters that
  // select samples (band edges), which derivative-free simplex methods stall on. Then a
  // subplex polish (NLopt) for the smooth ones (a Stribeck velocity).
  std::vector<size_t> cont;
  for (size_t k = 0; k < ns; ++k)
    if (!c.shape[k]->integer && axes[k].size() > 1) cont.push_back(k);
  for (int round = 0; round < 3 && !cont.empty(); ++round)
    for (size_t k : cont) {
      const double cell = (c.shape_range[k].second - c.shape_range[k].first) / (per_axis - 1) / std::pow(4.0, round);
      for (int i = -8; i <= 8; ++i) {
        std::vector<double> p = best;
        p[k] = std::clamp(best[k] + cell * i / 8.0, c.shape_range[k].first, c.shape_range[k].second);
        if (p[k] == best[k]) continue;
        const Gain g = evaluate(p, nullptr);
        if (g.rank > 0 && g.rss_drop > best_drop) best_drop = g.rss_drop, best = p;
      }
    }
  // Parameters that select samples leave a plateau of equally good values between two
  // samples; take its middle, the value least likely to misplace unseen samples.
  for (size_t k : cont) {
    const double fine = (c.shape_range[k].second - c.shape_range[k].first) / (per_axis - 1) / 256;
    double ends[2] = {best[k], best[k]};
    for (int side = 0; side < 2; ++side)
      for (int i = 1; i <= 24; ++i) {
        std::vector<double> p = best;
        p[k] = best[k] + (side ? fine : -fine) * i;
        if (p[k] < c.shape_range[k].first || p[k] > c.shape_range[k].second) break;
        const Gain g = evaluate(p, nullptr);
        if (!(g.rank > 0 && g.rss_drop >= best_drop * (1 - 1e-12))) break;
        ends[side] = p[k];
      }
    if (ends[0] != ends[1]) {
      std::vector<double> p = best;
      p[k] = 0.5 * (ends[0] + ends[1]);
      const Gain g = evaluate(p, nullptr);
      if (g.rank > 0 && g.rss_drop >= best_drop * (1 - 1e-12)) best = p, best_drop = std::max(best_drop, g.rss_drop);
    }
  }
  if (!cont.empty()) {
    std::vector<double> lb, ub, x;
    for (size_t k : cont) {
      const double cell = (c.shape_range[k].second - c.shape_range[k].first) / (per_axis - 1) / 16;
      lb.push_back(std::max(c.shape_range[k].first, best[k] - cell));
      ub.push_back(std::min(c.shape_range[k].second, best[k] + cell));
      x.push_back(best[k]);
    }
    struct Ctx {
      std::function<double(const std::vector<double>&)> f;
    } ctx{[&](const std::vector<double>& v) {
      std::vector<double> p = best;
      for (size_t a = 0; a < cont.size(); ++a) p[cont[a]] = v[a];
      const Gain g = evaluate(p, nullptr);
      return g.rank > 0 ? g.rss_drop : 0.0;
    }};
    nlopt::opt local(nlopt::LN_SBPLX, static_cast<unsigned>(cont.size()));
    local.set_lower_bounds(lb);
    local.set_upper_bounds(ub);
    local.set_max_objective([](const std::vector<double>& v, std::vector<double>&, void* data) { return static_cast<Ctx*>(data)->f(v); }, &ctx);
    local.set_maxeval(static_cast<int>(25 * cont.size()));
    local.set_xtol_rel(1e-4);
    double value = best_drop;
    try {
      local.optimize(x, value);
    } catch (const std::exception&) {
      // NLopt reports roundoff-limited stops as exceptions; x holds the best point found.
    }
    if (value > best_drop) {
      for (size_t a = 0; a < cont.size(); ++a) best[cont[a]] = x[a];
      best_drop = value;
    }
  }
  c.shape_values = best;
  c.gain = evaluate(best, &c.fit_cols);
  c.searched = true;
  return c.gain.rss_drop;
}

std::vector<const BlockColumns*> Diagnosis::blocks(const std::vector<int>& causes, bool base_free) const {
  std::vector<const BlockColumns*> out;
  if (base_free) out.push_back(&fit_.base);
  for (int c : causes) out.push_back(&cands_[static_cast<size_t>(c)].fit_cols);
  return out;
}

Fit Diagnosis::refit(const std::vector<int>& causes, bool base_free) const {
  return fit_blocks(blocks(causes, base_free), fit_.y0, true);
}

// Residual of a fit on another split (test, cross): the causes' columns evaluated there.
Eigen::VectorXd Diagnosis::residual_on(const SplitData& s, const std::vector<int>& causes, bool base_free, const Fit& f) const {
  Eigen::VectorXd pred = Eigen::VectorXd::Zero(s.y0.size());
  Eigen::Index c = 0;
  if (base_free) {
    pred += s.base.times(f.coef.segment(0, s.base.cols));
    c += s.base.cols;
  }
  for (int k : causes) {
    const Candidate& cand = cands_[static_cast<size_t>(k)];
    PluginInstance inst(*cand.plugin, reg_->model(), {cand.joint}, config_of(cand, cand.shape_values), "diagnose");
    const BlockColumns cols = columns(inst, s);
    pred += cols.times(f.coef.segment(c, cols.cols));
    c += cols.cols;
  }
  return s.y0 - pred;
}

double Diagnosis::rss_on(const Eigen::VectorXd& r, const std::vector<int>& outputs, Eigen::Index N) const {
  double s = 0;
  for (int o : outputs) s += r.segment(o * N, N).squaredNorm();
  return s;
}

std::vector<int> Diagnosis::outputs_of(int candidate) const { return cands_[static_cast<size_t>(candidate)].fit_cols.active; }

std::string Diagnosis::refused(int candidate, const Eigen::VectorXd& theta) const {
  const Candidate& c = cands_[static_cast<size_t>(candidate)];
  try {
    PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, c.shape_values), "diagnose");
    inst.set_params(theta);
    const std::string text = inst.config_text();
    if (text.empty()) return "";   // cannot check; the extended model will say it is not written
    PluginInstance again(*c.plugin, reg_->model(), {c.joint}, parse_config_words(text, "fitted"), "fitted");
    return "";
  } catch (const std::exception& e) {
    return e.what();
  }
}

void Diagnosis::select() {
  const double n = static_cast<double>(fit_.y0.size());
  std::vector<int> chosen;
  std::set<int> research;   // joints whose candidates need a new shape search
  for (size_t j = 0; j < still_.size(); ++j) research.insert(static_cast<int>(j));
  auto t0 = Clock::now();
  Fit current = refit(chosen, true);
  Eigen::VectorXd r_test = residual_on(test_, chosen, true, current);
  result_.timings.refits += since(t0);
  while (static_cast<int>(chosen.size()) < opt_.max_causes) {
    t0 = Clock::now();
    std::vector<int> order;
    for (size_t k = 0; k < cands_.size(); ++k) {
      if (std::find(chosen.begin(), chosen.end(), static_cast<int>(k)) != chosen.end()) continue;
      Candidate& c = cands_[k];
      if (!c.searched || (!c.shape.empty() && research.count(c.joint)))
        search_shape(c, current);
      else
        c.gain = gain_of(c.fit_cols, current.Q, current.residual);
      if (c.gain.rank == 0 || c.gain.rss_drop <= 0) continue;
      const double dk = c.gain.rank + static_cast<double>(c.shape.size());
      c.delta_bic = delta_bic(n, current.rss, current.rss - c.gain.rss_drop, dk);
      if (c.delta_bic > opt_.bic_threshold) order.push_back(static_cast<int>(k));
    }
    result_.timings.search += since(t0);
    // Most evidence per added parameter (linear directions and shape parameters) first: of
    // nested explanations the smaller one (Coulomb before asymmetric friction, before a band
    // that spans the whole stroke) gets its turn, the larger follows if it adds.
    std::sort(order.begin(), order.end(), [&](int a, int b) {
      const auto &ca = cands_[static_cast<size_t>(a)], &cb = cands_[static_cast<size_t>(b)];
      return ca.delta_bic / (ca.gain.rank + static_cast<double>(ca.shape.size())) >
             cb.delta_bic / (cb.gain.rank + static_cast<double>(cb.shape.size()));
    });
    t0 = Clock::now();
    int accepted = -1;
    Fit next;
    Eigen::VectorXd next_test;
    for (size_t i = 0; i < order.size() && i < 6 && accepted < 0; ++i) {
      std::vector<int> trial = chosen;
      trial.push_back(order[i]);
      Fit f = refit(trial, true);
      Eigen::Index off = f.coef.size() - cands_[static_cast<size_t>(order[i])].fit_cols.cols;
      if (!refused(order[i], f.coef.tail(f.coef.size() - off)).empty()) continue;
      Eigen::VectorXd rt = residual_on(test_, trial, true, f);
      const auto outs = outputs_of(order[i]);
      if (gains_on_test(rss_on(r_test, outs, test_.N), rss_on(rt, outs, test_.N), opt_.min_gain)) {
        accepted = order[i];
        next = std::move(f);
        next_test = std::move(rt);
      }
    }
    result_.timings.refits += since(t0);
    if (accepted < 0) break;
    chosen.push_back(accepted);
    causes_.push_back({accepted, cands_[static_cast<size_t>(accepted)].delta_bic, ""});
    current = std::move(next);
    r_test = std::move(next_test);
    research = {cands_[static_cast<size_t>(accepted)].joint};
  }
  // Backward elimination: a cause that a later one made redundant (its removal costs less
  // evidence than the threshold, or less than min_gain on the test split) is superseded.
  t0 = Clock::now();
  // Is cause i still needed among the causes `set` (candidate indices, i's included)?
  auto needed = [&](size_t i, const std::vector<size_t>& set) {
    std::vector<int> with, without;
    for (size_t k : set) {
      with.push_back(causes_[k].candidate);
      if (k != i) without.push_back(causes_[k].candidate);
    }
    const Fit fw = refit(with, true), fo = refit(without, true);
    const double dk = fw.rank - fo.rank + static_cast<double>(cands_[static_cast<size_t>(causes_[i].candidate)].shape.size());
    const auto outs = outputs_of(causes_[i].candidate);
    return delta_bic(n, fo.rss, fw.rss, dk) > opt_.bic_threshold &&
           gains_on_test(rss_on(residual_on(test_, without, true, fo), outs, test_.N),
                         rss_on(residual_on(test_, with, true, fw), outs, test_.N), opt_.min_gain);
  };
  auto live = [&](size_t upto) {
    std::vector<size_t> set;
    for (size_t k = 0; k <= upto && k < causes_.size(); ++k)
      if (causes_[k].superseded_by.empty()) set.push_back(k);
    return set;
  };
  for (bool changed = true; changed;) {
    changed = false;
    for (size_t i = 0; i < causes_.size() && !changed; ++i) {
      if (!causes_[i].superseded_by.empty() || needed(i, live(causes_.size()))) continue;
      // Superseded by the first later cause with which it is no longer needed.
      std::string by = "redundant";
      const int joint = cands_[static_cast<size_t>(causes_[i].candidate)].joint;
      for (size_t k = i + 1; k < causes_.size(); ++k)
        if (causes_[k].superseded_by.empty() && cands_[static_cast<size_t>(causes_[k].candidate)].joint == joint && !needed(i, live(k))) {
          by = cands_[static_cast<size_t>(causes_[k].candidate)].plugin->name;
          break;
        }
      causes_[i].superseded_by = by;
      changed = true;
    }
  }
  result_.timings.refits += since(t0);
}

nlohmann::json Diagnosis::per_joint(const Eigen::VectorXd& r, Eigen::Index N) const {
  nlohmann::json j = nlohmann::json::object();
  for (size_t o = 0; o < out_joints_.size(); ++o)
    j[out_joints_[o]] = std::sqrt(r.segment(static_cast<Eigen::Index>(o) * N, N).squaredNorm() / static_cast<double>(N));
  return j;
}

nlohmann::json Diagnosis::metrics(const Eigen::VectorXd& r_fit, const Eigen::VectorXd& r_test) const {
  auto rel = [&](const Eigen::VectorXd& r, const SplitData& s) {
    nlohmann::json j = nlohmann::json::object();
    for (size_t o = 0; o < out_joints_.size(); ++o) {
      const auto seg = static_cast<Eigen::Index>(o) * s.N;
      const double denom = s.b.segment(seg, s.N).norm();
      j[out_joints_[o]] = denom > 0 ? r.segment(seg, s.N).norm() / denom : std::numeric_limits<double>::infinity();
    }
    return j;
  };
  return {{"rmse_fit", per_joint(r_fit, fit_.N)}, {"rmse_test", per_joint(r_test, test_.N)},
          {"rel_error_fit", rel(r_fit, fit_)}, {"rel_error_test", rel(r_test, test_)},
          {"rel_error_fit_all", r_fit.norm() / fit_.b.norm()}, {"rel_error_test_all", r_test.norm() / test_.b.norm()}};
}

void Diagnosis::decide_parameters() {
  const std::vector<int> effects = kept_effects();
  const Fit free = refit(effects, true), fixed = refit(effects, false);
  parameters_delta_bic_ = delta_bic(static_cast<double>(fit_.y0.size()), fixed.rss, free.rss, free.rank - fixed.rank);
  parameters_named_ = parameters_delta_bic_ > opt_.bic_threshold &&
                      gains_on_test(residual_on(test_, effects, false, fixed).squaredNorm(),
                                    residual_on(test_, effects, true, free).squaredNorm(), opt_.min_gain);
}


// Standard MJCF quantities from the base parameters: beta = pi[independent] + Kd pi[dependent],
// so a change of beta is carried by the independent parameter of each group.
Eigen::VectorXd standard_from_base(const MjcfRegressor& reg, const MjcfRegressor::Base& base, const Eigen::VectorXd& delta) {
  Eigen::VectorXd pi = reg.model_params();
  for (int i = 0; i < base.rank; ++i) pi[base.independent[static_cast<size_t>(i)]] += delta[i];
  return pi;
}

void Diagnosis::build_report(const std::string& out_dir) {
  namespace fs = std::filesystem;
  auto t0 = Clock::now();
  nlohmann::json& R = result_.report;
  R["format"] = "spml-diagnose/1";
  R["model"] = opt_.model;
  R["data"] = opt_.data;
  R["fit_split"] = opt_.fit_split;
  R["test_split"] = test_name_;
  R["joints"] = out_joints_;
  R["rows"] = {{"fit", fit_.N}, {"test", test_.N}};
  R["settings"] = {{"bic_threshold", opt_.bic_threshold}, {"min_gain", opt_.min_gain}, {"max_causes", opt_.max_causes},
                   {"still_speed", opt_.still_speed}, {"candidates", cands_.size()}};
  R["baseline"] = metrics(fit_.y0, test_.y0);

  const std::vector<int> effects = kept_effects();
  const bool free = parameters_named_;
  const Fit final_fit = refit(effects, free);
  const Eigen::VectorXd final_test = residual_on(test_, effects, free, final_fit);

  nlohmann::json causes = nlohmann::json::array();
  MjcfEdits edits;
  std::vector<std::string> notes = notes_;
  if (free) {
    const Fit pf = refit({}, true);
    nlohmann::json params = nlohmann::json::object(), se = nlohmann::json::object(), prior = nlohmann::json::object();
    nlohmann::json undetermined = nlohmann::json::array();
    std::set<std::string> joints;
    for (int i = 0; i < base_.rank; ++i) {
      const double d = final_fit.coef[i], e = final_fit.stderr_[i];
      const std::string& name = base_.names[static_cast<size_t>(i)];
      if (!final_fit.determined[static_cast<size_t>(i)]) {
        undetermined.push_back(name);
        continue;
      }
      // Contradicted: the estimate lies beyond three standard errors of the MJCF's value.
      if (std::fabs(d) <= 3 * e) continue;
      params[name] = base_.model_values[i] + d;
      se[name] = e;
      prior[name] = base_.model_values[i];
      for (size_t j = 0; j < reg_->joint_names().size(); ++j)
        if (name.find(":" + reg_->joint_names()[j]) != std::string::npos) joints.insert(reg_->joint_names()[j]);
    }
    const nlohmann::json after = metrics(pf.residual, residual_on(test_, {}, true, pf));
    causes.push_back({{"effect", "parameters"}, {"joints", joints.empty() ? nlohmann::json(out_joints_) : nlohmann::json(joints)},
                      {"params", params}, {"stderr", se}, {"prior", prior}, {"not_identifiable", undetermined},
                      {"delta_bic", parameters_delta_bic_}, {"rmse_test_after", after["rmse_test"]},
                      {"rel_error_test_after", after["rel_error_test"]}, {"rel_error_fit_after", after["rel_error_fit"]},
                      {"rel_error_test_after_all", after["rel_error_test_all"]}, {"rel_error_fit_after_all", after["rel_error_fit_all"]}});
    // The corrected MJCF quantities.
    const Eigen::VectorXd pi = standard_from_base(*reg_, base_, final_fit.coef.head(base_.rank));
    const Eigen::VectorXd& pi0 = reg_->model_params();
    const auto& names = reg_->param_names();
    std::set<std::string> bodies;
    for (size_t k = 0; k < names.size(); ++k) {
      if (pi[static_cast<Eigen::Index>(k)] == pi0[static_cast<Eigen::Index>(k)]) continue;
      const std::string& nm = names[k];
      const auto colon = nm.find(':');
      const std::string kind = nm.substr(0, colon), what = nm.substr(colon + 1);
      if (kind == "armature" || kind == "damping" || kind == "stiffness" || kind == "coulomb") {
        if (mj_name2id(reg_->model(), mjOBJ_JOINT, what.c_str()) >= 0) {
          // MuJoCo needs these >= 0 (a negative armature makes the mass matrix singular, a
          // negative damping feeds energy in): an estimate below 0 is written as 0, and said.
          double v = pi[static_cast<Eigen::Index>(k)];
          if (v < 0 && kind != "stiffness") {
            notes.push_back(nm + " is estimated at " + fmt(v) + " (< 0, not physical): written as 0");
            v = 0;
          }
          edits.joint_attributes[what][kind == "coulomb" ? "frictionloss" : kind] = v;
        } else
          notes.push_back(nm + " changed but is a tendon quantity: not written");
      } else if (kind == "plugin") {
        notes.push_back(nm + " (a force plugin of the model) changed: not written, edit its declaration by hand");
      } else {
        bodies.insert(what);
      }
    }
    for (const auto& body : bodies) {
      auto at = [&](const std::string& k) {
        const auto it = std::find(names.begin(), names.end(), k + ":" + body);
        return pi[it - names.begin()];
      };
      const double mass = at("m");
      Eigen::Vector3d h(at("mx"), at("my"), at("mz"));
      Eigen::Matrix3d I;
      I << at("Ixx"), at("Ixy"), at("Ixz"), at("Ixy"), at("Iyy"), at("Iyz"), at("Ixz"), at("Iyz"), at("Izz");
      std::string why;
      MjcfEdits::Inertial in;
      in.body = body;
      if (!(mass > 0)) {
        why = "mass " + fmt(mass);
      } else {
        const Eigen::Vector3d c = h / mass;
        const Eigen::Matrix3d Ic = I - mass * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(Ic);
        const auto& l = eig.eigenvalues();
        if (!(l.minCoeff() > 0) || l[0] + l[1] < l[2]) why = "principal moments " + fmt(l[0]) + ", " + fmt(l[1]) + ", " + fmt(l[2]);
        in.mass = mass;
        for (int k = 0; k < 3; ++k) in.pos[k] = c[k];
        const double full[6] = {Ic(0, 0), Ic(1, 1), Ic(2, 2), Ic(0, 1), Ic(0, 2), Ic(1, 2)};
        std::copy(full, full + 6, in.fullinertia);
      }
      if (why.empty())
        edits.inertials.push_back(in);
      else
        notes.push_back("body '" + body + "': the re-identified inertial parameters are not physically consistent (" + why +
                        "), so its inertial is not written; the extended model keeps the MJCF's");
    }
  }
  nlohmann::json cross_after = nlohmann::json::array();
  if (free) {
    const Fit pf = refit({}, true);
    cross_after.push_back(cross_errors({}, true, pf));
  }
  // Effects, in the order chosen; after-metrics along the path (causes superseded by then left out).
  for (size_t i = 0; i < causes_.size(); ++i) {
    const Cause& cause = causes_[i];
    const Candidate& c = cands_[static_cast<size_t>(cause.candidate)];
    std::vector<int> path;
    for (size_t k = 0; k <= i; ++k) {
      bool gone = false;
      for (size_t l = k + 1; l <= i; ++l)
        gone |= !causes_[k].superseded_by.empty() && cands_[static_cast<size_t>(causes_[l].candidate)].plugin->name == causes_[k].superseded_by &&
                cands_[static_cast<size_t>(causes_[l].candidate)].joint == c.joint;
      if (!gone) path.push_back(causes_[k].candidate);
    }
    const Fit pf = refit(path, free);
    const nlohmann::json after = metrics(pf.residual, residual_on(test_, path, free, pf));
    cross_after.push_back(cross_errors(path, free, pf));
    // Parameter values: the final fit's for causes kept, the path's for superseded ones.
    const bool kept = cause.superseded_by.empty();
    const Fit& src = kept ? final_fit : pf;
    const std::vector<int>& order = kept ? effects : path;
    Eigen::Index off = free ? base_.rank : 0;
    for (int k : order) {
      if (k == cause.candidate) break;
      off += cands_[static_cast<size_t>(k)].fit_cols.cols;
    }
    PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, c.shape_values), "diagnose");
    const auto pnames = inst.param_names();
    nlohmann::json params = nlohmann::json::object(), se = nlohmann::json::object(), shape = nlohmann::json::object();
    Eigen::VectorXd theta(inst.nparam());
    for (int k = 0; k < inst.nparam(); ++k) {
      theta[k] = src.determined[static_cast<size_t>(off + k)] ? src.coef[off + k] : 0.0;
      params[pnames[static_cast<size_t>(k)]] = theta[k];
      se[pnames[static_cast<size_t>(k)]] = src.stderr_[off + k];
    }
    for (size_t k = 0; k < c.shape.size(); ++k) shape[c.shape[k]->key] = c.shape_values[k];
    inst.set_params(theta);
    const std::string config = inst.config_text();
    nlohmann::json j{{"effect", c.plugin->name}, {"joints", {c.joint_name}}, {"params", params}, {"stderr", se}, {"shape", shape},
                     {"delta_bic", cause.delta_bic}, {"rmse_test_after", after["rmse_test"]},
                     {"rel_error_test_after", after["rel_error_test"]}, {"rel_error_fit_after", after["rel_error_fit"]},
                     {"rel_error_test_after_all", after["rel_error_test_all"]}, {"rel_error_fit_after_all", after["rel_error_fit_all"]}};
    if (!kept) j["superseded_by"] = cause.superseded_by;
    if (kept) {
      const std::string name = "spml.plugin.diagnosed_" + std::string(c.plugin->name) + "_" + c.joint_name;
      if (config.empty())
        notes.push_back(std::string("plugin '") + c.plugin->name + "' cannot write its configuration (no write_config): " + name + " is not in the extended model");
      else {
        edits.texts.emplace_back(name, "type=" + std::string(c.plugin->name) + " joints=" + c.joint_name + " " + config);
        j["declaration"] = edits.texts.back().second;
      }
    }
    causes.push_back(j);
  }
  R["causes"] = causes;
  R["final"] = metrics(final_fit.residual, final_test);
  if (!cross_.empty()) {
    nlohmann::json cross = nlohmann::json::array();
    const nlohmann::json fin = cross_errors(effects, free, final_fit);
    for (size_t k = 0; k < cross_.size(); ++k) {
      const SplitData& s = cross_[k].second;
      nlohmann::json after = nlohmann::json::array();
      for (const auto& step : cross_after) after.push_back(step[k]);
      cross.push_back({{"data", cross_[k].first}, {"split", s.name}, {"rows", s.N},
                       {"rel_error_given", s.y0.norm() / s.b.norm()}, {"rel_error_after_each_cause", after},
                       {"rel_error_final", fin[k]}});
    }
    R["cross"] = cross;
  }
  nlohmann::json still = nlohmann::json::array();
  for (size_t j = 0; j < still_.size(); ++j)
    if (still_[j])
      still.push_back({{"joint", reg_->joint_names()[j]},
                       {"reason", "does not move in the fit split (|qd| <= " + fmt(opt_.still_speed) + "): its friction and inertia are not identifiable; no cause is tried on it"}});
  R["not_identifiable"] = still;
  R["not_tried"] = not_tried_;

  // extended.xml, then its own check: its inverse dynamics must reproduce the final prediction.
  edits.comment = "extended by spml diagnose from " + opt_.model + " and " + opt_.data + " (fit split '" + opt_.fit_split + "')";
  result_.extended_mjcf = write_extended_mjcf(opt_.model, edits, notes);
  const fs::path ext_path = out_dir.empty() ? fs::temp_directory_path() / ("spml-extended-" + std::to_string(::getpid()) + ".xml")
                                            : fs::path(out_dir) / "extended.xml";
  if (!out_dir.empty()) fs::create_directories(out_dir);
  write_text_atomic(ext_path.string(), result_.extended_mjcf);
  R["extended_mjcf"] = out_dir.empty() ? "" : "extended.xml";
  const Eigen::VectorXd final_pred_fit = fit_.b - final_fit.residual;
  {
    MjcfRegressor ext(ext_path.string());
    auto ebase = ext.base_parameters();
    const JointColumns cols(ext, fit_.split);
    const Eigen::MatrixXd A = stacked_base_regressor(ext, ebase, fit_.split.X, cols, fit_.name);
    const Eigen::VectorXd pred = A * ebase.model_values;
    R["extended_check"] = {{"max_abs_deviation", (pred - final_pred_fit).cwiseAbs().maxCoeff()},
                           {"rms_torque", std::sqrt(fit_.b.squaredNorm() / static_cast<double>(fit_.b.size()))}};
  }
  result_.timings.outputs += since(t0);
  t0 = Clock::now();
  if (opt_.rollouts > 0) {
    try {
      const RolloutResult before = rollout(opt_.model, test_.split, opt_.rollouts, opt_.rollout_seconds);
      const RolloutResult after = rollout(ext_path.string(), test_.split, opt_.rollouts, opt_.rollout_seconds);
      nlohmann::json b = nlohmann::json::object(), a = nlohmann::json::object();
      for (size_t j = 0; j < before.joints.size(); ++j) {
        b[before.joints[j]] = before.position_error[j];
        a[after.joints[j]] = after.position_error[j];
      }
      R["rollout"] = {{"split", test_name_}, {"horizon_s", opt_.rollout_seconds}, {"windows", before.windows},
                      {"position_error_before", b}, {"position_error_after", a}};
    } catch (const std::exception& e) {
      R["rollout"] = {{"skipped", e.what()}};
    }
  }
  if (out_dir.empty()) fs::remove(ext_path);
  result_.timings.rollouts += since(t0);
  R["notes"] = notes;

  // Per-sample series for the plots: both splits, measured and predicted torques.
  t0 = Clock::now();
  if (!out_dir.empty()) {
    std::ostringstream csv;
    csv.precision(10);
    csv << "split,t";
    for (const auto& j : out_joints_) csv << ",q:" << j << ",qd:" << j << ",tau:" << j << ",given:" << j << ",final:" << j;
    csv << "\n";
    auto rows = [&](const SplitData& s, const Eigen::VectorXd& final_pred) {
      for (Eigen::Index i = 0; i < s.N; ++i) {
        csv << (&s == &fit_ ? "fit" : "test") << "," << (s.split.t.size() ? s.split.t[i] : static_cast<double>(i));
        for (size_t o = 0; o < out_joints_.size(); ++o) {
          const auto j = static_cast<size_t>(out_joint_index_[o]);
          const Eigen::Index r = static_cast<Eigen::Index>(o) * s.N + i;
          csv << "," << s.split.X(i, s.cols->q[j]) << "," << s.split.X(i, s.cols->qd[j]) << "," << s.b[r] << "," << s.given[r] << ","
              << final_pred[r];
        }
        csv << "\n";
      }
    };
    rows(fit_, final_pred_fit);
    rows(test_, test_.b - final_test);
    write_text_atomic((fs::path(out_dir) / "series.csv").string(), csv.str());
  }
  result_.timings.outputs += since(t0);
}

DiagnoseResult Diagnosis::run(const std::string& out_dir) {
  auto t0 = Clock::now();
  load();
  find_candidates();
  result_.timings.load = since(t0);
  select();
  t0 = Clock::now();
  decide_parameters();
  result_.timings.refits += since(t0);
  build_report(out_dir);
  auto& T = result_.timings;
  result_.report["timings_s"] = {{"load", T.load}, {"search", T.search}, {"refits", T.refits}, {"rollouts", T.rollouts}, {"outputs", T.outputs}};
  result_.summary = report_summary(result_.report);
  if (!out_dir.empty()) {
    namespace fs = std::filesystem;
    write_text_atomic((fs::path(out_dir) / "report.md").string(), report_markdown(result_.report));
    write_text_atomic((fs::path(out_dir) / "report.json").string(), result_.report.dump(2) + "\n");
  }
  return result_;
}

}  // namespace

DiagnoseResult diagnose(const DiagnoseOptions& options, const std::string& out_dir) {
  Diagnosis d(options);
  return d.run(out_dir);
}

}  // namespace spml
