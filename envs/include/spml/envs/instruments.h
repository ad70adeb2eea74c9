// Instruments for the instrumental-variable estimator (IDIM-IV; Janot, Vandanjon & Gautier,
// "A generic instrumental variable approach for industrial robot identification", IEEE TCST
// 2014): the regressor evaluated on states the model simulates along the measured motion,
// which follow the true motion but not the noise of positions differentiated twice.
//
// The paper drives the simulation with the robot's own reference and controller. A log holds
// neither, so here the model is driven by the measured torques, and a weak tracking loop
// (M(q) * (w^2 e + 2 w e'), e = measured - simulated position) keeps it on the measured path
// against drift and model error (the gap falls as 1/w^2). The simulated acceleration then carries the torque noise
// through M^-1 (a bias of the order of the squared relative torque noise, 1e-4 at 1 %), and
// the measured position noise only through the loop's low gain; the acceleration noise of
// differentiated positions, which grows with the sampling rate squared, not at all.
#pragma once

#include <string>
#include <vector>

#include "spml/dataset.h"

namespace spml {

struct InstrumentOptions {
  // Bandwidth of the tracking loop (critically damped) [Hz]; 0: the lowest of 1, 2, 4, ... Hz
  // (at most a tenth of the sampling rate) that keeps every joint's RMS gap within `max_gap`
  // of the joint's own RMS motion.
  double tracking_hz = 0;
  // 10 % where positions come raw (a tighter loop feeds their noise into the instruments); a
  // caller whose positions went through a low-pass may ask for 1 % (less model error in them).
  double max_gap = 0.1;
};

struct SimulatedTwin {
  Split split;                          // the input split, q:/qd:/qdd:<joint> replaced by simulated states
  std::vector<std::string> joints;      // the model's joints
  std::vector<double> rms_tracking;     // per joint: RMS of measured - simulated position
  int records = 0;                      // stretches simulated from their own first row
  double tracking_hz = 0;               // the bandwidth used
};

// Simulates the MJCF (contacts off, its force plugins attached) along split s, which needs
// time stamps and q:/qd:/qdd:<joint> for every joint; tau:<joint> columns drive it (joints
// without one get none). A record starts at every row in `runs` and wherever the time stamps
// jump by more than 5 median steps; each starts from its first row's measured state. Throws
// std::runtime_error naming the split and what is missing, or where the simulation diverged.
SimulatedTwin simulated_twin(const std::string& mjcf_path, const Split& s, const std::vector<Eigen::Index>& runs = {},
                             const InstrumentOptions& options = {});

}  // namespace spml
