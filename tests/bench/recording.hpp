// The whole loop over one simulated recording (the paper scenario's 60 s and M = 3, IMU 200 Hz,
// camera at 20 Hz as issue 6 asks), from the filter's construction to the final estimate; the data
// are simulated beforehand and the estimate is published to a sink that drops it.
#pragma once

#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mirrorcal::bench {

struct Recording {
  sim::Scenario scenario;
  sim::SimData data;
};

Recording paper_recording();

// Calibrates from the recording; returns the number of markers used (so the work cannot be
// optimised away, and a caller can check it did something).
std::uint64_t calibrate(const Recording& r);

// Calibrates as `mirrorcal calibrate` and `mirrorcal sim` do: calibration::run_loop's passes over
// the data (kDefaultPasses at least) and its Gauss-Newton refinement, keeping the history; returns
// the last pass's markers used.
std::uint64_t calibrate_as_shipped(const Recording& r);
// The same with the IMU's intrinsics estimated (scale-misalignment, the scenario's tolerances),
// or 0 if the build lacks that model.
std::uint64_t calibrate_as_shipped_with_imu_intrinsics(const Recording& r);

}  // namespace mirrorcal::bench
