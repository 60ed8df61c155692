// montecarlo --batch: a simulated run's data and prior solved by the batch (batch.hpp) beside the
// filter's calibration of them. Part of mirrorcal::batch: only a build with the batch has it.
#pragma once

#include <cstdint>

#include "mirrorcal/evaluation/campaign.hpp"

namespace mirrorcal::evaluation {

// The batch solution of the data and prior that run_simulation draws for rig from seed (stage 1;
// the IMU model's intrinsics estimated), against the rig's truth; failure says why there is none.
BatchOutcome solve_batch_outcome(const sim::Scenario& rig, std::uint64_t seed, ImuModel imu_model);

}  // namespace mirrorcal::evaluation
