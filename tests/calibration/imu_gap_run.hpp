// A simulated calibration with the IMU silent for a while, as `mirrorcal calibrate` makes it of a
// recording whose IMU rows of that stretch are missing: imu_gap_tests, and imu_gap_survey for the
// README's figures over more rigs.
#pragma once

#include <algorithm>
#include <cstdint>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mirrorcal::gaptest {

using Run = calibration::CalibrationRun<3, 0>;

constexpr std::int64_t kMs = 1'000'000;

// The calibration of seed's simulated minute with the IMU samples of [start_ms, start_ms + gap_ms)
// removed.
inline Run calibrate_with_gap(const sim::Scenario& s, std::uint64_t seed, std::int64_t start_ms,
                              std::int64_t gap_ms, calibration::Passes passes = {}) {
  const sim::SimData data = sim::simulate(s, seed);
  calibration::LoopData d = evaluation::loop_data(s, data);
  const std::int64_t from = start_ms * kMs, to = (start_ms + gap_ms) * kMs;
  d.imu.erase(std::remove_if(d.imu.begin(), d.imu.end(),
                             [&](const ImuSample& x) { return x.t_ns >= from && x.t_ns < to; }),
              d.imu.end());
  Run::State x0;
  Run::Filter::Covariance p0;
  initialise(sim::simulation_prior<sim::kPaperMarkers>(s, data, seed), x0, p0);
  const Run::State truth = evaluation::truth_state<Run::State>(s);
  return calibration::run_loop<3, 0>(evaluation::scenario_config(s), x0, p0, d, &truth, {}, {},
                                     passes);
}

// The largest |error| / sigma over a run's calibration states.
inline double worst_sigmas(const Run& run) {
  const auto row = run.history.back();
  return (row.error.array().abs() / row.sigma.array()).maxCoeff();
}

}  // namespace mirrorcal::gaptest
