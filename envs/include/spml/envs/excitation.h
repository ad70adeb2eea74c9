// Reference trajectories that excite a robot for identification: a multi-sine, a chirp, or a
// recorded trajectory from a file, kept inside each joint's range.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace spml {

struct ExcitationOptions {
  std::string kind = "multisine";   // "multisine", "chirp" or "file:PATH"
  double amplitude = 0.8;           // peak excursion [rad] (hinge) or amplitude/8 [m] (slide) without a range
  double f_low = 0.1, f_high = 1.0; // band [Hz] of the multi-sine components and of the chirp sweep
  std::uint64_t seed = 1;           // frequencies and phases
};

// Positions (rows: `times`, columns: the model's joints in order) of the reference, its
// velocity and acceleration by central differences (`times` evenly spaced). Every joint must be a hinge or a slide. A limited joint
// moves about the middle of its range within 80 % of its half range (and within `amplitude`),
// an unlimited one about qpos0. "file:PATH" reads a CSV with a time column "t" and one column
// "q:<joint>" per joint, linearly interpolated (held at the ends). Throws std::runtime_error
// naming the file, column or joint.
struct ReferenceTrack {
  Eigen::MatrixXd q, qd, qdd;
};
ReferenceTrack make_reference(const mjModel* m, const ExcitationOptions& options, const Eigen::VectorXd& times);

// The span [s] of a "file:PATH" reference (its last time stamp minus its first).
double reference_file_duration(const std::string& path);

// Names of the model's joints, in order (a joint without a name is an error naming its index).
std::vector<std::string> joint_names(const mjModel* m, const std::string& source);

}  // namespace spml
