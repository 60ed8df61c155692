// One calibration through the deterministic loop, end to end: on the simulated rig, or on any data
// held in memory (a recording).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "history.hpp"
#include "mirrorcal/firmware/loop.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/sim_host/scenario.hpp"
#include "mirrorcal/sim_host/simulator.hpp"
#include "outputs.hpp"

namespace mirrorcal::app {

constexpr int kMarkers = 3;  // M of the product build: the paper's three markers

// mirrorcal sim --frames: find the markers in rendered frames with the board's detection code
// (sim_frames.hpp) instead of taking the listed reflections. By default the frames carry the
// scenario's pixel noise (each spot drawn displaced by it, as the listed reflections are) and the
// filter assumes it: the paper's scenario with detection and identification in the loop.
struct FrameMode {
  bool enabled = false;
  hal::PixelFormat format = hal::PixelFormat::kGrey;
  double spot_noise_px = -1.0;  // the noise drawn into the frames, px; < 0: the scenario's
  double pixel_sigma = -1.0;    // the pixel noise the filter assumes, px; < 0: the scenario's
};

// How detection did against the rendered truth (--frames only).
struct DetectionReport {
  std::uint64_t frames = 0;
  std::uint64_t markers_drawn = 0;        // reflections in the image
  std::uint64_t markers_labelled = 0;     // reflections the detection reported
  std::uint64_t wrong_labels = 0;         // reported under one marker's label at another's spot
  std::uint64_t wrong_labels_before = 0;  // the same in the passes before the last (the rest of
                                          // the report is the last pass's)
  std::uint64_t dropped_in_doubt = 0;     // labels withheld: ambiguous, crossing or merged
  std::uint64_t unlabelled_blobs = 0;     // blobs no marker took (spurious, merged, crowded)
  double centroid_rms_px = 0.0;           // correctly labelled, against where the spot was drawn
  double centroid_max_px = 0.0;
  double centroid_mean_px[2] = {0.0, 0.0};  // the mean error in u and v: detection's bias
  double ms_per_frame = 0.0;                // detection and identification, wall time
};

template <int NK>
struct SimRun {
  using Filter = CalibrationFilter<double, kMarkers, NK>;
  using State = typename Filter::State;
  State truth{};
  std::vector<HistoryRow<Filter>> history;  // one row per frame, and the final one
  typename Filter::Covariance covariance;   // the final one (stage 2 starts from stage 1's)
  CalibrationResult result;
  FilterCounters filter_counters;
  firmware::LoopCounters loop_counters;
  std::uint64_t markers_out_of_image = 0;
  std::size_t imu_samples = 0, frames = 0;
  DetectionReport detection;  // --frames only
};
template <int NK>
using CalibrationRun = SimRun<NK>;

// What the loop consumes, filled before it starts (the loop itself never allocates).
struct LoopData {
  std::vector<ImuSample> imu;              // timestamp order
  std::vector<sim::ObservedFrame> frames;  // timestamp order; any subset of markers each
  std::int64_t imu_period_ns = 5'000'000;  // nominal IMU period
  int width = 640, height = 480;           // image size, for the result files
};

// The nominal period of an IMU sampled at rate_hz.
inline std::int64_t imu_period_ns(double rate_hz) {
  return static_cast<std::int64_t>(1e9 / rate_hz);
}

// The calibration configuration a scenario implies (the filter is told the true noise levels and,
// in stage 1, the true intrinsics: the paper's calibrated camera).
CalibrationConfig scenario_config(const sim::Scenario& s);

// The data a simulated run hands to the loop.
LoopData loop_data(const sim::Scenario& s, const sim::SimData& data);

// What a run may add to the loop: marker frames from elsewhere than LoopData::frames (sim --frames:
// rendered frames through the board's detection, relabelled with the filter's prediction), and a
// profiler timing its stages.
struct LoopHooks {
  hal::MarkerSource<kMarkers>* source = nullptr;
  hal::MarkerRelabeler<kMarkers>* relabeler = nullptr;
  firmware::LoopProfiler* profiler = nullptr;
};

// Passes over the data that a calibration makes by default. The first pass linearises the
// measurements about the user's guesses (markers known to 10 cm while their mirror images are
// 60 cm away): those early linearisation errors stay in the estimate and make the filter
// over-confident (average NEES of the calibration states about 30 where 15 is consistent). The
// second pass starts the calibration parameters at the first pass's estimate, with the prior's
// covariance; its estimate is consistent (NEES 15-17) and as accurate as a run started at the
// truth. The data count twice only through the prior mean, whose weight against the data's is
// (final sigma / prior sigma)^2 < 1e-4 in stage 1. A parameter whose prior still weighs more than
// kNegligiblePriorWeight (stage 2's start from stage 1's covariance) keeps its prior mean: moving
// it made stage 2 over-confident (average NEES 23.0 of 20 states over 40 runs, outside 18.1..22.0).
constexpr int kDefaultPasses = 2;
constexpr double kNegligiblePriorWeight = 1e-2;

// Runs the loop on data from the initial estimate (x0, p0), `passes` times (see kDefaultPasses);
// the result is the last pass's. With truth, each history row carries the error and NEES against
// it. progress(f) is called with the fraction done now and then; hooks(pass), if given, adds a
// marker source or profiler to a pass.
template <int NK>
SimRun<NK> run_loop(const CalibrationConfig& config, const typename SimRun<NK>::State& x0,
                    const typename SimRun<NK>::Filter::Covariance& p0, const LoopData& data,
                    const typename SimRun<NK>::State* truth,
                    const std::function<void(double)>& progress = {},
                    const std::function<LoopHooks(int pass)>& hooks = {},
                    int passes = kDefaultPasses);

extern template SimRun<0> run_loop<0>(const CalibrationConfig&, const SimRun<0>::State&,
                                      const SimRun<0>::Filter::Covariance&, const LoopData&,
                                      const SimRun<0>::State*, const std::function<void(double)>&,
                                      const std::function<LoopHooks(int)>&, int);
extern template SimRun<5> run_loop<5>(const CalibrationConfig&, const SimRun<5>::State&,
                                      const SimRun<5>::Filter::Covariance&, const LoopData&,
                                      const SimRun<5>::State*, const std::function<void(double)>&,
                                      const std::function<LoopHooks(int)>&, int);

// Simulates one run (data and initial guess from seed) and calibrates it: simulate, then run_loop.
SimRun<0> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                         const std::function<void(double)>& progress = {},
                         const FrameMode& frames = {}, firmware::LoopProfiler* profiler = nullptr,
                         int passes = kDefaultPasses);

// The paper's section III and Table III: stage 1 as run_simulation (the camera's intrinsics known),
// then stage 2 on a second minute of data (the rig moved again, new noise) with the intrinsics
// estimated too: the calibration parameters start from stage 1's estimate and covariance, the
// intrinsics from guesses drawn with the scenario's intrinsics sigma (100 px), the IMU state from
// its prior. Stage 2's state is what the run reports.
SimRun<5> run_two_stage_simulation(const sim::Scenario& s, std::uint64_t seed,
                                   const std::function<void(double)>& progress = {});

// The prior a simulated run with this seed starts from (a user's guesses, drawn around the truth).
Prior<kMarkers> simulation_prior(const sim::Scenario& s, const sim::SimData& data,
                                 std::uint64_t seed);

// camchain-imucam.yaml, mirrorcal-result.yaml and estimates.csv of a run, in dir.
template <int NK>
bool write_run_outputs(const std::string& dir, const SimRun<NK>& run, std::string& error) {
  return write_camchain_imucam(dir + "/camchain-imucam.yaml", run.result, error) &&
         write_result_yaml(dir + "/mirrorcal-result.yaml", run.result, error) &&
         write_estimates_csv(dir + "/estimates.csv", run.history, error);
}

}  // namespace mirrorcal::app
