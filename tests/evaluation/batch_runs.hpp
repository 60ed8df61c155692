// Simulated runs solved by the batch, for its tests (batch_test.cpp, batch_campaign_test.cpp).
#pragma once

#include <gtest/gtest.h>

#include "mirrorcal/evaluation/batch.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"

namespace batch_runs {

namespace mc = mirrorcal;
namespace ev = mirrorcal::evaluation;

// A simulated run's batch solution and its error against the truth.
struct Solved {
  mc::calibration::CalibrationResult result;
  ev::BatchReport report;
  ev::TruthError error;
};
// From the priors drawn for the run, or (guess_truth) with every guess at the truth and the
// drawn sigmas: the solution then owes nothing to the priors' pull. camera_parameters: the
// filter's NK; imu_model: the IMU's intrinsics estimated.
inline Solved solve_simulated(const mc::sim::Scenario& s, const mc::sim::SimData& data,
                              std::uint64_t seed, bool guess_truth = false,
                              int camera_parameters = 0,
                              mc::ImuModel imu_model = mc::ImuModel::kCalibrated) {
  mc::Prior<3> prior = mc::sim::simulation_prior<3>(s, data, seed);
  if (guess_truth) {
    const mc::sim::Kinematics k =
        mc::sim::kinematics(s.motion, static_cast<double>(data.imu.front().t_ns) * 1e-9);
    prior.p = k.p;
    prior.v = k.v;
    prior.q_n_b = k.q_n_b;
    prior.b_a = data.b_a0;
    prior.b_g = data.b_g0;
    prior.p_b_c = s.truth.p_b_c;
    prior.q_b_c = s.truth.q_b_c;
    for (std::size_t i = 0; i < 3; ++i) prior.markers[i] = s.truth.markers[i];
    prior.t_d = s.truth.t_d;
    prior.intrinsics = s.truth.intrinsics;
  }
  const mc::io::RecordingPriors priors =
      mc::io::from_prior(prior, s.gravity_n, s.pixel_sigma, camera_parameters > 0);
  ev::BatchInput in = ev::simulated_batch_input(s, data, priors, camera_parameters, imu_model);
  if (guess_truth) in.imu_guess = s.imu_intrinsics;
  Solved out;
  std::string error;
  EXPECT_TRUE(ev::solve_batch(in, {}, out.result, out.report, error)) << error;
  out.error = ev::truth_error(out.result, mc::sim::recording_truth(s));
  return out;
}

inline mc::sim::Scenario short_random(std::uint64_t seed, double duration_s) {
  mc::sim::Scenario s = mc::sim::random_scenario(seed);
  s.duration_s = duration_s;
  return s;
}

}  // namespace batch_runs
