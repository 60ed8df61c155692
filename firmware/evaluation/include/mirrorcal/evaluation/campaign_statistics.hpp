// A Monte Carlo campaign's numbers, computed from its runs' outcomes: each parameter's error over
// the runs beside the paper's tables, the average NEES against its chi-square interval, a random
// family's statistics by parameter group and by each axis it draws, and the filter against the
// batch on the same runs. The campaign's report prints them (its tables, summary.csv, batch.csv).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "mirrorcal/evaluation/campaign.hpp"

namespace mirrorcal::evaluation {

// The largest |error| / sigma over a run's calibration states.
double worst_sigmas(const RunOutcome& run);

// Where the average NEES of `runs` runs of `states` states each lies with probability 1 - 2 tail
// (chi-square with runs * states degrees of freedom, over runs), and the verdict on one such
// average.
constexpr double kTail95 = 0.025, kTail99 = 0.005;
struct NeesInterval {
  double lo = 0.0, hi = 0.0;
  bool contains(double nees) const { return nees >= lo && nees <= hi; }
  const char* verdict(double nees) const {
    return contains(nees) ? "consistent" : "NOT consistent";
  }
};
NeesInterval average_nees_interval(double runs, std::size_t states, double tail);

// Each parameter's error over the runs (mean, variance, mean square) and reported variance
// (display units), and the average NEES of the calibration states with its 95 % interval.
struct ErrorStatistics {
  std::size_t runs = 0;
  std::vector<double> mean, var, mean_square, sigma_square;
  double nees = 0;
  NeesInterval nees95;
  std::size_t states() const { return mean.size(); }
};
// Over the first `states` errors of each run.
ErrorStatistics error_statistics(const std::vector<RunOutcome>& runs, std::size_t states);

// The runs that said consistent: true, and their average NEES (0 when none did).
struct TrustedNees {
  std::size_t runs = 0;
  double nees = 0.0;
};
TrustedNees trusted_nees(const std::vector<RunOutcome>& runs);

// The parameter groups a family's statistics are kept by (CalibrationGroup, the layout's), each
// in its display unit: p_b_c in cm, rotation in deg, markers in mm, the time offset in ms, and in
// stage 2 the camera's fu fv cu cv (skew) in px and the lens's coefficients in thousandths.
constexpr std::size_t kGroups = kCalibrationGroups;
const char* group_label(std::size_t group);  // "p_b_c [cm]" ...
// The groups a campaign on layout reports: stage 1's four, the camera's, and the lens's.
std::size_t reported_groups(const CalibrationLayout& layout);

// Statistics of some of a family's runs (errors in display units), by parameter group.
class GroupStatistics {
 public:
  using PerGroup = std::array<double, kGroups>;
  explicit GroupStatistics(const CalibrationLayout& layout) : layout_(layout) {}
  void add(const RunOutcome& run);

  std::size_t runs() const { return nees_.size(); }
  const std::vector<double>& nees() const { return nees_; }
  double mean_nees() const;
  double median_nees() const;
  int beyond() const { return beyond_; }    // runs with a state beyond 4 sigma
  int flagged() const { return flagged_; }  // runs that said consistent: false
  int missed() const { return missed_; }    // beyond 4 sigma, yet not flagged

  // RMS error and root-mean-square reported sigma (the markers in mm).
  PerGroup rms() const;
  PerGroup sigma() const;
  // The RMS error over the RMS of what the data can hold (data_limit_sigmas()): 1 is the limit.
  PerGroup over_limit(bool consistent_only) const;
  // How many runs the consistent runs' RMS over the limit rests on, in effect: it weighs each run
  // by its limit's variance, so a few weakly seen rigs can carry a group (the sum of the runs'
  // variances, squared, over the sum of their squares). Chance moves the ratio of a one-coordinate
  // group by about 1 / sqrt(2 n) (docs/campaign/random/README.md, "Over the whole family").
  PerGroup effective_runs() const;
  // The consistent runs' errors, each over its own run's limit, RMS: 1 is the limit, and a run
  // whose rig the data see poorly (large sigmas and errors) weighs no more than any other.
  PerGroup per_run_over_limit() const;

 private:
  CalibrationLayout layout_;  // the runs' calibration block
  std::vector<double> nees_;
  int beyond_ = 0, flagged_ = 0, missed_ = 0;
  PerGroup sq_{}, var_{}, lim_{}, count_{}, sq_ok_{}, lim_ok_{};  // _ok: consistent runs
  // Each consistent run's limit (its group's coordinates' variances summed), squared, summed.
  PerGroup run_lim_sq_ok_{};
  // Each consistent run's squared error over its own limit, summed, and how many.
  PerGroup per_run_ok_{}, count_ok_{};
};

// A slice of a family's runs by one axis the family draws: runs whose rig has() it.
struct FamilyGroup {
  std::string axis, value;
  std::function<bool(const sim::Scenario&)> has;
};
// The slices a family's report gives statistics for: all runs, then by mirror, motion, camera
// rate, pixel noise, IMU noise and marker prior, and with the camera's group (groups > 4) by the
// camera's prior.
std::vector<FamilyGroup> family_groups(std::size_t groups);

// A campaign's filter against the batch on the same runs (montecarlo --batch): each parameter
// group's RMS error of both over the runs, and the batch's own NEES.
class BatchComparison {
 public:
  explicit BatchComparison(const CalibrationLayout& layout) : layout_(layout) {}
  // One run's errors (calibration_params() order, SI) and the batch's NEES.
  void add(const Eigen::VectorXd& filter_error, const Eigen::VectorXd& batch_error,
           double batch_nees);
  std::size_t runs() const { return batch_nees_.size(); }
  // The group's RMS error of the filter and of the batch (SI), and the first over the second
  // (0 for a group the layout does not have).
  double filter_rms(CalibrationGroup g) const;
  double batch_rms(CalibrationGroup g) const;
  double ratio(CalibrationGroup g) const;
  double mean_batch_nees() const;
  int states() const { return layout_.size(); }

 private:
  static std::size_t index(CalibrationGroup g) { return static_cast<std::size_t>(g); }
  CalibrationLayout layout_;
  std::array<double, kCalibrationGroups> filter_sq_{}, batch_sq_{}, count_{};
  std::vector<double> batch_nees_;
};

// The detection of every run as one (--frames).
DetectionReport combined_detection(const std::vector<RunOutcome>& runs);

}  // namespace mirrorcal::evaluation
