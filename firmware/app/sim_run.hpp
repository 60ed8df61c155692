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
// (sim_frames.hpp) instead of taking the listed reflections.
struct FrameMode {
  bool enabled = false;
  hal::PixelFormat format = hal::PixelFormat::kGrey;
};

// How detection did against the rendered truth (--frames only).
struct DetectionReport {
  std::uint64_t frames = 0;
  std::uint64_t markers_drawn = 0;     // reflections in the image
  std::uint64_t markers_labelled = 0;  // reflections the detection reported
  std::uint64_t wrong_labels = 0;      // reported under one marker's label at another's spot
  std::uint64_t dropped_in_doubt = 0;  // labels withheld: ambiguous, crossing or merged
  std::uint64_t spurious_blobs = 0;    // blobs no marker took
  double centroid_rms_px = 0.0;        // correctly labelled, against the true projection
  double centroid_max_px = 0.0;
  double ms_per_frame = 0.0;  // detection and identification, wall time
};

template <int NK>
struct SimRun {
  using Filter = CalibrationFilter<double, kMarkers, NK>;
  using State = typename Filter::State;
  State truth{};
  std::vector<HistoryRow<Filter>> history;  // one row per frame, and the final one
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
  // A camera in place of the listed frames (mirrorcal sim --frames): markers detected in frames,
  // relabelled with the loop's prediction at each frame. Not owned; frames is then unused.
  hal::MarkerSource<kMarkers>* camera = nullptr;
  hal::MarkerRelabeler<kMarkers>* identifier = nullptr;
};

// The calibration configuration a scenario implies (the filter is told the true noise levels and,
// in stage 1, the true intrinsics: the paper's calibrated camera).
CalibrationConfig scenario_config(const sim::Scenario& s);

// The data a simulated run hands to the loop.
LoopData loop_data(const sim::Scenario& s, const sim::SimData& data);

// Runs the loop on data from the initial estimate (x0, p0). With truth, each history row carries
// the error and NEES against it. progress(f) is called with the fraction done now and then.
template <int NK>
SimRun<NK> run_loop(const CalibrationConfig& config, const typename SimRun<NK>::State& x0,
                    const typename SimRun<NK>::Filter::Covariance& p0, const LoopData& data,
                    const typename SimRun<NK>::State* truth,
                    const std::function<void(double)>& progress = {});

extern template SimRun<0> run_loop<0>(const CalibrationConfig&, const SimRun<0>::State&,
                                      const SimRun<0>::Filter::Covariance&, const LoopData&,
                                      const SimRun<0>::State*, const std::function<void(double)>&);
extern template SimRun<5> run_loop<5>(const CalibrationConfig&, const SimRun<5>::State&,
                                      const SimRun<5>::Filter::Covariance&, const LoopData&,
                                      const SimRun<5>::State*, const std::function<void(double)>&);

// Simulates one run (data and initial guess from seed) and calibrates it: simulate, then run_loop.
SimRun<0> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                         const std::function<void(double)>& progress = {},
                         const FrameMode& frames = {});

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
