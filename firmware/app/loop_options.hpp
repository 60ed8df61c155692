// Options of the commands that run the loop (sim, and run on the board): the timing budget
// (--profile, --budget-imu-us, --budget-frame-us) and real-time scheduling (--rt-priority, --mlock,
// --cpu), and the passes over the data.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cli.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/loop/timing.hpp"

namespace mirrorcal::app {

using calibration::imu_period_ns;
using calibration::Passes;

// Option names to add to parse(): these take a value, these are flags.
extern const std::vector<std::string> kLoopValueOptions;
extern const std::vector<std::string> kLoopFlagOptions;

// Applies --rt-priority, --mlock and --cpu, printing one line per setting (what was done, or why
// not: without privileges the run goes on); an error for a value that is wrong in itself.
bool apply_realtime_options(const Options& o, std::string& error);

// The profiler --profile asks for (nullptr without it): budgets from --budget-imu-us and
// --budget-frame-us, by default the IMU and the frame period. Call before the loop starts.
bool make_profiler(const Options& o, hal::Clock& clock, std::int64_t imu_period_ns,
                   std::int64_t frame_period_ns, std::unique_ptr<loop::LoopProfiler>& profiler,
                   std::string& error);

// --passes N of sim and montecarlo: exactly N, 1 <= N <= kMaxRequestedPasses (each replays the
// whole recording); without it, the default (Passes{}).
constexpr std::uint64_t kMaxRequestedPasses = 20;
bool passes_option(const Options& o, Passes& passes, std::string& error);

// Prints the timing table under a title and writes the histograms to <dir>/timing-histogram.txt;
// an error if it cannot.
bool report_profile(const loop::LoopProfiler& p, const std::string& title, const std::string& dir,
                    std::string& error);

}  // namespace mirrorcal::app
