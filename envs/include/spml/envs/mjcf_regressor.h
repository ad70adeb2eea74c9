// The identification model of any MJCF tree of hinge/slide joints, derived numerically from
// MuJoCo's kinematics: tau = Y(q, qd, qdd) * pi with
//   per body  b: m, m*cx, m*cy, m*cz, Ixx, Iyy, Izz, Ixy, Ixz, Iyz   (inertia about the body
//                frame origin, in body coordinates)
//   per joint j: armature (qdd), damping (qd), Coulomb (sign qd), [offset (1) on request]
//   per tendon with stiffness/damping, per joint with stiffness: spring and damper terms
//   plus the regressor columns of every linear force plugin declared in the MJCF.
// Base parameters come from a rank decision on the singular values of the regressor stacked
// over many random states, with columns in physical proportion (envs/base_parameters.cc).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "spml/dataset.h"
#include "spml/envs/instruments.h"
#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"

namespace spml {

struct RegressorOptions {
  bool offsets = false;   // add a constant-torque column per joint
  // Coulomb (frictionloss) columns only for joints whose MJCF gives a frictionloss: diagnose
  // uses this so that dry friction the model leaves out is named as an effect, not a parameter.
  bool coulomb_only_where_modelled = false;
};

// The joint attribute a standard parameter sets: "damping:J2" -> {"J2", "damping"}, likewise
// armature and stiffness; a Coulomb level ("coulomb:J2") is MuJoCo's frictionloss. Empty for
// any other name (inertials, plugin parameters, base combinations). Whether the joint exists
// is the caller's to check. (These are the terms an identification keeps non-negative and
// writes as MJCF joint attributes.)
struct JointAttributeTerm {
  std::string joint, attribute;
};
std::optional<JointAttributeTerm> joint_attribute_term(const std::string& name);

// A joint where the regressor times the model's own values (plugins' included) differs from
// MuJoCo's inverse dynamics of the model (envs/regressor_check.cc).
struct InverseMismatch {
  std::string joint;
  double relative = 0;   // worst |Y pi - qfrc_inverse| over the states / RMS of qfrc_inverse
  double worst = 0, rms = 0;
  std::vector<std::string> reasons;   // the likely ones: unmodelled plugins, constraint kinds
  bool plugins_only = false;          // every reason is a declared plugin without regressor columns
};
// "joint 'j': ... differs ... by up to ... likely <reasons> ...", for a warning or a note.
std::string inverse_mismatch_text(const InverseMismatch& mismatch);
class MjcfRegressor;
// "spml: warning: <file>: <text>" on stderr for every mismatch of reg (identify, bench --model).
void warn_inverse_mismatches(const MjcfRegressor& reg, const std::string& file);

class MjcfRegressor {
 public:
  MjcfRegressor(const std::string& mjcf_file, const RegressorOptions& options = {});
  ~MjcfRegressor();

  const mjModel* model() const { return m_.get(); }
  int nv() const { return m_->nv; }
  const std::vector<std::string>& joint_names() const { return joints_; }
  // The model's declared force plugins (their linear parameters are standard parameters "plugin:...").
  const ForceEffects& effects() const { return *effects_; }

  // Standard parameters: names and the values of the loaded model (pi such that
  // Y * pi = mj_inverse of that model, plugins included).
  const std::vector<std::string>& param_names() const { return names_; }
  const Eigen::VectorXd& model_params() const { return pi_; }

  // The mutable half of an evaluation (MuJoCo's mjData), kept apart from the model as
  // MuJoCo and Pinocchio do: one workspace per thread, the regressor itself stays const.
  struct Workspace {
    DataPtr d;
  };
  Workspace workspace() const { return Workspace{make_data(m_.get())}; }

  // Y for one state: nv x num_params (q, qd, qdd indexed by joint).
  Eigen::MatrixXd evaluate(Workspace& ws, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                           const Eigen::VectorXd& qdd) const;

  struct Base {
    int rank = 0;
    // The rank decision: singular values of the scaled stacked regressor, relative to the
    // largest, descending; rank = how many exceed `tolerance`.
    double tolerance = 0;
    Eigen::VectorXd singular_values;
    double smallest_kept = 0;             // singular_values[rank - 1]
    double largest_dropped = 0;           // singular_values[rank], 0 when none is dropped
    double gap() const;                   // smallest_kept / largest_dropped (inf when none dropped)
    bool close_call() const;              // a singular value lies within kCloseCall of the tolerance
    std::vector<int> independent;         // indices into the standard parameters
    std::vector<int> dependent;
    Eigen::MatrixXd Kd;                   // beta = pi[independent] + Kd * pi[dependent]
    std::vector<std::string> names;       // readable grouping per base parameter
    Eigen::VectorXd model_values;         // beta of the loaded model (its prior)
    Eigen::MatrixXd Y_base(const Eigen::MatrixXd& Y) const;   // columns of Y kept as base
  };
  // Random states in joint ranges (or +-pi / +-1 m), velocities and accelerations; `samples`
  // states stacked. Deterministic for a given seed.
  Base base_parameters(int samples = 400, std::uint64_t seed = 1) const;

  // Y * model_params() against mj_inverse (qfrc_inverse; every declared plugin's force added,
  // stateful ones at their first state) at `states` seeded states (positions and accelerations
  // drawn as base_parameters draws them, speeds log-uniform in [3e-3, 3]); the joints where
  // they differ by more than kInverseTolerance of the joint's RMS torque.
  std::vector<InverseMismatch> inverse_mismatches(int states = 50, std::uint64_t seed = 1) const;
  // Where the regressor is exact the two agree to rounding: 1e-12 of the torque on the
  // project's models (tests: 1e-8 absolute on torques of 1-100). An element the regressor
  // leaves out shows at its own size, a frictionloss of 1 % of the torque as 1e-2. 1e-6 lies
  // six decades from either, and a mismatch below it is far below any sensor's noise.
  static constexpr double kInverseTolerance = 1e-6;

  // Relative singular values below this are dropped: rounding a model's angles to 4 decimals
  // (up to 5e-5 rad, as URDF files do) leaves singular values of about that size where exact
  // angles give zero; measured on the Kinova Gen3 (README, "Base parameters").
  static constexpr double kRankTolerance = 1e-4;
  // A decision is a close call when a kept or dropped singular value lies within this factor
  // of the tolerance: another rounding of the file or other samples could flip it.
  static constexpr double kCloseCall = 10;

 private:
  Eigen::MatrixXd sample_regressor(int samples, std::uint64_t seed) const;
  Eigen::VectorXd column_scales(const Eigen::MatrixXd& W) const;
  void group(Base& base, const Eigen::MatrixXd& Ws, const Eigen::VectorXd& scale) const;

  ModelPtr m_;
  std::unique_ptr<ForceEffects> effects_;
  RegressorOptions options_;
  std::vector<std::string> joints_, names_;
  Eigen::VectorXd pi_;
  std::vector<int> tendons_, stiff_joints_;
  std::vector<bool> coulomb_;   // per joint: has a Coulomb column
};

// The rank decision in words, for `regressor`, `identify` and `diagnose`: "rank 62 of 91:
// smallest kept singular value 0.089, largest dropped 1.4e-06 (ratio 6.2e+04, tolerance 1e-04)".
std::string rank_decision_text(const MjcfRegressor::Base& base, size_t standard_parameters);
// The warning to print when the decision is a close call, empty otherwise.
std::string rank_decision_warning(const MjcfRegressor::Base& base);

// Where the joints of an MJCF are in a split: X columns q:/qd:/qdd:<joint> for every joint,
// Y columns tau:<joint> (every Y column must name a model joint; joints without one are
// not scored). Throws DatasetError naming the split and the missing or unknown column.
struct JointColumns {
  std::vector<int> q, qd, qdd;     // per model joint: X column
  std::vector<int> output_dof;     // per Y column: the dof of its joint
  JointColumns(const MjcfRegressor& reg, const Split& s);
};

// The stacked base regressor (rows output-major: o * N + i, outputs = the Y columns `cols`
// was made for) of inputs X laid out like that split. Throws DatasetError naming the split
// (`where`) and row when a value makes it non-finite.
Eigen::MatrixXd stacked_base_regressor(const MjcfRegressor& reg, const MjcfRegressor::Base& base, const RowMatrix& X,
                                       const JointColumns& cols, const std::string& where);

// The split's torques stacked output-major (as the regressors above), refused when every one
// is zero: relative errors over them are undefined and there is nothing to identify.
// `source` (the dataset file, or "") prefixes the message.
Eigen::VectorXd stacked_torques(const Split& s, const std::string& source);

// Identification of base parameters on one split of a dataset whose X has q:/qd:/qdd:<joint>
// and whose Y has tau:<joint> for every joint of the model: least squares ("ls"), or
// instrumental variables ("iv", IDIM-IV: instruments.h), which stay unbiased when the
// regressor's inputs are noisy (accelerations differentiated from positions) where least
// squares shrinks the inertial parameters (errors in variables).
struct IdentifyOptions {
  std::string estimator = "ls";   // "ls" or "iv"
  std::string mjcf_path;          // iv: the model simulated for the instruments
  InstrumentOptions instruments;
};
struct Identification {
  std::string estimator;
  std::vector<std::string> names;
  Eigen::VectorXd estimate, std_error, prior;
  double sigma = 0;             // residual standard deviation
  double condition = 0;         // of the stacked base regressor
  struct SplitError { std::string split; Eigen::Index rows; double relative_error, rmse; };
  std::vector<SplitError> errors;   // first the identification split, then the others held out
  std::vector<std::string> joints;  // iv: the model's joints, and per joint the RMS of measured -
  std::vector<double> tracking_rms; //     simulated position along the instruments' simulation
  double tracking_hz = 0;           // iv: the tracking loop's bandwidth
};

Identification identify(const MjcfRegressor& reg, const MjcfRegressor::Base& base, const Dataset& ds,
                        const std::string& split, const IdentifyOptions& options = {});

}  // namespace spml
