// The model's own friction level on a joint, taken over by a named friction. A model may
// already state a dry-friction level on a joint - MuJoCo's frictionloss, a declared coulomb
// plugin, the Coulomb friction a previous diagnosis wrote - and the data may hold more than a
// level there (a LuGre break-away). A named friction that holds a whole level of its own on
// that joint (Coulomb, Stribeck, asymmetric friction, LuGre) replaces the model's: written beside
// it, the joint had two frictions. (A review's model declaring Coulomb 0.69 on a LuGre joint:
// `stick_slip` was fitted with the base parameters free - the declared level refitted to 0.03 -
// but written beside the declared 0.69, its rollouts 4.8 times worse and rejected; the model
// without the declaration has `stick_slip` named, 1.47 % held out where the declaring model
// as given leaves 3.16 %.)
//
// So, for a joint whose own level a cause takes over: every fit with the cause, the base
// parameters free or held at the MJCF's values, holds none of that level (its columns zero,
// its force returned to the targets: base_without_taken, returned_levels), and a stateful
// candidate is searched that way (level_held); `parameters` does not list the level as
// contradicted (the cause carries it); and every model written with the cause states the level
// as 0 (with_take_over), which a model written without the cause does not.
#include <mujoco/mujoco.h>

#include "diagnosis.h"

namespace spml::diagnose_detail {

// Per model joint: frictionloss, and the declared linear plugin parameters whose force on that
// joint is a pure level (the same size and opposed to the motion at every speed and position
// tried, zero on the other joints). Checked on the plugin's regressor at chosen states, not on
// the data: the same answer for every split.
void Diagnosis::find_own_levels() {
  const mjModel* m = reg_->model();
  own_levels_.assign(static_cast<size_t>(m->njnt), OwnLevel{});
  for (int j = 0; j < m->njnt; ++j) {
    const int dof = m->jnt_dofadr[j];
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
    own_levels_[static_cast<size_t>(j)].frictionloss = m->dof_frictionloss[dof];
  }
  const std::vector<double> speeds = {-3, -0.4, -0.004, 0.004, 0.4, 3}, shifts = {0, 0.37, -0.81};
  const auto& insts = declared_->instances();
  for (size_t n = 0; n < insts.size(); ++n) {
    const PluginInstance& inst = insts[n].object;
    if (!inst.plugin().regressor) continue;
    const int np = inst.nparam();
    const Eigen::VectorXd theta = inst.params();
    const auto names = inst.param_names();
    for (int j = 0; j < m->njnt; ++j) {
      if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
      const int dof = m->jnt_dofadr[j], qadr = m->jnt_qposadr[j];
      std::vector<double> size(static_cast<size_t>(np), 0.0);
      std::vector<bool> level(static_cast<size_t>(np), true);
      std::vector<mjtNum> qpos(m->qpos0, m->qpos0 + m->nq), qvel(static_cast<size_t>(m->nv), 0.0),
          R(static_cast<size_t>(m->nv) * static_cast<size_t>(np));
      for (double shift : shifts)
        for (double v : speeds) {
          qpos[static_cast<size_t>(qadr)] = m->qpos0[qadr] + shift;
          qvel[static_cast<size_t>(dof)] = v;
          std::fill(R.begin(), R.end(), 0.0);
          inst.plugin().regressor(inst.state(), m, qpos.data(), qvel.data(), R.data());
          for (int k = 0; k < np; ++k) {
            // Inverse dynamics holds -R theta (columns()): a level is -R = c sign(v), one c > 0.
            const double c = -R[static_cast<size_t>(dof * np + k)] * (v > 0 ? 1.0 : -1.0);
            double elsewhere = 0;
            for (int w = 0; w < m->nv; ++w)
              if (w != dof) elsewhere += std::fabs(R[static_cast<size_t>(w * np + k)]);
            auto& s = size[static_cast<size_t>(k)];
            if (s == 0) s = c;
            level[static_cast<size_t>(k)] = level[static_cast<size_t>(k)] && c > 0 && std::fabs(c - s) <= 1e-12 * s && elsewhere == 0;
          }
        }
      for (int k = 0; k < np; ++k)
        if (level[static_cast<size_t>(k)]) {
          OwnLevel& o = own_levels_[static_cast<size_t>(j)];
          o.params.push_back({n, k});
          o.names.push_back("plugin:" + insts[n].decl.instance + "." + names[static_cast<size_t>(k)]);
          o.declared += size[static_cast<size_t>(k)] * theta[k];
        }
    }
  }
  for (size_t j = 0; j < own_levels_.size(); ++j)
    if (own_levels_[j].frictionloss != 0) own_levels_[j].names.push_back("coulomb:" + reg_->joint_names()[j]);
}

// The model's own level force per output, stacked like b (unfiltered; `soft` is MuJoCo's
// frictionloss beyond its ideal level, unfiltered too); empty when no joint has one.
Eigen::VectorXd Diagnosis::own_level_force(const SplitData& s, const Eigen::VectorXd& soft) const {
  const mjModel* m = reg_->model();
  const auto O = static_cast<Eigen::Index>(s.cols->output_dof.size());
  Eigen::VectorXd out;
  for (Eigen::Index o = 0; o < O; ++o) {
    const int j = m->dof_jntid[s.cols->output_dof[static_cast<size_t>(o)]];
    const OwnLevel& L = own_levels_[static_cast<size_t>(j)];
    if (!L.any()) continue;
    if (!out.size()) out = Eigen::VectorXd::Zero(s.N * O);
    const auto qd = s.split.X.col(s.cols->qd[static_cast<size_t>(j)]);
    for (Eigen::Index i = 0; i < s.N; ++i) out[o * s.N + i] = (L.frictionloss + L.declared) * (qd[i] > 0 ? 1.0 : qd[i] < 0 ? -1.0 : 0.0);
    if (L.frictionloss != 0 && soft.size()) out.segment(o * s.N, s.N) += soft.segment(o * s.N, s.N);
  }
  return out;
}

// Does cause candidate k hold a whole friction level of its own on its joint: a static one
// whose columns span the joint's Coulomb column (as filtered), a stateful one that dissipates?
bool Diagnosis::takes_over(int k) const {
  const Candidate& c = cands_[static_cast<size_t>(k)];
  if (c.joint < 0 || !own_levels_[static_cast<size_t>(c.joint)].any()) return false;
  if (c.stateful) return dissipates(c);
  const auto o = std::find(out_joint_index_.begin(), out_joint_index_.end(), c.joint) - out_joint_index_.begin();
  const auto p = std::find(c.fit_cols.active.begin(), c.fit_cols.active.end(), static_cast<int>(o)) - c.fit_cols.active.begin();
  if (static_cast<size_t>(p) >= c.fit_cols.parts.size()) return false;
  Eigen::VectorXd sign(fit_.N);
  const auto qd = fit_qd(o);
  for (Eigen::Index i = 0; i < fit_.N; ++i) sign[i] = qd[i] > 0 ? 1.0 : qd[i] < 0 ? -1.0 : 0.0;
  if (sign.squaredNorm() == 0) return false;
  filter_stacked(fit_.sos, sign, fit_.N, fit_.runs);
  const Eigen::MatrixXd& A = c.fit_cols.parts[static_cast<size_t>(p)];
  const Eigen::VectorXd left = sign - A * A.colPivHouseholderQr().solve(sign);
  return left.norm() <= 1e-8 * sign.norm();
}

// The joints (model indices) whose own level one of `causes` takes over.
std::vector<int> Diagnosis::taken_over(const std::vector<int>& causes) const {
  std::vector<int> joints;
  for (int k : causes) {
    const int j = cands_[static_cast<size_t>(k)].joint;
    if (std::find(joints.begin(), joints.end(), j) == joints.end() && takes_over(k)) joints.push_back(j);
  }
  return joints;
}

// What the model as given predicts of the levels `causes` take over, on split s (stacked, as
// filtered; empty: none): added to the targets of a fit with the base parameters held.
Eigen::VectorXd Diagnosis::returned_levels(const SplitData& s, const std::vector<int>& causes) const {
  if (!s.own_level.size()) return {};
  const std::vector<int> joints = taken_over(causes);
  if (joints.empty()) return {};
  Eigen::VectorXd out = Eigen::VectorXd::Zero(s.own_level.size());
  for (size_t o = 0; o < out_joint_index_.size(); ++o)
    if (std::find(joints.begin(), joints.end(), out_joint_index_[o]) != joints.end()) {
      const auto seg = static_cast<Eigen::Index>(o) * s.N;
      out.segment(seg, s.N) = s.own_level.segment(seg, s.N);
    }
  return out;
}

// Is base parameter i (every term of it) the own level of one of `joints`?
bool Diagnosis::own_level_parameter(int i, const std::vector<int>& joints) const {
  if (joints.empty()) return false;
  for (const auto& term : term_names(base_.names[static_cast<size_t>(i)])) {
    bool own = false;
    for (int j : joints) {
      const auto& names = own_levels_[static_cast<size_t>(j)].names;
      own |= std::find(names.begin(), names.end(), term) != names.end();
    }
    if (!own) return false;
  }
  return true;
}

// The base block of a fit with `causes` where they take over own levels: a copy with those
// levels' columns zero (undetermined, coefficient 0); none where they take over nothing.
std::optional<BlockColumns> Diagnosis::base_without_taken(const BlockColumns& base, const std::vector<int>& causes) const {
  const std::vector<int> joints = taken_over(causes);
  if (joints.empty()) return std::nullopt;
  BlockColumns out = base;
  for (int i = 0; i < out.cols; ++i)
    if (own_level_parameter(i, joints))
      for (auto& part : out.parts) part.col(i).setZero();
  return out;
}

// The base block and targets of a fit with `causes` on the fit split (or `on`, a split
// prepared like it): its own, or where they take over own levels, the base without those levels
// (base_without_taken) and their force returned to the targets.
TakenBase Diagnosis::taken_base(const std::vector<int>& causes, const SplitData* on) const {
  const SplitData& s = on ? *on : fit_;
  TakenBase t{base_without_taken(s.base, causes), s.y0};
  if (const Eigen::VectorXd returned = returned_levels(s, causes); returned.size()) t.y += returned;
  return t;
}

// Is base parameter i the own level of a joint `causes` take over?
bool Diagnosis::taken_level(int i, const std::vector<int>& causes) const { return own_level_parameter(i, taken_over(causes)); }

// The fit a stateful candidate k is searched against: `current` (the base parameters free
// beside `chosen`), but where k's joint has an own level, without that level's base columns
// and with the level returned to the targets. Free beside it, the level took a share of
// LuGre's (a review's elbow: fc 0.044 of 0.06 and fs 36, the declared column the rest) and
// the written model, which states the level 0, rolled out worse.
Fit Diagnosis::level_held(int k, const Fit& current, const std::vector<int>& chosen) const {
  const Candidate& c = cands_[static_cast<size_t>(k)];
  if (!c.stateful || c.joint < 0 || !own_levels_[static_cast<size_t>(c.joint)].any() || !fit_.own_level.size()) return current;
  std::vector<Eigen::Index> keep;
  for (int i = 0; i < fit_.base.cols; ++i)
    if (!own_level_parameter(i, {c.joint})) keep.push_back(i);
  BlockColumns base = fit_.base;
  base.cols = static_cast<int>(keep.size());
  for (size_t p = 0; p < base.parts.size(); ++p) base.parts[p] = fit_.base.parts[p](Eigen::all, keep);
  std::vector<const BlockColumns*> with{&base};
  for (int q : chosen) with.push_back(&cands_[static_cast<size_t>(q)].fit_cols);
  // The level returned on k's joint (before the fit, takes_over cannot ask k's force whether it dissipates).
  Eigen::VectorXd target = fit_.y0;
  for (size_t o = 0; o < out_joint_index_.size(); ++o)
    if (out_joint_index_[o] == c.joint) target.segment(static_cast<Eigen::Index>(o) * fit_.N, fit_.N) += fit_.own_level.segment(static_cast<Eigen::Index>(o) * fit_.N, fit_.N);
  return fit_blocks(with, target, true);
}

// The edits as written: where a diagnosed declaration of `takers` (default: e itself) is a
// cause that takes over its joint's own level, that level is 0 - frictionloss="0" on the joint,
// the declared plugin parameters at 0 in their own texts.
MjcfEdits Diagnosis::with_take_over(const MjcfEdits& e, const MjcfEdits* takers) const {
  const MjcfEdits& t = takers ? *takers : e;
  // Any candidate's (the rollout test writes one before it is chosen); one per plugin and joint.
  std::vector<int> causes;
  for (size_t k = 0; k < cands_.size(); ++k)
    for (const auto& text : t.texts)
      if (text.first == declaration_name(cands_[k])) causes.push_back(static_cast<int>(k));
  MjcfEdits out = e;
  const std::vector<int> joints = taken_over(causes);
  if (joints.empty()) return out;
  const auto& insts = declared_->instances();
  std::map<size_t, std::vector<bool>> zeroed;   // declared instance -> its parameters taken over
  for (int j : joints) {
    const OwnLevel& L = own_levels_[static_cast<size_t>(j)];
    if (L.frictionloss != 0) out.joint_attributes[reg_->joint_names()[static_cast<size_t>(j)]]["frictionloss"] = 0;
    for (const auto& [n, k] : L.params) {
      if (!zeroed.count(n)) zeroed[n].assign(static_cast<size_t>(insts[n].object.nparam()), false);
      zeroed[n][static_cast<size_t>(k)] = true;
    }
  }
  for (const auto& [n, taken] : zeroed) {
    // From the values `parameters` re-identified where identified_model_edits rewrote the text.
    const std::string text_name = "spml.plugin." + insts[n].decl.instance;
    const auto it = out.replaced_texts.find(text_name);
    const std::string data = declared_->redeclared(n, [&](Eigen::VectorXd& theta) {
      for (size_t k = 0; k < taken.size(); ++k)
        if (taken[k]) theta[static_cast<Eigen::Index>(k)] = 0;
    }, it != out.replaced_texts.end() ? it->second : "");
    if (!data.empty()) out.replaced_texts[text_name] = data;   // empty: the plugin cannot write itself, its text stays as declared
  }
  return out;
}

// report.json: the model's own level a kept cause takes over ({} when none): frictionloss and
// the declared plugin parameters, as the model as given states them.
nlohmann::json Diagnosis::replaced_friction(int k) const {
  nlohmann::json j = nlohmann::json::object();
  if (!takes_over(k)) return j;
  const OwnLevel& L = own_levels_[static_cast<size_t>(cands_[static_cast<size_t>(k)].joint)];
  if (L.frictionloss != 0) j["frictionloss"] = L.frictionloss;
  const auto& insts = declared_->instances();
  for (const auto& [n, p] : L.params) j["spml.plugin." + insts[n].decl.instance][insts[n].object.param_names()[static_cast<size_t>(p)]] = insts[n].object.params()[p];
  return j;
}

}  // namespace spml::diagnose_detail
