// One calibration of the simulated rig through the deterministic loop, end to end.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "history.hpp"
#include "mirrorcal/firmware/loop.hpp"
#include "mirrorcal/sim_host/scenario.hpp"
#include "outputs.hpp"

namespace mirrorcal::app {

constexpr int kMarkers = 3;  // M of the product build: the paper's three markers

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
};

// The calibration configuration a scenario implies (the filter is told the true noise levels and,
// in stage 1, the true intrinsics: the paper's calibrated camera).
CalibrationConfig scenario_config(const sim::Scenario& s);

// Simulates one run (data and initial guess from seed) and calibrates it. progress(f) is called
// with the fraction done now and then, if given; profiler, if given, times the loop.
SimRun<0> run_simulation(const sim::Scenario& s, std::uint64_t seed,
                         const std::function<void(double)>& progress = {},
                         firmware::LoopProfiler* profiler = nullptr);

}  // namespace mirrorcal::app
