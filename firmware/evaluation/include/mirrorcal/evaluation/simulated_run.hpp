// Simulated calibrations for the sim and montecarlo commands and the tests: a scenario's rig
// simulated with a seed, the prior a user would have drawn around its truth, and the calibration
// pipeline run on it (stage 1, both stages, or everything at once), with the truth to judge it.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mirrorcal::evaluation {

using calibration::CalibrationRun;
using calibration::LoopData;
using calibration::Passes;

// mirrorcal sim --frames: find the markers in rendered frames with the board's detection code
// (rendered_markers.hpp) instead of taking the listed reflections. By default the frames carry the
// scenario's pixel noise (each spot drawn displaced by it, as the listed reflections are) and the
// filter assumes it: the paper's scenario with detection and identification in the loop.
struct FrameMode {
  bool enabled = false;
  hal::PixelFormat format = hal::PixelFormat::kGrey;
  double spot_noise_px = -1.0;  // the noise drawn into the frames, px; < 0: the scenario's
  double pixel_sigma = -1.0;    // the pixel noise the filter assumes, px; < 0: the scenario's
  // Every LED drawn equally bright: no brightness code, the labels come from the rig's shape
  // fitted to reflections tracked over frames (detection/shape_bootstrap.hpp).
  bool identical_leds = false;
  // LEDs that blink their names (hal/blink_code.hpp): marker i is not drawn in frame i + 1 of
  // each period of this many frames, and the detection names the tracks by the frames they go
  // dark in. 0: the LEDs stay lit.
  int blink_period = 0;
  // A real room drawn into the frames (sim::RoomConfig): two lights seen in the mirror, a ghost
  // of each LED from the glass's front surface, the brightest LEDs clipped, motion blur.
  bool room = false;
};

// The calibration configuration a scenario implies (the filter is told the true noise levels and,
// in stage 1, the true intrinsics: the paper's calibrated camera).
CalibrationConfig scenario_config(const sim::Scenario& s);

// The data a simulated run hands to the loop.
LoopData loop_data(const sim::Scenario& s, const sim::SimData& data);

// Simulates one run (data and initial guess from seed) and calibrates it: simulate, then run_loop.
// M is the scenario's number of markers (s.truth.markers); NI the IMU's intrinsics estimated (an
// ImuModel's, from the default ImuIntrinsicsSigma prior about the ideal IMU).
template <int M, int NI = 0>
CalibrationRun<M, 0, NI> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                                        const std::function<void(double)>& progress = {},
                                        const FrameMode& frames = {},
                                        loop::LoopProfiler* profiler = nullptr, Passes passes = {});

// What the data of a simulated run can hold: the 1-sigma of each calibration state (SI, in
// calibration_params() order) that a filter linearised at the truth ends with, on the same rig,
// motion and sensors with noise-free data, started at the truth from the prior's covariance (one
// pass; the curvature the transform sees over the prior still widens its first frames a little).
// The campaigns judge errors against it: a run's estimate can be no better than this. NI: the IMU
// model's intrinsics, estimated too (started at the scenario's true ones, with the prior's sigmas).
template <int M, int NI = 0>
std::vector<double> data_limit_sigmas(const sim::Scenario& s, std::uint64_t seed);

// The paper's section III and Table III: stage 1 as run_simulation (the camera's intrinsics known),
// then stage 2 on a second minute of data (the rig moved again, new noise) with the intrinsics
// estimated too: the calibration parameters start from stage 1's estimate and covariance, the
// intrinsics from guesses drawn with the scenario's intrinsics sigma (100 px), the IMU state from
// its prior. Stage 2's state is what the run reports. NK = 5 estimates the skew; NK = 4 holds it at
// the scenario camera's (simulate a camera without skew to hold it at zero: sim::without_skew()).
// NI: the IMU model's intrinsics, estimated in both stages (stage 2 starts them from stage 1's).
template <int M, int NK, int NI = 0>
CalibrationRun<M, NK, NI> run_two_stage_simulation(
    const sim::Scenario& s, std::uint64_t seed, const std::function<void(double)>& progress = {});

// The paper's "everything at once" mode: one minute of data, the intrinsics estimated with the
// rest from the prior's guesses (100 px off), the same as `record --intrinsics` then `calibrate`.
template <int M, int NK, int NI = 0>
CalibrationRun<M, NK, NI> run_one_stage_simulation(
    const sim::Scenario& s, std::uint64_t seed, const std::function<void(double)>& progress = {});

// Compiled in simulated_run.cpp for every filter the product uses (marker_counts.hpp).
#define MIRRORCAL_RUN_SIMULATION(M, NI)                                               \
  CalibrationRun<M, 0, NI> run_simulation<M, NI>(const sim::Scenario&, std::uint64_t, \
                                                 const std::function<void(double)>&,  \
                                                 const FrameMode&, loop::LoopProfiler*, Passes)
#define MIRRORCAL_STAGED_SIMULATION(name, M, NK, NI)                             \
  CalibrationRun<M, NK, NI> name<M, NK, NI>(const sim::Scenario&, std::uint64_t, \
                                            const std::function<void(double)>&)
#define MIRRORCAL_EXTERN_SIMULATION_(M, NI)        \
  extern template MIRRORCAL_RUN_SIMULATION(M, NI); \
  extern template std::vector<double> data_limit_sigmas<M, NI>(const sim::Scenario&, std::uint64_t);
MIRRORCAL_FOR_EACH_STAGE1_FILTER(MIRRORCAL_EXTERN_SIMULATION_)
#undef MIRRORCAL_EXTERN_SIMULATION_
#define MIRRORCAL_EXTERN_STAGED_SIMULATIONS_(M, NK, NI)                             \
  extern template MIRRORCAL_STAGED_SIMULATION(run_two_stage_simulation, M, NK, NI); \
  extern template MIRRORCAL_STAGED_SIMULATION(run_one_stage_simulation, M, NK, NI);
MIRRORCAL_FOR_EACH_STAGE2_FILTER(MIRRORCAL_EXTERN_STAGED_SIMULATIONS_)
#undef MIRRORCAL_EXTERN_STAGED_SIMULATIONS_

// The calibration state a scenario's truth is, with the IMU's intrinsics (the IMU's motion block
// left at zero).
template <class State>
State truth_state(const sim::Scenario& s) {
  State t;
  t.p_b_c = s.truth.p_b_c;
  t.q_b_c = s.truth.q_b_c;
  for (int i = 0; i < State::kMarkers; ++i)
    t.markers.template segment<3>(3 * i) = s.truth.markers[static_cast<std::size_t>(i)];
  t.t_d = s.truth.t_d;
  if constexpr (State::kIntrinsics > 0) {
    const auto k = camera_parameters<State::kIntrinsics>(s.truth.intrinsics);
    for (int j = 0; j < State::kIntrinsics; ++j) t.intrinsics(j) = k[static_cast<std::size_t>(j)];
  }
  if constexpr (State::kImuIntrinsics > 0) t.imu = s.imu_intrinsics;
  return t;
}

}  // namespace mirrorcal::evaluation
