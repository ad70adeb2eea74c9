// Parallel filtering (Gautier 1997, "Dynamic identification of robots with power model"): the
// torques and every regressor column pass through the same zero-phase low-pass, so that a
// discontinuous force (Coulomb friction) is compared with its own filtered image instead of
// being read as a smooth curve (a fake Stribeck), and noise above the excitation band does not
// enter the accelerations (errors in variables).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "spml/dataset.h"
#include "spml/signal.h"

namespace spml::diagnose_detail {

using Section = Eigen::Matrix<double, 5, 1>;

// The widest low-pass worth running: at or above this share of the sampling rate a zero-phase
// Butterworth leaves next to nothing out (and spml import's anti-alias keeps just this much).
constexpr double kWidestLowpassShare = 0.4;

struct FilterPlan {
  enum class Source { none, recorded, detected } source = Source::none;
  LowpassRecord lowpass;
  bool torques = false;       // filter the torques too (they came unfiltered)
  // The accelerations are differences of noisy positions that no low-pass smoothed in the
  // band (the filter was detected; or the dataset says import derived them and records no
  // filter, or one at or above 0.4 of the rate it ran at - an anti-aliased decimation leaves
  // too little above the band to detect): what interpolates the columns (the delay search)
  // also averages their errors.
  bool raw_differences = false;
  std::string description;    // for report.json: what was done and why
};

// The plan for a dataset: its recorded `filter` attribute (the torques already went through
// it: only the model's columns are filtered), else - when the accelerations hold noise above
// the band the positions excite, or the model's error does - a low-pass at five times that
// band on torques and columns. `qdd`, `q`: per joint, the fit split's columns; `residual`: per
// output, the fit split's torques minus the model as given; `rate_hz`: its sampling rate (0: none).
FilterPlan plan_filter(const Dataset& ds, const std::vector<Eigen::VectorXd>& q, const std::vector<Eigen::VectorXd>& qdd,
                       const std::vector<Eigen::VectorXd>& residual, double rate_hz, std::vector<std::string>& notes);

// K of the dataset's decimation record (1: none, or not understood).
double decimated_by(const Dataset& ds);

// The sections for one split (empty when the plan is none, the split has no time stamps, or
// the cut-off lies at or above 0.4 of its sampling rate: nothing left to filter).
std::vector<Section> plan_sections(const FilterPlan& plan, const Split& s);

// Filters every column of a stacked matrix (rows o*N .. o*N+N-1 are output o) segment-wise;
// `runs` (first rows of the runs after the first, when several records are stacked) splits each
// output's rows further, so that no filter runs across the junction of two records.
void filter_stacked(const std::vector<Section>& sos, Eigen::MatrixXd& A, Eigen::Index N, const std::vector<Eigen::Index>& runs = {});
void filter_stacked(const std::vector<Section>& sos, Eigen::VectorXd& b, Eigen::Index N, const std::vector<Eigen::Index>& runs = {});

}  // namespace spml::diagnose_detail
