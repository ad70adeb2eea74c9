// Base parameters of an MJCF regressor: which combinations of the standard parameters the
// joint torques determine, decided numerically as in Gautier, "Numerical calculation of the
// base inertial parameters of robots" (J. Robotic Systems 8(4), 1991; ICRA 1990): stack the
// regressor over random states, find its rank, keep the columns a pivoted QR picks first and
// express every other column through them. The regrouping this reproduces is the one
// Gautier & Khalil derive in closed form ("Direct calculation of minimum set of inertial
// parameters of serial robots", IEEE T-RA 1990); tests/test_mjcf_regressor.cc checks counts.
//
// What is specific here is the scaling and the tolerance. A column that is zero in exact
// arithmetic comes out of double precision as ~1e-17 noise, and a column that a rounded angle
// (URDF `rpy="1.5708"`) makes nonzero is ~1e-5 of its neighbours; scaling every column to unit
// norm (unit-free, but blind to size) turns both into independent directions and gives base
// values of 1e25. So columns keep their physical proportions instead (see column_scales) and
// the rank is decided on singular values with a tolerance above what rounding leaves.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "spml/envs/mjcf_regressor.h"
#include "spml/parse.h"

namespace spml {

Eigen::MatrixXd MjcfRegressor::Base::Y_base(const Eigen::MatrixXd& Y) const {
  Eigen::MatrixXd out(Y.rows(), rank);
  for (int i = 0; i < rank; ++i) out.col(i) = Y.col(independent[i]);
  return out;
}

double MjcfRegressor::Base::gap() const {
  return largest_dropped > 0 ? smallest_kept / largest_dropped : std::numeric_limits<double>::infinity();
}

bool MjcfRegressor::Base::close_call() const {
  return smallest_kept < kCloseCall * tolerance || largest_dropped * kCloseCall > tolerance;
}

// Random states in joint ranges (or +-pi / +-1 m), velocities and accelerations, stacked.
Eigen::MatrixXd MjcfRegressor::sample_regressor(int samples, std::uint64_t seed) const {
  const mjModel* m = m_.get();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int nv = m->nv;
  Eigen::MatrixXd W(static_cast<Eigen::Index>(samples) * nv, static_cast<Eigen::Index>(names_.size()));
  Eigen::VectorXd q(m->njnt), qd(m->njnt), qdd(m->njnt);
  Workspace ws = workspace();
  for (int s = 0; s < samples; ++s) {
    for (int j = 0; j < m->njnt; ++j) {
      double lo = -M_PI, hi = M_PI;
      if (m->jnt_limited[j]) lo = m->jnt_range[2 * j], hi = m->jnt_range[2 * j + 1];
      else if (m->jnt_type[j] == mjJNT_SLIDE) lo = -1, hi = 1;
      q[j] = lo + (hi - lo) * 0.5 * (u(rng) + 1);
      qd[j] = 3 * u(rng);
      qdd[j] = 10 * u(rng);
    }
    W.middleRows(static_cast<Eigen::Index>(s) * nv, nv) = evaluate(ws, q, qd, qdd);
  }
  return W;
}

// Column scales that make every column a torque of one common size per unit change of its
// parameter, so that the singular values compare like with like whatever the model's units:
// inertial columns of body b are multiplied by the size of a typical parameter of their kind,
// M for masses, M*L for first moments, M*L^2 for inertias (L = the reach of the model: the
// largest distance of a body origin or centre of mass from its tree's root at qpos0; the
// common factor M cancels). A change of length unit by s then scales every inertial column
// by s^2 alike (a mass column is a torque per mass, ~ L^2), so the rank does not depend on it. Their relative sizes stay physical, so a column that is
// rounding noise stays noise. The other columns (armature, damping, Coulomb, offsets, springs,
// plugins) are exact functions of the state with units of their own: each is scaled to the
// norm of the largest inertial column.
Eigen::VectorXd MjcfRegressor::column_scales(const Eigen::MatrixXd& W) const {
  const mjModel* m = m_.get();
  DataPtr d = make_data(m);
  mj_kinematics(m, d.get());
  double L = 0;
  for (int b = 1; b < m->nbody; ++b) {
    Eigen::Map<const Eigen::Vector3d> root(d->xpos + 3 * m->body_rootid[b]);
    L = std::max({L, (Eigen::Map<const Eigen::Vector3d>(d->xpos + 3 * b) - root).norm(),
                  (Eigen::Map<const Eigen::Vector3d>(d->xipos + 3 * b) - root).norm()});
  }
  if (!(L > 0)) L = 1;   // every body at its root: the mass and moment columns are zero anyway
  const Eigen::Index inertial = 10 * (m->nbody - 1);
  Eigen::VectorXd scale(W.cols());
  for (Eigen::Index c = 0; c < inertial; ++c) scale[c] = c % 10 == 0 ? 1.0 : (c % 10 < 4 ? L : L * L);
  const double reference = inertial > 0 ? (W.leftCols(inertial) * scale.head(inertial).asDiagonal()).colwise().norm().maxCoeff() : 1.0;
  for (Eigen::Index c = inertial; c < W.cols(); ++c) {
    const double n = W.col(c).norm();
    scale[c] = n > 0 && reference > 0 ? reference / n : 1.0;
  }
  return scale;
}

MjcfRegressor::Base MjcfRegressor::base_parameters(int samples, std::uint64_t seed) const {
  const Eigen::MatrixXd W = sample_regressor(samples, seed);
  const Eigen::VectorXd scale = column_scales(W);
  const Eigen::MatrixXd Ws = W * scale.asDiagonal();
  const int np = static_cast<int>(W.cols());
  Base base;
  base.tolerance = kRankTolerance;
  // Jacobi, not BDCSVD: Eigen 3.4.0's divide and conquer indexes out of range when it deflates
  // some clustered singular values (an assertion with asserts on, NaN without), and a written
  // extended.xml of a realistic draw (4 bodies, every column finite) had its rank read as 0.
  const Eigen::VectorXd sv = Eigen::JacobiSVD<Eigen::MatrixXd>(Ws).singularValues();
  base.singular_values = sv[0] > 0 ? Eigen::VectorXd(sv / sv[0]) : Eigen::VectorXd(sv);
  while (base.rank < base.singular_values.size() && base.singular_values[base.rank] > base.tolerance) ++base.rank;
  if (base.rank == 0) throw std::runtime_error("the regressor is zero in every sampled state: nothing to identify");
  base.smallest_kept = base.singular_values[base.rank - 1];
  base.largest_dropped = base.rank < base.singular_values.size() ? base.singular_values[base.rank] : 0.0;
  // Independent columns: the first `rank` pivots of a column-pivoted QR (Gautier 1991) on
  // unit-norm columns, so that the choice among the members of a group does not depend on
  // units; columns below the tolerance (rounding noise, or a rounded angle's trace) are zeroed
  // first and can only be dependent.
  // Ties (equal columns, e.g. the first joint's armature and its link's inertia about the
  // axis) go to the link's parameter, as in Gautier & Khalil's ZZR1: the other columns enter
  // at 0.99 of unit norm.
  Eigen::MatrixXd Wu = Ws;
  const Eigen::Index inertial = 10 * (m_->nbody - 1);
  for (Eigen::Index c = 0; c < Wu.cols(); ++c) {
    const double n = Wu.col(c).norm(), unit = c < inertial ? 1.0 : 0.99;
    Wu.col(c) = n > base.tolerance * sv[0] ? Eigen::VectorXd(Wu.col(c) * (unit / n)) : Eigen::VectorXd::Zero(Wu.rows());
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Wu);
  const auto& perm = qr.colsPermutation().indices();
  for (int i = 0; i < np; ++i) (i < base.rank ? base.independent : base.dependent).push_back(perm[i]);
  // Listed in the standard parameters' order (body by body, then joints), whatever the pivots'.
  std::sort(base.independent.begin(), base.independent.end());
  std::sort(base.dependent.begin(), base.dependent.end());
  group(base, Ws, scale);
  return base;
}

// The dependent columns as combinations of the independent ones, by least squares on the
// scaled columns (beta = pi[independent] + Kd pi[dependent]). Coefficients below 1e-8 in
// scaled units are rounding residue of exact zeros and are set to zero.
void MjcfRegressor::group(Base& base, const Eigen::MatrixXd& Ws, const Eigen::VectorXd& scale) const {
  const Eigen::Index r = base.rank, nd = static_cast<Eigen::Index>(base.dependent.size());
  Eigen::MatrixXd Wi(Ws.rows(), r), Wd(Ws.rows(), nd);
  for (Eigen::Index i = 0; i < r; ++i) Wi.col(i) = Ws.col(base.independent[static_cast<size_t>(i)]);
  for (Eigen::Index k = 0; k < nd; ++k) Wd.col(k) = Ws.col(base.dependent[static_cast<size_t>(k)]);
  const Eigen::MatrixXd K = Wi.colPivHouseholderQr().solve(Wd);
  base.Kd.resize(r, nd);
  base.model_values.resize(r);
  for (Eigen::Index i = 0; i < r; ++i) {
    const int ind = base.independent[static_cast<size_t>(i)];
    std::string name = names_[static_cast<size_t>(ind)];
    double value = pi_[ind];
    for (Eigen::Index k = 0; k < nd; ++k) {
      const int dep = base.dependent[static_cast<size_t>(k)];
      const double c = std::fabs(K(i, k)) < 1e-8 ? 0.0 : K(i, k) * scale[ind] / scale[dep];
      base.Kd(i, k) = c;
      if (std::fabs(K(i, k)) < base.tolerance) {   // kept in the value, below the decision's precision in the name
        value += c * pi_[dep];
        continue;
      }
      const std::string size = number_text(std::fabs(c), 4);
      name += (c > 0 ? " + " : " - ") + (size == "1" ? std::string() : size + "*") + names_[static_cast<size_t>(dep)];
      value += c * pi_[dep];
    }
    base.names.push_back(name);
    base.model_values[i] = value;
  }
}

std::string rank_decision_text(const MjcfRegressor::Base& base, size_t standard_parameters) {
  std::string s = "rank " + std::to_string(base.rank) + " of " + std::to_string(standard_parameters) +
                  ": smallest kept singular value " + number_text(base.smallest_kept, 4);
  if (base.largest_dropped > 0)
    s += ", largest dropped " + number_text(base.largest_dropped, 4) + " (ratio " + number_text(base.gap(), 4) + ")";
  else
    s += ", none dropped";
  return s + "; relative to the largest, tolerance " + number_text(base.tolerance, 4);
}

std::string rank_decision_warning(const MjcfRegressor::Base& base) {
  if (!base.close_call()) return "";
  return "the base-parameter rank is a close call: a singular value lies within a factor " +
         number_text(MjcfRegressor::kCloseCall, 4) + " of the tolerance " + number_text(base.tolerance, 4) +
         " (smallest kept " + number_text(base.smallest_kept, 4) + ", largest dropped " + number_text(base.largest_dropped, 4) +
         "): combinations that weak are barely determined by torques, and another rounding of the model's angles "
         "could change the rank (README, \"Base parameters\")";
}

}  // namespace spml
