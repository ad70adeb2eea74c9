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
  // A recorded low-pass the states went through as well: the most a second pass changes the
  // torques and the model's prediction alike on a joint (the square root of the inner product
  // of the two changes, relative to the torques' mean-free RMS), the most it changes the
  // prediction, and whether the smooth columns are left filtered once (prepare.cc,
  // weigh_second_pass; ParallelFilter's probe).
  double second_pass_change = 0, second_pass_model_change = 0;
  bool smooth_kept = false;
  // The dataset records that its ends kept the import's start-up transient (spml/1
  // `start_up_transient`): the model's columns keep the odd reflection there (filtering.cc).
  bool ends_transient = false;
  std::string description;    // for report.json: what was done and why
};

constexpr double kSecondPassChange = 0.05, kSecondPassShared = 0.2;

// The plan for a dataset: its recorded `filter` attribute (the torques already went through
// it: only the model's columns are filtered), else - when the accelerations hold noise above
// the band the positions excite, or the model's error does - a low-pass at five times that
// band on torques and columns. `qdd`, `q`: per joint, the fit split's columns; `residual`: per
// output, the fit split's torques minus the model as given; `rate_hz`: its sampling rate (0: none).
FilterPlan plan_filter(const Dataset& ds, const std::vector<Eigen::VectorXd>& q, const std::vector<Eigen::VectorXd>& qdd,
                       const std::vector<Eigen::VectorXd>& residual, double rate_hz, std::vector<std::string>& notes);

// K of the dataset's decimation record (1: none, or not understood).
double decimated_by(const Dataset& ds);

// Under a recorded low-pass, a column is filtered again when the power it holds above
// kSwitchingProbe times the cut-off is more than kSwitchingShare of what it holds above half
// that (filtering.cc, filter_stacked says why): a step's spectrum falls as 1/f^2 (about a third
// of its power above 1.5 fc lies above 3 fc), a smooth function of states that went through
// the low-pass falls with the filter's own slope (well under 1e-3).
constexpr double kSwitchingShare = 0.03;
constexpr double kSwitchingProbe = 3;

// One split's parallel filter: its sections and, when the states themselves went through the
// data's low-pass (a recorded filter), the probe low-pass that tells the columns that switch
// from those that are smooth functions of the filtered states (empty: every column filtered).
struct ParallelFilter {
  std::vector<Section> sections;
  std::vector<Section> probe, probe_half;   // low-passes at probe_hz and half of it
  double probe_hz = 0;
  // The model's own columns' segments are continued past their ends by linear prediction
  // before the pass, in place of the odd reflection: set where the torques are not filtered
  // again, no smooth column is left as it is (no probe), and the log's ends hold no start-up
  // transient of the import (filtering.cc, segment_pass, says why).
  bool predicted_ends = false;
  Eigen::Index settle = 0;   // the pass's settling (samples): how far the ends are continued
  bool empty() const { return sections.empty(); }
};

// The filter for one split (empty when the plan is none, the split has no time stamps, or
// the cut-off lies at or above 0.4 of its sampling rate: nothing left to filter).
ParallelFilter plan_sections(const FilterPlan& plan, const Split& s);

// The first rows of one output's records (`runs`: the first rows after the first), and N last.
std::vector<Eigen::Index> segment_bounds(Eigen::Index N, const std::vector<Eigen::Index>& runs);

// Filters the columns of a stacked matrix (rows o*N .. o*N+N-1 are output o) segment-wise;
// `runs` (first rows of the runs after the first, when several records are stacked) splits each
// output's rows further, so that no filter runs across the junction of two records. Where the
// filter has a probe, a column that does not switch (kSwitchingShare) is left as is.
// `model_columns`: A holds the model's own columns (its rigid-body and joint terms, its declared
// levels, or their prediction), whose ends are predicted where the filter says so; a
// candidate's columns keep the odd reflection (filtering.cc, segment_pass, says why).
void filter_stacked(const ParallelFilter& f, Eigen::MatrixXd& A, Eigen::Index N, const std::vector<Eigen::Index>& runs = {},
                    bool model_columns = false);
void filter_stacked(const ParallelFilter& f, Eigen::VectorXd& b, Eigen::Index N, const std::vector<Eigen::Index>& runs = {},
                    bool model_columns = false);

}  // namespace spml::diagnose_detail
