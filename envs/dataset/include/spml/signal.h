// Conditioning measured signals before identification: uniform resampling of uneven time
// stamps, a zero-phase Butterworth low-pass, central differences, edge trimming and
// decimation - what `spml import --lowpass/--derive/--drop-edges/--decimate` applies.
#pragma once

#include <Eigen/Core>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace spml {

// Second-order sections of a digital Butterworth low-pass (bilinear transform with
// pre-warping): `order` (even) poles, cut-off `cutoff_hz` at sampling rate `rate_hz`
// (0 < cutoff < rate / 2). Each section: b0 b1 b2 a1 a2 (a0 = 1), unity gain at DC.
std::vector<Eigen::Matrix<double, 5, 1>> butterworth_lowpass(int order, double cutoff_hz, double rate_hz);

// Forward-backward (zero-phase) filtering with the sections above; the signal is extended
// at both ends by odd reflection (3 * order samples, or `reflect` when >= 0; fewer for short
// signals) and every
// section starts in its steady state for the first sample, so the ends do not ring.
// The magnitude response is squared: -6 dB at the cut-off.
Eigen::VectorXd filtfilt(const std::vector<Eigen::Matrix<double, 5, 1>>& sos, const Eigen::VectorXd& x, Eigen::Index reflect = -1);

// Samples until the sections' impulse response stays below 1e-6 of its peak: how far into a
// log each end's start-up transient of filtfilt reaches (where the log ends while the signal
// moves), what `spml import --drop-edges` should drop.
Eigen::Index settling_samples(const std::vector<Eigen::Matrix<double, 5, 1>>& sos);

// Central differences (x[i+1] - x[i-1]) / (2 dt) inside, one-sided at the two ends: the one
// differentiation of the project (import --derive, generate --derive, the scenarios). Applied
// twice (NumPy's `gradient` recipe) it gives qd and qdd; unbiased for smooth signals, white
// position noise of std s becomes s*sqrt(6)/(4 dt^2) on qdd. Twice applied, the first and last
// two samples of qdd lean on one-sided steps: the scenario generators drop them.
Eigen::VectorXd central_difference(const Eigen::VectorXd& x, double dt);

// True when the steps of t differ from their median by more than 1 %.
bool uneven_steps(const Eigen::VectorXd& t);
double median_step(const Eigen::VectorXd& t);
// Linear interpolation of (t, x) at the times `at` (t increasing, at within [t0, tN]).
Eigen::VectorXd interpolate(const Eigen::VectorXd& t, const Eigen::VectorXd& x, const Eigen::VectorXd& at);

// The zero-phase low-pass a dataset went through, as recorded in its root attribute `filter`
// ("butterworth order=4 cutoff=15 zero-phase": order of one pass, cut-off in Hz).
struct LowpassRecord {
  int order = 4;
  double cutoff_hz = 0;
};
std::string lowpass_record_text(const LowpassRecord& f);
// nullopt when `text` is not such a record (a reader ignores what it does not know).
std::optional<LowpassRecord> parse_lowpass_record(const std::string& text);

// A decimation, as recorded in the root attribute `decimation`: every `keep`-th row kept,
// after an anti-alias low-pass ("keep=5 after butterworth order=8 cutoff=80 zero-phase") or
// without one ("keep=5 plain").
struct DecimationRecord {
  int keep = 1;
  std::optional<LowpassRecord> anti_alias;
};
std::string decimation_record_text(const DecimationRecord& d);
std::optional<DecimationRecord> parse_decimation_record(const std::string& text);

// The step of a quantized position log (an encoder's count) from its raw samples: every
// change between samples is a whole multiple of the smallest one (within 1 % of it, for 99.9 %
// of the changes). nullopt where the log is not so (continuous values) or changes fewer than
// 20 times.
std::optional<double> quantization_step(const Eigen::VectorXd& x);

// The record of the position columns' steps, root attribute `position_steps`
// ("q:J1=0.00153398 q:J2=3.8147e-06"; what spml import found in the raw log).
std::string position_steps_text(const std::map<std::string, double>& steps);
// Empty where the text is not such a record (a reader ignores what it does not know).
std::map<std::string, double> parse_position_steps(const std::string& text);

// What spml import's --lowpass/--derive/--decimate make of one raw position log sampled at
// `rate_hz`: the zero-phase `lowpass` (none: raw differences), two central differences, the
// decimation's anti-alias pass on all three, every keep-th sample (import.cc's condition() on
// one column, no edges dropped). A `velocity` or `acceleration` given (raw, same rate) stands
// for that state as the import was given it: low-passed in place of the difference, and the
// acceleration then differenced from the given velocity. For a consumer that needs the chain's
// effect on a position error (diagnose's resolution floor) or on a known motion (diagnose's
// chain bias), not for importing.
struct DerivedSignals {
  Eigen::VectorXd q, qd, qdd;
};
DerivedSignals derive_like_import(const Eigen::VectorXd& raw, double rate_hz, const std::optional<LowpassRecord>& lowpass, const DecimationRecord& decimation,
                                  const Eigen::VectorXd* velocity = nullptr, const Eigen::VectorXd* acceleration = nullptr);
// The same chain without differences, for a column the import does not differentiate (a torque).
Eigen::VectorXd condition_like_import(const Eigen::VectorXd& raw, double rate_hz, const std::optional<LowpassRecord>& lowpass, const DecimationRecord& decimation);

}  // namespace spml
