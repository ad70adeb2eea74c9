// The regressor against MuJoCo's own inverse dynamics (mj_inverse), at seeded states: where
// Y(q, qd, qdd) * pi(model) differs from qfrc_inverse, the model holds something the regressor
// does not express, and every fit on data simulated from it starts from a wrong model.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <set>

#include "spml/envs/mjcf_regressor.h"
#include "spml/parse.h"

namespace spml {
namespace {

// Which constraint kinds act on each dof at the current state of d (after mj_inverse).
void constraint_kinds(const mjModel* m, const mjData* d, std::vector<std::set<std::string>>& kinds) {
  auto label = [&](int i) -> std::string {
    switch (d->efc_type[i]) {
      case mjCNSTR_EQUALITY: return "an equality constraint";
      case mjCNSTR_FRICTION_DOF: return "MJCF frictionloss (MuJoCo applies it as a soft constraint, not as ideal Coulomb friction)";
      case mjCNSTR_FRICTION_TENDON: return "a tendon's frictionloss (a soft constraint)";
      case mjCNSTR_LIMIT_JOINT: return "a joint limit";
      case mjCNSTR_LIMIT_TENDON: return "a tendon limit";
      default: return "contacts";
    }
  };
  const bool sparse = mj_isSparse(m);
  for (int i = 0; i < d->nefc; ++i) {
    if (d->efc_force[i] == 0) continue;
    if (sparse) {
      for (int k = 0; k < d->efc_J_rownnz[i]; ++k) kinds[d->efc_J_colind[d->efc_J_rowadr[i] + k]].insert(label(i));
    } else {
      for (int v = 0; v < m->nv; ++v)
        if (d->efc_J[i * m->nv + v] != 0) kinds[v].insert(label(i));
    }
  }
}

}  // namespace

std::vector<InverseMismatch> MjcfRegressor::inverse_mismatches(int states, std::uint64_t seed) const {
  const mjModel* m = m_.get();
  const int nv = m->nv;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Workspace ws = workspace();
  DataPtr d = make_data(m);
  Eigen::VectorXd q(m->njnt), qd(m->njnt), qdd(m->njnt);
  Eigen::VectorXd worst = Eigen::VectorXd::Zero(nv), sum_sq = Eigen::VectorXd::Zero(nv);
  std::vector<std::set<std::string>> kinds(static_cast<size_t>(nv));
  std::vector<mjtNum> plugin(static_cast<size_t>(nv));
  for (int s = 0; s < states; ++s) {
    for (int j = 0; j < m->njnt; ++j) {   // positions and accelerations as the base-parameter samples
      double lo = -M_PI, hi = M_PI;
      if (m->jnt_limited[j]) lo = m->jnt_range[2 * j], hi = m->jnt_range[2 * j + 1];
      else if (m->jnt_type[j] == mjJNT_SLIDE) lo = -1, hi = 1;
      q[j] = d->qpos[m->jnt_qposadr[j]] = lo + (hi - lo) * 0.5 * (u(rng) + 1);
      // Speeds log-uniform over three decades up to 3: where friction acts as a constraint
      // the two differ near zero speed, which uniform speeds would rarely visit.
      qd[j] = d->qvel[m->jnt_dofadr[j]] = (u(rng) < 0 ? -3 : 3) * std::pow(10.0, -1.5 * (u(rng) + 1));
      qdd[j] = d->qacc[m->jnt_dofadr[j]] = 10 * u(rng);
    }
    mj_inverse(m, d.get());   // no plugin attached: their forces are added below, every one of them
    std::fill(plugin.begin(), plugin.end(), 0.0);
    effects_->compute(d.get(), plugin.data());
    const Eigen::VectorXd tau = evaluate(ws, q, qd, qdd) * pi_;
    for (int v = 0; v < nv; ++v) {
      const double truth = d->qfrc_inverse[v] - plugin[static_cast<size_t>(v)];
      worst[v] = std::max(worst[v], std::fabs(tau[v] - truth));
      sum_sq[v] += truth * truth;
    }
    constraint_kinds(m, d.get(), kinds);
  }
  std::vector<InverseMismatch> out;
  for (int j = 0; j < m->njnt; ++j) {
    const int v = m->jnt_dofadr[j];
    const double rms = std::sqrt(sum_sq[v] / std::max(states, 1));
    const double rel = rms > 0 ? worst[v] / rms : (worst[v] > 0 ? HUGE_VAL : 0.0);
    if (!(rel > kInverseTolerance)) continue;
    InverseMismatch mm{joints_[static_cast<size_t>(j)], rel, worst[v], rms, {}};
    for (const auto& inst : effects_->instances())
      if ((!inst.plugin().regressor || inst.plugin().advance) &&
          std::find(inst.decl.joints.begin(), inst.decl.joints.end(), mm.joint) != inst.decl.joints.end())
        mm.reasons.push_back("the declared plugin '" + inst.decl.instance + "' (" + inst.decl.type + ", " +
                             (inst.plugin().advance ? "stateful" : "not linear in its parameters") + ") has no regressor columns");
    mm.plugins_only = !mm.reasons.empty() && kinds[static_cast<size_t>(v)].empty();
    mm.reasons.insert(mm.reasons.end(), kinds[static_cast<size_t>(v)].begin(), kinds[static_cast<size_t>(v)].end());
    if (mm.reasons.empty()) mm.reasons.push_back("an element the regressor does not model (fluid forces, a nonlinear passive force?)");
    out.push_back(std::move(mm));
  }
  return out;
}

std::string inverse_mismatch_text(const InverseMismatch& mm) {
  std::string reasons;
  for (const auto& r : mm.reasons) reasons += (reasons.empty() ? "" : "; ") + r;
  return "joint '" + mm.joint + "': the regressor with the model's own values differs from MuJoCo's inverse dynamics by up to " +
         number_text(mm.worst, 3) + " (" + number_text(100 * mm.relative, 3) + " % of its RMS torque " + number_text(mm.rms, 3) +
         ") at seeded states: likely " + reasons + "; data simulated by MuJoCo from this model do not fit it exactly";
}

void warn_inverse_mismatches(const MjcfRegressor& reg, const std::string& file) {
  for (const auto& mm : reg.inverse_mismatches()) std::cerr << "spml: warning: " << file << ": " << inverse_mismatch_text(mm) << "\n";
}

}  // namespace spml
