// Stage 4a, candidates: every force plugin with a regressor, on every joint that moves, and the
// regressor columns of one configured plugin on one split.
#include <algorithm>
#include <cmath>

#include "diagnosis.h"
#include "statistics.h"
#include "spml/column_unit.h"
#include "spml/parse.h"
#include "spml/signal.h"

namespace spml::diagnose_detail {

// The configuration a candidate is made with: its shape values, and for every other required
// key a neutral value (0 clipped into the key's range): linear parameters do not change the
// regressor columns, so their values do not matter here.
void Diagnosis::find_candidates() {
  for (const std::string& name : available_force_plugins()) {
    const spml_force_plugin& p = load_force_plugin(name);
    if (!p.regressor && is_stateful(p)) {   // #22: fitted by simulation (stateful_fit.cc)
      add_stateful_candidates(p);
      continue;
    }
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
    add_candidates(p, shape, fixed);
  }
}

// One candidate per moving joint, with the shape ranges made absolute: position shapes span
// the joint's stroke in the fit split, speed shapes its largest speed.
void Diagnosis::add_candidates(const spml_force_plugin& p, const std::vector<const spml_shape_param*>& shape,
                               const std::vector<std::pair<std::string, std::string>>& fixed) {
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
    if (std::string(p.name) == "ripple") {
      std::vector<double> speed(static_cast<size_t>(q.size()));
      for (Eigen::Index i = 0; i < q.size(); ++i) speed[static_cast<size_t>(i)] = std::fabs(fit_.split.X(i, fit_.cols->qd[static_cast<size_t>(j)]));
      if (!bound_wavenumber(c, q.maxCoeff() - q.minCoeff(), quantile(std::move(speed), 0.5))) continue;
    }
    cands_.push_back(std::move(c));
  }
}

// A position-periodic effect is told from a smooth position-dependent residual only when the
// stroke spans several of its periods: the ripple's wavenumber (`gear`, periods per radian
// over 2 pi) is searched from min_ripple_periods periods over the stroke upwards, or fixed
// at the drive's gear ratio when given. Upwards it is bounded by the band the data keep (the
// parallel filter's cut-off, else 0.4 of the sampling rate) at the joint's median speed: a
// faster ripple is seen only near reversals, where it dresses up the filtered step of Coulomb
// friction (gear 199 beside a hidden Coulomb level through a 10 Hz low-pass: 32 Hz at the
// joint's median speed). False (with a note) when nothing is left to search.
bool Diagnosis::bound_wavenumber(Candidate& c, double stroke, double median_speed) {
  const double dt = fit_.split.t.size() == fit_.split.rows() && fit_.split.rows() > 1 ? median_step(fit_.split.t) : 0;
  const double band_hz = !fit_.sos.empty() ? filter_plan_.lowpass.cutoff_hz : dt > 0 ? kWidestLowpassShare / dt : 0;
  for (size_t k = 0; k < c.shape.size(); ++k) {
    if (std::string(c.shape[k]->key) != "gear") continue;
    auto& [lo, hi] = c.shape_range[k];
    if (opt_.ripple_gear > 0) {
      lo = hi = opt_.ripple_gear;
      return true;
    }
    const std::string unit = column_unit("q:", reg_->model()->jnt_type[c.joint] == mjJNT_SLIDE);
    lo = std::max(lo, std::ceil(opt_.min_ripple_periods * 2 * M_PI / std::max(stroke, 1e-12)));
    if (lo > hi) {
      not_tried_.push_back({{"effect", "ripple"}, {"joint", c.joint_name},
                            {"reason", "the stroke (" + fmt(stroke) + " " + unit + ") spans fewer than " + fmt(opt_.min_ripple_periods) +
                                           " periods of any wavenumber the plugin allows: a ripple cannot be told from a smooth residual"}});
      return false;
    }
    if (band_hz > 0 && median_speed > 0) hi = std::min(hi, std::floor(2 * M_PI * band_hz / median_speed));
    if (lo > hi) {
      not_tried_.push_back({{"effect", "ripple"}, {"joint", c.joint_name},
                            {"reason", "at the joint's median speed (" + fmt(median_speed) + " " + unit + "/s) every wavenumber from " + fmt(lo) +
                                           " up lies above the band the data keep (" + fmt(band_hz) + " Hz): such a ripple shows only near reversals"}});
      return false;
    }
  }
  return true;
}

std::vector<std::pair<std::string, std::string>> Diagnosis::config_of(const Candidate& c, const std::vector<double>& shape) const {
  auto config = c.fixed;
  for (size_t k = 0; k < c.shape.size(); ++k)
    config.emplace_back(c.shape[k]->key, c.shape[k]->integer ? integer_text(shape[k]) : exact_text(shape[k]));
  return config;
}

BlockColumns Diagnosis::columns(const PluginInstance& inst, const SplitData& s, bool filtered) const {
  if (!inst.plugin().regressor) return simulated_columns(inst, s);   // #22: a stateful plugin (simulated, always filtered)
  const mjModel* m = reg_->model();
  const int np = inst.nparam(), O = static_cast<int>(s.split.Y.cols());
  BlockBuilder C(s.N, O, np);
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
      for (int k = 0; k < np; ++k) C.set(o, i, k, -R[static_cast<size_t>(s.cols->output_dof[static_cast<size_t>(o)] * np + k)]);
  }
  if (!C.all_finite())
    throw PluginError("plugin '" + std::string(inst.plugin().name) + "' gave non-finite regressor values on split '" + s.name + "'");
  return std::move(C).finish([&](Eigen::MatrixXd& part) {
    if (filtered) filter_stacked(s.sos, part, s.N, s.runs);
  });
}

// The columns of a candidate with its chosen shape on another split (test, cross).
BlockColumns Diagnosis::columns_of(const Candidate& c, const SplitData& s) const {
  PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, c.shape_values), "diagnose");
  return columns(inst, s);
}

Eigen::Ref<const Eigen::VectorXd> Diagnosis::fit_qd(Eigen::Index output) const {
  return fit_.split.X.col(fit_.cols->qd[static_cast<size_t>(out_joint_index_[static_cast<size_t>(output)])]);
}

// `col` (stacked over the outputs, fit split): C is the column in inverse dynamics (tau = ... -
// force), so the force's power is -C qd.
bool Diagnosis::opposes_motion(const Eigen::VectorXd& col) const {
  const Eigen::Index N = fit_.N;
  bool acts = false;
  for (Eigen::Index o = 0; o * N < col.size(); ++o) {
    const auto qd = fit_qd(o);
    for (Eigen::Index i = 0; i < N; ++i) {
      const double power = -col[o * N + i] * qd[i];
      if (power > 0) return false;
      acts |= power < 0;
    }
  }
  return acts;
}

double Diagnosis::rate_of(const Eigen::VectorXd& col) const {
  const Eigen::Index N = fit_.N;
  double slope = 0;
  for (Eigen::Index o = 0; o * N < col.size(); ++o) {
    const auto qd = fit_qd(o);
    for (Eigen::Index i = 0; i < N; ++i) {
      const double v = col[o * N + i];
      if (v == 0) continue;
      if (std::abs(qd[i]) < 1e-12) return 0;
      const double r = v / qd[i];
      if (slope == 0) slope = r;
      else if (std::abs(r - slope) > 1e-9 * std::abs(slope)) return 0;   // not proportional to q̇
    }
  }
  return slope;
}

// A term whose force opposes the joint's motion at every row of the fit split (Coulomb, Stribeck,
// viscous, one direction of asymmetric friction, a band) is friction: fitted with a negative
// coefficient it would push the joint along its motion, feeding it energy, which no friction
// does. Such a fit is the regression spending a dissipative column on something else (rounding,
// a constraint's stick phases), not a cause. Terms that are not sign-definite (ripple, offset)
// are free. Checked on the unfiltered columns: the filter smears signs at reversals.
// A viscous column (proportional to q̇ wherever it acts, e.g. asymmetric friction's fv_pos) adds
// to the joint's own damping: a negative coefficient lowers that damping and feeds the joint
// energy only beyond it (EMPS: damping 200, fv_pos -33.6 is a correction, not a pump). The
// damping is the MJCF's, or `damping` when the base parameters were refitted beside it (the
// joint's q̇ column is a base column too, and the fit splits the shared part between them).
bool Diagnosis::within_damping(const Eigen::VectorXd& col, int joint, double coef, double damping) const {
  const mjModel* m = reg_->model();
  const double slope = rate_of(col);
  return slope > 0 && (std::isfinite(damping) ? damping : m->dof_damping[m->jnt_dofadr[joint]]) + slope * coef >= 0;
}

double Diagnosis::refitted_damping(int joint, const Fit& f) const {
  const std::string name = "damping:" + reg_->joint_names()[static_cast<size_t>(joint)];
  for (int i = 0; i < base_.rank && i < f.coef.size(); ++i)
    if (base_.names[static_cast<size_t>(i)] == name && f.determined[static_cast<size_t>(i)]) return base_.model_values[i] + f.coef[i];
  return std::numeric_limits<double>::quiet_NaN();
}

// Friction of a level, not of a rate: a stateful candidate's force (as fitted, amplitude +1)
// takes energy out on balance over the fit split; every column of a static one opposes the
// motion (checked unfiltered, as above) and none is a rate (Coulomb, Stribeck, a band; not
// viscous friction or asymmetric friction's fv columns, which LuGre with sigma2 = 0 does not
// hold).
bool Diagnosis::dissipates(const Candidate& c) const {
  if (c.stateful) {
    if (c.fit_cols.cols != 1) return false;
    double power = 0;
    for (size_t p = 0; p < c.fit_cols.parts.size(); ++p) power -= c.fit_cols.parts[p].col(0).dot(fit_qd(c.fit_cols.active[p]));
    return power < 0;
  }
  const auto [levels, cols] = level_friction_columns(c);
  return cols > 0 && levels == cols;
}

// Does a static candidate hold a friction of a level: a column that opposes the motion and is
// not a rate (asymmetric friction's fc_pos and fc_neg, beside its fv columns)?
bool Diagnosis::holds_level_friction(const Candidate& c) const { return !c.stateful && level_friction_columns(c).first > 0; }

// How many of a static candidate's columns (checked unfiltered) oppose the motion and are no
// rate, and how many columns it has.
std::pair<Eigen::Index, Eigen::Index> Diagnosis::level_friction_columns(const Candidate& c) const {
  PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, c.shape_values), "diagnose");
  const Eigen::MatrixXd C = columns(inst, fit_, false).dense();
  Eigen::Index levels = 0;
  for (Eigen::Index k = 0; k < C.cols(); ++k) levels += opposes_motion(C.col(k)) && rate_of(C.col(k)) == 0;
  return {levels, C.cols()};
}

std::string Diagnosis::injects_energy(const Candidate& c, const Eigen::VectorXd& theta, double damping) const {
  PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, c.shape_values), "diagnose");
  const Eigen::MatrixXd C = columns(inst, fit_, false).dense();
  const auto names = inst.param_names();
  for (Eigen::Index k = 0; k < theta.size() && k < C.cols(); ++k)
    if (theta[k] < 0 && opposes_motion(C.col(k)) && !within_damping(C.col(k), c.joint, theta[k], damping))
      return names[static_cast<size_t>(k)] + " = " + fmt(theta[k]) + " < 0 on a term that opposes the motion at every sample: negative "
             "friction would feed the joint energy, not dissipate it";
  return "";
}

// The signs an effect's own form needs, checked on its fitted coefficients: by refused() and,
// at every shape, by the shape search (shape_search.cc) - else the search settles where the
// fit leaves the form (a Stribeck speed at the bottom of its range, vs 0.004 rad/s, with fs
// < fc, refused after, where the hidden curve had vs 0.29 rad/s and fs 3 fc).
std::string Diagnosis::outside_its_form(const Candidate& c, const Eigen::VectorXd& theta) {
  // A Stribeck curve falls from its break-away level fs to the Coulomb level fc. Fitted with
  // fs < fc it is friction lower at low speed: the stick phases of Coulomb friction (the joint
  // held while the applied torque is below fc, read through estimated velocities), not Stribeck.
  if (std::string(c.plugin->name) == "stribeck")
    for (Eigen::Index k = 0; k + 1 < theta.size(); k += 2)
      if (!(theta[k + 1] >= theta[k]))
        return "fs " + fmt(theta[k + 1]) + " < fc " + fmt(theta[k]) + ": not a Stribeck curve (friction lower at low speed: stick phases)";
  // A spring pulls the joint back to its rest position: stiffness k > 0 (MuJoCo's `stiffness`,
  // which extended.xml writes it as, is >= 0). Fitted with k <= 0 the q column is spent on
  // something else (gravity the base parameters leave, errors of the derived states).
  if (std::string(c.plugin->name) == "spring")
    for (Eigen::Index k = 0; k + 1 < theta.size(); k += 2)
      if (!(theta[k] > 0))
        return "k " + fmt(theta[k]) + " <= 0: not a spring (a negative stiffness pushes the joint away from its rest position)";
  return "";
}

std::string Diagnosis::refused(int candidate, const Eigen::VectorXd& theta, double damping) const {
  const Candidate& c = cands_[static_cast<size_t>(candidate)];
  if (c.stateful) return theta.size() == 1 && theta[0] > 0 ? "" : "the simulated force would enter with a negative amplitude";   // #22
  if (std::string form = outside_its_form(c, theta); !form.empty()) return form;
  const std::string pumping = injects_energy(c, theta, damping);
  if (!pumping.empty()) return pumping;
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

}  // namespace spml::diagnose_detail
