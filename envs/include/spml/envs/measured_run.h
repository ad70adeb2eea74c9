// A measured run of any MJCF robot: forward simulation (mj_step, with the model's declared
// force plugins) under a joint controller tracking an excitation, recorded the way a real
// logger records it - encoder-quantized positions at a fixed rate with jittered sampling
// instants, the commanded joint torques with sensor noise, no velocities or accelerations.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "spml/dataset.h"
#include "spml/envs/excitation.h"
#include "spml/import.h"

namespace spml {

struct MeasurementOptions {
  double duration = 20;        // [s] of logged data
  double rate = 1000;          // logger and controller rate [Hz]
  std::string controller = "pd";   // "pd": PD tracking + the model's bias forces; "torque": open loop
  double bandwidth = 4;        // PD closed-loop bandwidth [Hz] (critically damped per joint)
  double torque_noise = 0.01;  // std of the torque noise as a fraction of each joint's RMS torque
  int encoder_bits = 18;       // counts per turn = 2^bits (hinge); per metre (slide); 0: exact
  double jitter = 0;           // std [s] of the sampling instants about k / rate (clipped to 0.45 / rate)
  std::uint64_t seed = 1;      // noise, jitter (the excitation has its own seed)
  ExcitationOptions excitation;
};

struct MeasuredRun {
  std::vector<std::string> joints;
  Eigen::VectorXd t;           // sampling instants (the time stamps) [s]
  Eigen::MatrixXd q, tau;      // measured: quantized positions, noisy torques (rows: samples)
  // What a perfect sensor would have read at the same instants, for tests and provenance.
  Eigen::MatrixXd q_true, tau_true;
  // The simulation's exact state at every controller tick (rows: ticks, time = k / rate):
  // qpos, qvel, the qacc MuJoCo computed for that step, and the torque applied over it.
  Eigen::MatrixXd tick_qpos, tick_qvel, tick_qacc, tick_tau;
  Eigen::VectorXd rms;         // RMS of tau_true per joint (the noise scale)
  double sim_timestep = 0;     // integration step used (divides 1 / rate)
  std::string plugins;         // the force plugins that acted, as declared
  std::string settings;        // the options, as words (provenance)
};

// Simulates `model_path` (hinge and slide joints only). The controller acts through
// qfrc_applied on every joint; the model's own actuators are disabled so the logged torque is
// all the actuation there is. Throws std::runtime_error / PluginError naming the file.
MeasuredRun simulate_measured(const std::string& model_path, const MeasurementOptions& options);

// The positions-only log as a table: t, q:<joint>..., tau:<joint>... (what `spml import` reads).
Table measured_table(const MeasuredRun& run, const std::string& source);
// spml/1 dataset of the run, one split "train". derive: qd:/qdd:<joint> by the import path's
// central differences (no filter), two rows dropped at each end; else positions only.
Dataset measured_dataset(const MeasuredRun& run, bool derive, const std::string& source);
// Writes the table as CSV (17 significant digits), atomically.
void write_measured_csv(const std::string& path, const MeasuredRun& run);

}  // namespace spml
