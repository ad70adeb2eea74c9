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
  int windows = 0;
  double horizon = 0;                     // seconds
};

// Starts `windows` rollouts evenly spread over the split (which needs time stamps and
// q:/qd:/tau:<joint> columns), each `horizon` seconds long, with contacts off (inverse
// dynamics has none either) and the model's force plugins attached. Joints without a tau:
// column get no applied torque.
// `runs`: first rows of the records after the first (several --data): no window spans a junction.
RolloutResult rollout(const std::string& mjcf_path, const Split& s, int windows, double horizon, const std::vector<Eigen::Index>& runs = {});

}  // namespace spml::diagnose_detail
