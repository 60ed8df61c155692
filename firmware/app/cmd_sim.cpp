// mirrorcal sim: one calibration of a simulated rig, printed beside the truth.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include "build_tools.hpp"
#include "cli.hpp"
#include "loop_options.hpp"
#include "mirrorcal/calibration/report.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/evaluation/paper_tables.hpp"
#include "mirrorcal/evaluation/plots.hpp"
#include "mirrorcal/evaluation/rendered_markers.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/sim/simulator.hpp"
#include "sim_options.hpp"

namespace mirrorcal::app {

using namespace calibration;
using namespace evaluation;

namespace {

// Each calibration state's truth, its estimate after the first frame and at the end with their
// sigmas, and the NEES of the end.
template <class Run>
void print_estimates(const Run& run, const sim::Scenario& s) {
  const auto& params = run.result.params;
  const auto truth = truth_display(s, Run::State::kIntrinsics);
  const auto& first = run.first_frame;
  const auto& last = run.history.back();
  std::printf("\n%-17s %-5s %12s %20s %20s %10s\n", "param", "unit", "truth",
              "after 1st frame +-1s", "final +-1sigma", "error/sig");
  for (std::size_t j = 0; j < params.size(); ++j) {
    const double sc = params[j].scale;
    std::printf("%-17s %-5s %12.4f %12.4f +-%-6.3f %12.4f +-%-6.4f %+10.2f\n",
                params[j].name.c_str(), params[j].unit.c_str(), truth[j],
                truth[j] + first.error(int(j)) * sc, first.sigma(int(j)) * sc,
                truth[j] + last.error(int(j)) * sc, last.sigma(int(j)) * sc,
                last.error(int(j)) / last.sigma(int(j)));
  }
  print_final_nees(params.size(), last.nees);
}

template <class Run>
void print_loop_summary(const Run& run, double wall) {
  const auto& lc = run.loop_counters;
  const auto& fc = run.filter_counters;
  std::printf(
      "loop, last of %d passes: %llu IMU samples, %llu frames (%llu without markers), %llu "
      "IMU gaps, "
      "%llu markers used, %llu gated, %llu filter failures; %.2f s wall\n",
      run.result.passes, (unsigned long long)lc.imu_samples, (unsigned long long)lc.frames,
      (unsigned long long)lc.frames_without_markers, (unsigned long long)lc.imu_gaps,
      (unsigned long long)fc.markers_used, (unsigned long long)fc.markers_gated,
      (unsigned long long)fc.failures, wall);
}

// What a sim run shows and writes beside its calibration.
struct SimReport {
  const sim::Scenario& scenario;
  std::uint64_t seed;
  FrameMode frames;
  bool plots;
  std::string dir, title;
  bool two_stage;  // stage 2 reported, after stage 1
  const loop::LoopProfiler* profiler;
  std::chrono::steady_clock::time_point t0;
};

// What a run shows and writes, whichever stage it ended in; false with the error when a file
// cannot be written.
template <class Run>
bool report_run(const Run& run, const SimReport& r, int& status, std::string& err) {
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - r.t0).count();
  end_progress("calibrating done");
  print_estimates(run, r.scenario);
  print_loop_summary(run, wall);
  if (r.frames.enabled) print_detection(run.detection, r.frames.format);

  const auto& params = run.result.params;
  print_result_warnings(run.result);
  // The error plots first: the report embeds them.
  ReportPlots figures = report_plots(r.plots);
  if (figures.draw) {
    const std::vector<ErrorSeries> series = {error_series(run.history, params)};
    figures.extra_pngs = plot_errors(r.dir, "mirrorcal sim, seed " + std::to_string(r.seed), params,
                                     series, chi2_quantile(0.025, double(params.size())),
                                     chi2_quantile(0.975, double(params.size())), err);
    if (figures.extra_pngs.empty()) std::fprintf(stderr, "mirrorcal: no plots: %s\n", err.c_str());
    for (const auto& p : figures.extra_pngs) std::printf("plot: %s\n", p.c_str());
  }
  if (!write_run_outputs_and_report(r.dir, run, r.title, r.two_stage, figures, err)) return false;
  std::printf(
      "wrote %s/camchain-imucam.yaml, mirrorcal-result.yaml, estimates.csv, report.txt, "
      "report.html, residuals.csv, imu_residuals.csv%s\n",
      r.dir.c_str(),
      run.result.noise.estimated ? ", imu.yaml (the noise densities estimated)" : "");
  status = calibration_exit_status(run.result);
  return !r.profiler ||
         report_profile(*r.profiler,
                        "this host's monotonic clock, simulated data fed as fast as it is taken",
                        r.dir, err);
}

// --intrinsics and what goes with it: --hold-skew and --one-stage only with it, and
// --estimate-distortion with it and a lens; not with --frames or --profile. An error names the
// first that does not go.
bool check_stage_options(const Options& o, const FrameMode& frames, std::string& error) {
  const bool intrinsics = o.flag("intrinsics");
  if (intrinsics && (frames.enabled || o.flag("profile")))
    error = "--intrinsics runs on listed markers, without --profile (not yet with --frames)";
  else if ((o.flag("outliers") || o.flag("label-swaps")) && frames.enabled)
    error =
        "--outliers and --label-swaps mis-detect listed markers; rendered frames (--frames) have "
        "room lights";
  else if ((o.flag("hold-skew") || o.flag("one-stage")) && !intrinsics)
    error = "--hold-skew and --one-stage apply with --intrinsics";
  else if (o.flag("estimate-distortion") &&
           (!intrinsics || !o.flag("distortion") || o.get("distortion", "") == "none"))
    error = "--estimate-distortion applies with --intrinsics and --distortion radtan|equidistant";
  else
    return true;
  return false;
}

}  // namespace

int cmd_sim(int argc, char** argv) {
  std::vector<std::string> with_value = {"scenario",    "seed",        "out",
                                         "format",      "pixel-sigma", "imu-model",
                                         "spot-noise",  "passes",      "timeshift",
                                         "distortion",  "line-delay",  "filter-line-delay",
                                         "markers",     "duration",    "outliers",
                                         "label-swaps", "blink"},
                           flags = {"no-plots",       "frames",         "intrinsics",
                                    "hold-skew",      "one-stage",      "estimate-distortion",
                                    "estimate-noise", "identical-leds", "room"};
  with_value.insert(with_value.end(), kLoopValueOptions.begin(), kLoopValueOptions.end());
  flags.insert(flags.end(), kLoopFlagOptions.begin(), kLoopFlagOptions.end());
  Options o;
  FrameMode frames;
  std::string error;
  if (!parse(argc, argv, 2, with_value, flags, o, error) || !frame_mode_option(o, frames, error))
    return refuse(error);
  if (!check_stage_options(o, frames, error)) return refuse(error);
  const bool intrinsics = o.flag("intrinsics"), one_stage = o.flag("one-stage");
  // --estimate-distortion: stage 2 estimates the lens's coefficients with fu fv cu cv, skew held
  // (at the scenario camera's; --hold-skew: a camera without skew).
  const bool lens = o.flag("estimate-distortion");
  // --hold-skew: a camera without skew, and a stage 2 that holds it at zero.
  std::uint64_t seed = 0;
  sim::Scenario s;
  if (!parse_count(o, "seed", 1, 0, seed, error) || !scenario_option(o, seed, s, error) ||
      !blink_fits(frames, static_cast<int>(s.truth.markers.size()), error))
    return refuse(error);
  if (o.flag("hold-skew")) s = sim::without_skew(s);
  // --passes N: exactly N (at most kMaxRequestedPasses); by default kDefaultPasses, more while the
  // last gated too many.
  Passes passes;
  if (!passes_option(o, passes, error)) return refuse(error);
  if (intrinsics && o.flag("passes"))
    return refuse("--passes applies to stage 1 only (without --intrinsics)");
  ImuModel imu_model = ImuModel::kCalibrated;
  if (!imu_model_option(o, simulated_imu_model(s), imu_model, error)) return refuse(error);
  // --estimate-noise: the noise levels from the data, the calibration made again with them.
  passes.estimate_noise = o.flag("estimate-noise");
  if (intrinsics && passes.estimate_noise)
    return refuse("--estimate-noise applies to stage 1 only (without --intrinsics)");
  std::string dir;
  if (!make_out_dir(o, "out/sim", dir, error)) return refuse(error, 1);
  loop::SteadyClock clock;  // the simulation's own clock is simulated time
  std::unique_ptr<loop::LoopProfiler> profiler;
  if (!make_profiler(o, clock, static_cast<std::int64_t>(1e9 / s.imu_rate_hz),
                     static_cast<std::int64_t>(1e9 / s.camera_rate_hz), profiler, error) ||
      !apply_realtime_options(o, error))
    return refuse(error);
  const std::string note = markers_note(s);  // the number of markers, where not three
  std::printf(
      "mirrorcal sim: scenario '%s'%s, seed %llu, %.0f s of data (IMU %.0f Hz, camera %.0f Hz)\n",
      s.name.c_str(), note.c_str(), static_cast<unsigned long long>(seed), s.duration_s,
      s.imu_rate_hz, s.camera_rate_hz);
  const SimReport report{
      s,
      seed,
      frames,
      !o.flag("no-plots"),
      dir,
      "mirrorcal sim, scenario " + s.name + note + ", seed " + std::to_string(seed) +
          (intrinsics
               ? one_stage ? ", intrinsics in one stage" : ", intrinsics in stage 2 (reported)"
               : ""),
      intrinsics && !one_stage,
      profiler.get(),
      std::chrono::steady_clock::now()};
  const auto progress = [](double f) { print_progress("calibrating", f); };
  return with_markers(int(s.truth.markers.size()), [&](auto markers) {
    constexpr int M = decltype(markers)::value;
    return with_filter_blocks(
        camera_block(intrinsics || lens, o.flag("hold-skew"), lens), imu_model,
        [&](auto k, auto imu) {
          constexpr int NK = decltype(k)::value, NI = decltype(imu)::value;
          std::string err;
          int status = 0;
          bool written = false;
          if constexpr (NK == 0)
            written =
                report_run(run_simulation<M, NI>(s, seed, progress, frames, profiler.get(), passes),
                           report, status, err);
          else
            written = report_run(one_stage ? run_one_stage_simulation<M, NK, NI>(s, seed, progress)
                                           : run_two_stage_simulation<M, NK, NI>(s, seed, progress),
                                 report, status, err);
          return written ? status : refuse(err, 1);
        });
  });
}

}  // namespace mirrorcal::app
