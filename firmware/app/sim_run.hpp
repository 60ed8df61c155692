// One calibration of the simulated rig through the deterministic loop, end to end.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "history.hpp"
#include "mirrorcal/firmware/loop.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/sim_host/scenario.hpp"
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

// The calibration configuration a scenario implies (the filter is told the true noise levels and,
// in stage 1, the true intrinsics: the paper's calibrated camera).
CalibrationConfig scenario_config(const sim::Scenario& s);

// Simulates one run (data and initial guess from seed) and calibrates it. progress(f) is called
// with the fraction done now and then, if given.
SimRun<0> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                         const std::function<void(double)>& progress = {},
                         const FrameMode& frames = {});

}  // namespace mirrorcal::app
