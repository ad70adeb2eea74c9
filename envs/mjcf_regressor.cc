#include "spml/envs/mjcf_regressor.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

#include "spml/parse.h"

namespace spml {

std::optional<JointAttributeTerm> joint_attribute_term(const std::string& name) {
  const auto colon = name.find(':');
  if (colon == std::string::npos) return std::nullopt;
  const std::string kind = name.substr(0, colon);
  if (kind != "armature" && kind != "damping" && kind != "coulomb" && kind != "stiffness") return std::nullopt;
  return JointAttributeTerm{name.substr(colon + 1), kind == "coulomb" ? "frictionloss" : kind};
}
namespace {

// Newton-Euler wrench of one body, in its frame, as a 6 x 10 matrix acting on
// (m, hx, hy, hz, Ixx, Iyy, Izz, Ixy, Ixz, Iyz): rows 0-2 force, rows 3-5 moment about the
// origin. w = angular velocity, dw = angular acceleration, a = classical acceleration of the
// origin with gravity folded in (a - g).
Eigen::Matrix<double, 6, 10> body_wrench(const Eigen::Vector3d& w, const Eigen::Vector3d& dw, const Eigen::Vector3d& a) {
  auto skew = [](const Eigen::Vector3d& v) {
    Eigen::Matrix3d S;
    S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
    return S;
  };
  // I * x for symmetric I written as a linear map of the 6 inertia entries.
  auto inertia_map = [](const Eigen::Vector3d& x) {
    Eigen::Matrix<double, 3, 6> L;
    L << x.x(), 0, 0, x.y(), x.z(), 0,
         0, x.y(), 0, x.x(), 0, x.z(),
         0, 0, x.z(), 0, x.x(), x.y();
    return L;
  };
  Eigen::Matrix<double, 6, 10> A = Eigen::Matrix<double, 6, 10>::Zero();
  Eigen::Matrix3d W = skew(w);
  A.block<3, 1>(0, 0) = a;                                   // m a
  A.block<3, 3>(0, 1) = skew(dw) + W * W;                    // dw x h + w x (w x h)
  A.block<3, 3>(3, 1) = -skew(a);                            // h x a = -a x h
  A.block<3, 6>(3, 4) = inertia_map(dw) + W * inertia_map(w);   // I dw + w x (I w)
  return A;
}

// Joint j's name, or an error naming its index, type and body: the regressor takes hinge and
// slide joints, and names parameters and data columns (q:<joint>) after them.
std::string checked_joint_name(const mjModel* m, int j, const std::string& file) {
  const int type = m->jnt_type[j];
  const char* name = mj_id2name(m, mjOBJ_JOINT, j);
  const std::string which = joint_description(m, j);
  if (type != mjJNT_HINGE && type != mjJNT_SLIDE)
    throw std::runtime_error(file + ": " + which + ": the regressor supports hinge and slide joints only (a free or ball "
                                                   "joint has no single-axis torque to identify)");
  if (!name || !*name)
    throw std::runtime_error(file + ": " + which + " has no name: parameters and data columns (q:<joint>, tau:<joint>) are "
                                                   "named after joints; give it name=\"...\"");
  return name;
}

}  // namespace

MjcfRegressor::MjcfRegressor(const std::string& mjcf_file, const RegressorOptions& options)
    : m_(load_mjcf(mjcf_file)), options_(options) {
  const mjModel* m = m_.get();
  if (m->njnt == 0)
    throw std::runtime_error(mjcf_file + ": the model has no joints, so there is nothing to identify (a regressor "
                                         "needs at least one hinge or slide joint)");
  for (int j = 0; j < m->njnt; ++j) joints_.push_back(checked_joint_name(m, j, mjcf_file));
  effects_ = std::make_unique<ForceEffects>(m, mjcf_file);
  std::vector<double> values;
  static const char* kBody[10] = {"m", "mx", "my", "mz", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz"};
  for (int b = 1; b < m->nbody; ++b) {
    // An unnamed body is called body#<id>: '#' keeps it apart from a body named "body3".
    const char* bn = mj_id2name(m, mjOBJ_BODY, b);
    std::string body = bn ? bn : "body#" + std::to_string(b);
    if (!bn && mj_name2id(m, mjOBJ_BODY, body.c_str()) >= 0)
      throw std::runtime_error(mjcf_file + ": body " + std::to_string(b) + " has no name and another body is named '" + body +
                               "': name body " + std::to_string(b));
    // Inertia about the body origin in body coordinates from MuJoCo's (mass, ipos, iquat, diag).
    double mass = m->body_mass[b];
    Eigen::Vector3d c(m->body_ipos + 3 * b);
    double mat[9];
    mju_quat2Mat(mat, m->body_iquat + 4 * b);
    Eigen::Matrix3d R = Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(mat);
    Eigen::Matrix3d I = R * Eigen::Vector3d(m->body_inertia + 3 * b).asDiagonal() * R.transpose() +
                        mass * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
    double v[10] = {mass, mass * c.x(), mass * c.y(), mass * c.z(), I(0, 0), I(1, 1), I(2, 2), I(0, 1), I(0, 2), I(1, 2)};
    for (int k = 0; k < 10; ++k) {
      names_.push_back(std::string(kBody[k]) + ":" + body);
      values.push_back(v[k]);
    }
  }
  for (int j = 0; j < m->njnt; ++j) {
    int dof = m->jnt_dofadr[j];
    names_.push_back("armature:" + joints_[j]); values.push_back(m->dof_armature[dof]);
    names_.push_back("damping:" + joints_[j]);  values.push_back(m->dof_damping[dof]);
    coulomb_.push_back(!options_.coulomb_only_where_modelled || m->dof_frictionloss[dof] != 0);
    if (coulomb_.back()) { names_.push_back("coulomb:" + joints_[j]);  values.push_back(m->dof_frictionloss[dof]); }
    if (options_.offsets) { names_.push_back("offset:" + joints_[j]); values.push_back(0.0); }
  }
  for (int j = 0; j < m->njnt; ++j)
    if (m->jnt_stiffness[j] != 0) {
      stiff_joints_.push_back(j);
      names_.push_back("stiffness:" + joints_[j]);
      values.push_back(m->jnt_stiffness[j]);
    }
  for (int t = 0; t < m->ntendon; ++t)
    if (m->tendon_stiffness[t] != 0 || m->tendon_damping[t] != 0) {
      const char* tn = mj_id2name(m, mjOBJ_TENDON, t);
      std::string name = tn ? tn : "tendon" + std::to_string(t);
      tendons_.push_back(t);
      names_.push_back("stiffness:" + name); values.push_back(m->tendon_stiffness[t]);
      names_.push_back("damping:" + name);   values.push_back(m->tendon_damping[t]);
    }
  // Plugins whose force is linear in their parameters: tau_inverse = ... - R * theta.
  for (const auto& n : effects_->linear_names()) names_.push_back("plugin:" + n);
  const Eigen::VectorXd theta = effects_->linear_params();
  values.insert(values.end(), theta.data(), theta.data() + theta.size());
  pi_ = Eigen::Map<Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size()));
}

MjcfRegressor::~MjcfRegressor() = default;

Eigen::MatrixXd MjcfRegressor::evaluate(Workspace& ws, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                        const Eigen::VectorXd& qdd) const {
  const mjModel* m = m_.get();
  mjData* d = ws.d.get();
  const int nv = m->nv;
  for (int j = 0; j < m->njnt; ++j) {
    d->qpos[m->jnt_qposadr[j]] = q[j];
    d->qvel[m->jnt_dofadr[j]] = qd[j];
    d->qacc[m->jnt_dofadr[j]] = qdd[j];
  }
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_tendon(m, d);
  mj_transmission(m, d);
  mj_comVel(m, d);   // cvel and cdof_dot
  Eigen::MatrixXd Y = Eigen::MatrixXd::Zero(nv, static_cast<Eigen::Index>(names_.size()));
  Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor> jp(3, nv), jr(3, nv);
  for (int b = 1; b < m->nbody; ++b) {
    // Spatial acceleration, com-based (at the root's subtree centre of mass, world axes):
    // sum over the dofs supporting b of cdof*qacc + cdof_dot*qvel. (mj_objectAcceleration in
    // 2.2.2 gave wrong linear terms here, so the sum is formed directly.)
    Eigen::Matrix<double, 6, 1> sacc = Eigen::Matrix<double, 6, 1>::Zero();
    int dof = -1;
    for (int bb = b; bb > 0 && dof < 0; bb = m->body_parentid[bb])
      if (m->body_dofnum[bb]) dof = m->body_dofadr[bb] + m->body_dofnum[bb] - 1;
    for (; dof >= 0; dof = m->dof_parentid[dof])
      sacc += Eigen::Map<const Eigen::Matrix<double, 6, 1>>(d->cdof + 6 * dof) * d->qacc[dof] +
              Eigen::Map<const Eigen::Matrix<double, 6, 1>>(d->cdof_dot + 6 * dof) * d->qvel[dof];
    Eigen::Map<const Eigen::Vector3d> com(d->subtree_com + 3 * m->body_rootid[b]), origin(d->xpos + 3 * b);
    Eigen::Map<const Eigen::Matrix<double, 6, 1>> cvel(d->cvel + 6 * b);
    const Eigen::Vector3d r = origin - com, w = cvel.head<3>(), dw = sacc.head<3>();
    const Eigen::Vector3d v = cvel.tail<3>() + w.cross(r);
    // Classical acceleration of the body origin, with gravity as a base acceleration.
    const Eigen::Vector3d a = sacc.tail<3>() + dw.cross(r) + w.cross(v) - Eigen::Vector3d(m->opt.gravity);
    Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> R(d->xmat + 9 * b);   // body -> world
    auto A = body_wrench(R.transpose() * w, R.transpose() * dw, R.transpose() * a);
    mj_jacBody(m, d, jp.data(), jr.data(), b);
    // tau += J^T (R f, R n): world-frame Jacobians of the body origin.
    Y.middleCols(10 * (b - 1), 10) += jp.transpose() * (R * A.topRows<3>()) + jr.transpose() * (R * A.bottomRows<3>());
  }
  int col = 10 * (m->nbody - 1);
  for (int j = 0; j < m->njnt; ++j) {
    int dof = m->jnt_dofadr[j];
    Y(dof, col++) = qdd[j];
    Y(dof, col++) = qd[j];
    if (coulomb_[j]) Y(dof, col++) = qd[j] > 0 ? 1.0 : (qd[j] < 0 ? -1.0 : 0.0);
    if (options_.offsets) Y(dof, col++) = 1.0;
  }
  for (int j : stiff_joints_) Y(m->jnt_dofadr[j], col++) = q[j] - m->qpos_spring[m->jnt_qposadr[j]];
  for (int t : tendons_) {
    Eigen::Map<const Eigen::VectorXd> J(d->ten_J + t * nv, nv);   // dense in 2.2.2
    double len = d->ten_length[t], rate = J.dot(Eigen::Map<const Eigen::VectorXd>(d->qvel, nv));
    Y.col(col++) = J * (len - m->tendon_lengthspring[t]);
    Y.col(col++) = J * rate;
  }
  if (col < Y.cols()) Y.rightCols(Y.cols() - col) = -effects_->linear_regressor(d->qpos, d->qvel);
  return Y;
}

JointColumns::JointColumns(const MjcfRegressor& reg, const Split& s) {
  for (const auto& j : reg.joint_names()) {
    for (auto [prefix, vec] : {std::pair<const char*, std::vector<int>*>{"q:", &q}, {"qd:", &qd}, {"qdd:", &qdd}}) {
      const int c = s.x_index(prefix + j);
      if (c < 0) throw DatasetError("split '" + s.name + "': no input column '" + prefix + j + "' for model joint '" + j + "'");
      vec->push_back(c);
    }
  }
  for (const auto& col : s.y_columns) {
    const auto& names = reg.joint_names();
    const auto it = col.rfind("tau:", 0) == 0 ? std::find(names.begin(), names.end(), col.substr(4)) : names.end();
    if (it == names.end())
      throw DatasetError("split '" + s.name + "': target column '" + col + "' is not tau:<joint> of a model joint");
    output_dof.push_back(reg.model()->jnt_dofadr[it - names.begin()]);
  }
}

Eigen::MatrixXd stacked_base_regressor(const MjcfRegressor& reg, const MjcfRegressor::Base& base, const RowMatrix& X,
                                       const JointColumns& cols, const std::string& where) {
  const Eigen::Index N = X.rows();
  const auto O = static_cast<Eigen::Index>(cols.output_dof.size());
  const auto J = cols.q.size();
  Eigen::MatrixXd A(N * O, base.rank);
  Eigen::VectorXd q(J), qd(J), qdd(J);
  auto ws = reg.workspace();
  for (Eigen::Index r = 0; r < N; ++r) {
    for (size_t j = 0; j < J; ++j) {
      q[j] = X(r, cols.q[j]);
      qd[j] = X(r, cols.qd[j]);
      qdd[j] = X(r, cols.qdd[j]);
    }
    const Eigen::MatrixXd Y = base.Y_base(reg.evaluate(ws, q, qd, qdd));
    if (!Y.allFinite())
      throw DatasetError("split '" + where + "' row " + std::to_string(r) +
                         ": the regressor is not finite there (a value too large for the model's dynamics?)");
    for (Eigen::Index o = 0; o < O; ++o) A.row(o * N + r) = Y.row(cols.output_dof[static_cast<size_t>(o)]);
  }
  return A;
}

Eigen::VectorXd stacked_torques(const Split& s, const std::string& source) {
  if (s.Y.size() > 0 && s.Y.cwiseAbs().maxCoeff() == 0)
    throw DatasetError((source.empty() ? "" : source + ": ") + "split '" + s.name +
                       "': every torque is zero: there is nothing to identify (a sensor not read?)");
  return stacked_targets(s.Y);
}

namespace {

// The stacked base regressor and torques of one split, errors naming the dataset file.
void stack_split(const MjcfRegressor& reg, const MjcfRegressor::Base& base, const Dataset& ds, const Split& s, Eigen::MatrixXd& A,
                 Eigen::VectorXd& b) {
  try {
    const JointColumns cols(reg, s);
    A = stacked_base_regressor(reg, base, s.X, cols, s.name);
  } catch (const DatasetError& e) {
    throw DatasetError((ds.source.empty() ? "" : ds.source + ": ") + e.what());
  }
  b = stacked_torques(s, ds.source);
}

// Refuses data that do not excite every base parameter, naming the parameters the data
// leave free (the largest entries of the weakest direction). Returns the condition number.
double check_excitation(const Eigen::JacobiSVD<Eigen::MatrixXd>& svd, const std::vector<std::string>& names, const std::string& where) {
  const auto& sv = svd.singularValues();
  const double condition = sv[0] > 0 ? sv[0] / sv[sv.size() - 1] : std::numeric_limits<double>::infinity();
  if (condition < 1e10) return condition;
  const Eigen::VectorXd v = svd.matrixV().col(sv.size() - 1);
  std::vector<std::pair<double, int>> w;
  for (int i = 0; i < v.size(); ++i) w.emplace_back(-std::fabs(v[i]), i);
  std::sort(w.begin(), w.end());
  std::string free;
  for (size_t i = 0; i < w.size() && i < 3 && -w[i].first > 0.1; ++i) free += (free.empty() ? "" : "; ") + names[static_cast<size_t>(w[i].second)];
  throw DatasetError(where + ": the data do not excite every base parameter (condition number " + number_text(condition, 4) +
                     "): not identifiable from this data: " + free + " (does every joint move, with varying speed and acceleration?)");
}

}  // namespace

Identification identify(const MjcfRegressor& reg, const MjcfRegressor::Base& base, const Dataset& ds, const std::string& split,
                        const IdentifyOptions& options) {
  Identification out;
  out.names = base.names;
  out.prior = base.model_values;
  out.estimator = options.estimator;
  Eigen::MatrixXd A;
  Eigen::VectorXd b;
  const Split& train = ds.get(split);
  stack_split(reg, base, ds, train, A, b);
  const std::string where = (ds.source.empty() ? "" : ds.source + ": ") + "split '" + split + "'";
  if (A.rows() <= A.cols())
    throw DatasetError(where + ": " + std::to_string(A.rows()) + " equations (" + std::to_string(train.rows()) +
                       " rows x " + std::to_string(train.Y.cols()) + " torques) for " + std::to_string(A.cols()) +
                       " base parameters: too few rows to identify them and estimate the noise");
  // Columns scaled to unit norm, so that the rank decision does not depend on units.
  Eigen::VectorXd scale = A.colwise().norm().transpose();
  for (Eigen::Index c = 0; c < A.cols(); ++c) scale[c] = scale[c] > 0 ? scale[c] : 1.0;
  const Eigen::MatrixXd As = A * scale.cwiseInverse().asDiagonal();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(As, Eigen::ComputeThinU | Eigen::ComputeThinV);
  out.condition = check_excitation(svd, out.names, where);
  const double dof = static_cast<double>(A.rows() - A.cols());
  if (options.estimator == "iv") {
    // IDIM-IV: theta = (Z^T A)^-1 Z^T b, Z the regressor on the simulated states (instruments.h);
    // covariance sigma^2 (Z^T A)^-1 Z^T Z (A^T Z)^-1.
    if (options.mjcf_path.empty()) throw std::invalid_argument("identify: the IV estimator needs the MJCF's path to simulate");
    SimulatedTwin twin;
    try {
      InstrumentOptions io = options.instruments;
      if (ds.provenance.count("filter")) io.max_gap = std::min(io.max_gap, 0.01);   // low-passed positions (instruments.h)
      twin = simulated_twin(options.mjcf_path, train, {}, io);
    } catch (const std::runtime_error& e) {
      const std::string what = e.what(), own = "split '" + split + "'";   // names the split itself when it is the split's fault
      throw DatasetError(what.rfind(own, 0) == 0 ? where + what.substr(own.size()) : where + ": " + what);
    }
    Eigen::MatrixXd Z;
    Eigen::VectorXd unused;
    stack_split(reg, base, ds, twin.split, Z, unused);
    const Eigen::MatrixXd Zs = Z * scale.cwiseInverse().asDiagonal();
    const Eigen::MatrixXd ZA = Zs.transpose() * As;
    const Eigen::FullPivLU<Eigen::MatrixXd> lu(ZA);
    if (!lu.isInvertible())
      throw DatasetError(where + ": the instruments (the model simulated along the data) do not span the base parameters: use --estimator ls");
    const Eigen::VectorXd theta_s = lu.solve(Zs.transpose() * b);
    out.estimate = scale.cwiseInverse().asDiagonal() * theta_s;
    out.sigma = std::sqrt((b - A * out.estimate).squaredNorm() / dof);
    const Eigen::MatrixXd P = lu.solve(Eigen::MatrixXd(Zs.transpose()));   // (Z^T A)^-1 Z^T
    const Eigen::MatrixXd cov = scale.cwiseInverse().asDiagonal() * (P * P.transpose()) * scale.cwiseInverse().asDiagonal();
    out.std_error = (out.sigma * out.sigma * cov.diagonal()).cwiseSqrt();
    out.tracking_rms = twin.rms_tracking;
    out.tracking_hz = twin.tracking_hz;
    out.joints = twin.joints;
  } else {
    out.estimate = scale.cwiseInverse().asDiagonal() * svd.solve(b);
    out.sigma = std::sqrt((b - A * out.estimate).squaredNorm() / dof);
    // (A^T A)^-1 = D^-1 V S^-2 V^T D^-1 with D the column scales.
    const auto& sv = svd.singularValues();
    const Eigen::MatrixXd Vs = scale.cwiseInverse().asDiagonal() * svd.matrixV();
    Eigen::MatrixXd cov = Vs * sv.cwiseInverse().cwiseAbs2().asDiagonal() * Vs.transpose();
    out.std_error = (out.sigma * out.sigma * cov.diagonal()).cwiseSqrt();
  }
  auto score = [&](const Split& s, const Eigen::MatrixXd& As_, const Eigen::VectorXd& bs) {
    Eigen::VectorXd r = bs - As_ * out.estimate;
    out.errors.push_back({s.name, s.rows(), r.norm() / bs.norm(), std::sqrt(r.squaredNorm() / static_cast<double>(bs.size()))});
  };
  score(train, A, b);
  for (const Split& s : ds.splits) {
    if (s.name == split) continue;
    Eigen::MatrixXd As2;
    Eigen::VectorXd bs;
    stack_split(reg, base, ds, s, As2, bs);
    score(s, As2, bs);
  }
  return out;
}

}  // namespace spml
