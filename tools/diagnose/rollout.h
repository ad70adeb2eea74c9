// Short open-loop rollouts of a model from measured states under the measured torques: how far
// the simulated positions drift from the measured ones in a fixed horizon.
#pragma once

#include <string>
#include <vector>

#include "spml/dataset.h"

namespace spml::diagnose_detail {

struct RolloutResult {
  std::vector<std::string> joints;        // the model's joints
  std::vector<double> position_error;     // per joint: mean |q_sim - q_measured| at the horizon
  std::vector<std::vector<double>> window_error;   // per window, per joint: |q_sim - q_measured|
  std::vector<double> window_start;       // per window: the time stamp it starts at (s)
  int windows = 0;
  double horizon = 0;                     // seconds
};

// One window's trajectory, a sample per simulation step from its start to its horizon: the
// measured positions (linearly interpolated at the step's time, as for the end error) and the
// simulated ones. The last sample's |simulated - measured| is the window's end error.
struct RolloutTrace {
  int window = 0;
  std::vector<double> t;                                   // per sample: time stamp (s)
  std::vector<std::vector<double>> measured, simulated;    // per sample, per joint
};

// Starts `windows` rollouts evenly spread over the split (which needs time stamps and
// q:/qd:/tau:<joint> columns), each `horizon` seconds long, with contacts off (inverse
// dynamics has none either) and the model's force plugins attached. Joints without a tau:
// column get no applied torque.
// `runs`: first rows of the records after the first (several --data): no window spans a junction.
RolloutResult rollout(const std::string& mjcf_path, const Split& s, int windows, double horizon, const std::vector<Eigen::Index>& runs = {});

// The trajectories of the windows `which` (indices among the `windows` rollout() starts with the
// same arguments), simulated as rollout() does.
std::vector<RolloutTrace> rollout_traces(const std::string& mjcf_path, const Split& s, int windows, double horizon,
                                         const std::vector<Eigen::Index>& runs, const std::vector<int>& which);

// Per joint: does `after` end farther from the measured positions than `before`, on mean over
// the windows (or not finite)? The joints report.json lists in rollout.worse_on, and those the
// confirmation in simulation tries to mend (confirm.cc).
std::vector<bool> worse_joints(const RolloutResult& before, const RolloutResult& after);

// The confirmation's verdict on one cause (confirm.cc): does the model `without` it roll out
// better than the model `with` it? Yes when it does on the `worse` joints and over all joints
// (each relative to `before`, the model as given), or, where one of `own` (the cause's joints)
// is among the worse, on the worse joints and over its own joints together. *own_rule says
// whether the second clause decided. A `nearest` candidate (its joints keep structure that a GP
// over the states predicts, unexplained.cc) goes when the worse joints roll out better without it.
bool better_without_cause(const RolloutResult& before, const RolloutResult& with, const RolloutResult& without,
                          const std::vector<bool>& worse, const std::vector<bool>& own, bool nearest, bool* own_rule = nullptr);

// Up to three windows worth drawing: the one with the largest end error (each joint's error
// relative to its mean over the windows: joints differ in units), the median one and the smallest.
std::vector<int> windows_to_trace(const RolloutResult& r);

// rollouts.csv: window,t and per joint q:<joint> (measured), given:<joint> and extended:<joint>
// (simulated by each model); `given` and `extended` trace the same windows.
std::string rollout_csv(const std::vector<std::string>& joints, const std::vector<RolloutTrace>& given,
                        const std::vector<RolloutTrace>& extended);

}  // namespace spml::diagnose_detail
