// A Monte Carlo campaign (mirrorcal montecarlo): N simulated calibrations, each run's outcome as
// the campaign's statistics and report need it, and the runs made on threads. What each run
// calibrates (the rig, the stages, the options) is the caller's.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/plots.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/sim/scenario.hpp"

namespace mirrorcal::evaluation {

using calibration::CalibrationRun;
using calibration::DetectionReport;
using calibration::ParamInfo;

// montecarlo --batch: the batch solution of a run's data and prior: its error against the truth
// (SI), its sigmas (display units), NEES and CPU time, or why it could not be solved.
struct BatchOutcome {
  Eigen::VectorXd error;
  std::vector<double> sigma;
  double nees = 0.0, cpu_s = 0.0;
  bool converged = false;
  std::string failure;  // empty when solved
};

// One run of a campaign, as the statistics and reports need it.
struct RunOutcome {
  std::uint64_t seed = 0;
  std::vector<double> error, sigma;  // the calibration states', display units
  double nees = 0, wall_s = 0;
  std::uint64_t gated = 0, failures = 0;
  int passes = 0;  // passes over the data (more than the default after a bad one)
  double nis_per_dof = 0, sigma_ratio = 1, refinement_step = 0;
  // The ideal-IMU check's statistic over its bound (IdealImuCheck; 0 when not made): above 1,
  // the run said consistent: false for it.
  double imu_check = 0;
  bool suspect = false;        // convergence_warning() would warn a user of this run
  std::uint64_t screened = 0;  // reflections the loop's marker screen withheld, last pass
  ErrorSeries series;
  DetectionReport detection;     // --frames only
  sim::Scenario scenario;        // the run's rig (a family draws one per run)
  std::vector<double> limit;     // data_limit_sigmas(), display units (a family's stage 1 only)
  Eigen::VectorXd filter_error;  // error, SI (set beside the batch's)
  BatchOutcome batch;            // --batch only
};

// The outcome of run r, calibrated on rig from seed in wall_s seconds. with_data_limit (stage 1
// only: NK = 0) adds what the rig's data can hold, data_limit_sigmas(): one more filter, over
// noise-free data.
template <int M, int NK, int NI>
RunOutcome run_outcome(const CalibrationRun<M, NK, NI>& r, const sim::Scenario& rig,
                       std::uint64_t seed, double wall_s, bool with_data_limit) {
  RunOutcome oc;
  oc.seed = seed;
  oc.scenario = rig;
  oc.wall_s = wall_s;
  const auto& last = r.history.back();
  const std::vector<ParamInfo>& params = r.result.params;
  for (std::size_t j = 0; j < params.size(); ++j) {
    oc.error.push_back(last.error(int(j)) * params[j].scale);
    oc.sigma.push_back(last.sigma(int(j)) * params[j].scale);
  }
  oc.nees = last.nees;
  oc.filter_error = last.error.template cast<double>();
  oc.gated = r.filter_counters.markers_gated;
  oc.suspect = !calibration::convergence_warning(r.result).empty();
  for (const std::uint64_t n : r.result.markers_screened) oc.screened += n;
  oc.passes = r.result.passes;
  oc.nis_per_dof = r.result.nis_per_dof;
  oc.sigma_ratio = r.result.sigma_ratio;
  oc.refinement_step = r.result.refinement_step_sigmas;
  const calibration::IdealImuCheck& check = r.result.imu.ideal_check;
  oc.imu_check = check.made ? check.statistic / check.bound : 0.0;
  oc.failures = r.filter_counters.failures;
  oc.series = error_series(r.history, params);
  if constexpr (NK == 0) {  // stage 2's limit is not computed yet
    if (with_data_limit) {
      const std::vector<double> limit = data_limit_sigmas<M, NI>(rig, seed);
      for (std::size_t j = 0; j < limit.size(); ++j) oc.limit.push_back(limit[j] * params[j].scale);
    }
  }
  oc.detection = r.detection;
  return oc;
}

// The campaign's runs, one per element of out, on `jobs` threads: run(i, out[i]) makes run i, then
// progress(the fraction done) is called, one thread at a time. False, with the message, when a
// run's temporary store could not be written (io::StoreError: a full $TMPDIR): no more runs
// start.
bool run_campaign(std::vector<RunOutcome>& out, std::uint64_t jobs,
                  const std::function<void(std::uint64_t, RunOutcome&)>& run,
                  const std::function<void(double)>& progress, std::string& store_error);

}  // namespace mirrorcal::evaluation
