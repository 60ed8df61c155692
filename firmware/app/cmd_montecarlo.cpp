// mirrorcal montecarlo: N independent simulated calibrations, statistics beside the paper's. The
// options make a campaign, its runs go out on threads, and evaluation's campaign statistics and
// reports say what came of them.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "cli.hpp"
#include "loop_options.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/campaign_report.hpp"
#include "mirrorcal/evaluation/paper_tables.hpp"
#include "mirrorcal/evaluation/rendered_markers.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#ifdef MIRRORCAL_BATCH
#include "mirrorcal/evaluation/batch_outcome.hpp"
#endif
#include "mirrorcal/sim/simulator.hpp"
#include "sim_options.hpp"

namespace mirrorcal::app {

using namespace calibration;
using namespace evaluation;

namespace {

// What a campaign runs, from the command line: the rigs, the seeds and how each run calibrates.
struct Campaign {
  bool intrinsics = false, hold_skew = false, one_stage = false;
  bool lens = false;                 // --estimate-distortion: the lens's coefficients in stage 2
  bool batch = false;                // --batch: the batch solution of every run beside it
  bool family = false;               // a rig of its own for every run (the random family)
  std::optional<std::uint64_t> rig;  // --rig: the family's one rig for every run, by its seed
  FrameMode frames;
  Passes passes;
  ImuModel imu_model = ImuModel::kCalibrated;  // --imu-model, or the scenario's IMU's
  std::uint64_t seed = 0, runs = 0, jobs = 0;
  sim::Scenario scenario;                // the campaign's (the seed's draw, for a family)
  std::vector<sim::Scenario> scenarios;  // each run's rig
  bool plots = true;
};

// The campaign the options ask for; an error (exit code 2) for options that are wrong or do not
// go together.
bool campaign_options(const Options& o, Campaign& c, std::string& error) {
  c.intrinsics = o.flag("intrinsics");
  c.hold_skew = o.flag("hold-skew");
  c.one_stage = o.flag("one-stage");
  c.plots = !o.flag("no-plots");
  // --estimate-distortion: stage 2 estimates the lens's coefficients with fu fv cu cv, skew held
  // (at the scenario camera's; --hold-skew: a camera without skew).
  c.lens = o.flag("estimate-distortion");
  // Options that are wrong or clash: error says why.
  const auto wrong = [&](const std::string& why) {
    error = why;
    return false;
  };
  if (c.lens && (!c.intrinsics || !o.flag("distortion") || o.get("distortion", "") == "none"))
    return wrong(
        "--estimate-distortion applies with --intrinsics and --distortion radtan|equidistant");
  if ((c.hold_skew || c.one_stage) && !c.intrinsics)
    return wrong("--hold-skew and --one-stage apply with --intrinsics");
  if (!frame_mode_option(o, c.frames, error)) return false;
  if ((o.flag("outliers") || o.flag("label-swaps")) && c.frames.enabled)
    return wrong(
        "--outliers and --label-swaps mis-detect listed markers; rendered frames (--frames) have "
        "room lights");
  if (c.intrinsics && c.frames.enabled)
    return wrong("--intrinsics runs on listed markers (not yet with --frames)");
  c.batch = o.flag("batch");
#ifndef MIRRORCAL_BATCH
  if (c.batch) return wrong("--batch: this build has no batch solver (Ceres; MIRRORCAL_BATCH)");
#endif
  if (c.batch && (c.intrinsics || c.frames.enabled || o.flag("outliers") || o.flag("label-swaps") ||
                  o.flag("estimate-noise")))
    return wrong(
        "--batch solves stage 1 on the listed, correctly labelled markers with the noise levels "
        "stated: not with --intrinsics, --frames, --outliers, --label-swaps or --estimate-noise");
  if (!o.flag("runs"))
    return wrong(std::string("montecarlo needs --runs N\n") + usage("montecarlo"));
  // --hold-skew: a camera without skew, and a stage 2 that holds it at zero. A family (random)
  // draws each run's rig from the run's seed.
  const auto scenario_for = [&](std::uint64_t run_seed, sim::Scenario& scenario) {
    if (!scenario_option(o, run_seed, scenario, error)) return false;
    if (c.hold_skew) scenario = sim::without_skew(scenario);
    return true;
  };
  if (!parse_count(o, "seed", 1, 0, c.seed, error) || !scenario_for(c.seed, c.scenario) ||
      !blink_fits(c.frames, static_cast<int>(c.scenario.truth.markers.size()), error))
    return false;
  c.family = c.scenario.name == "random" || c.scenario.name == "mems";
  // --rig SEED: one rig of the family for every run; each run draws its own noise and guesses.
  if (o.flag("rig")) {
    if (!c.family) return wrong("--rig applies with --scenario random or mems");
    std::uint64_t rig = 0;
    if (!parse_count(o, "rig", 0, 0, rig, error)) return false;
    c.rig = rig;
  }
  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  if (!parse_count(o, "runs", 0, 1, c.runs, error) || !parse_count(o, "jobs", hw, 1, c.jobs, error))
    return false;
  c.jobs = std::min(c.jobs, c.runs);
  // Each run's rig, drawn here: an option the scenario refuses ends the command before any run.
  c.scenarios.resize(c.runs);
  for (std::uint64_t i = 0; i < c.runs; ++i)
    if (!scenario_for(c.rig.value_or(sim::derive_seed(c.seed, 1000 + i)), c.scenarios[i]))
      return false;
  // --passes N: exactly N (at most kMaxRequestedPasses); by default kDefaultPasses, more while the
  // last gated too many.
  if (!passes_option(o, c.passes, error)) return false;
  if (c.intrinsics && o.flag("passes"))
    return wrong("--passes applies to stage 1 only (without --intrinsics)");
  if (!imu_model_option(o, simulated_imu_model(c.scenario), c.imu_model, error)) return false;
  // --estimate-noise: as sim (the mems family states noise levels 0.5-5x the true ones).
  c.passes.estimate_noise = o.flag("estimate-noise");
  if (c.intrinsics && c.passes.estimate_noise)
    return wrong("--estimate-noise applies to stage 1 only (without --intrinsics)");
  return true;
}

// The camera parameters the campaign's filter estimates: none in stage 1, fu fv cu cv (skew) in
// stage 2, and the lens's four coefficients in place of the skew with estimate_distortion.
int estimated_intrinsics(const Campaign& c) {
  return camera_block(c.intrinsics, c.hold_skew, c.lens);
}
// Their calibration block: the statistics are kept by its parameter groups.
CalibrationLayout layout_of(const Campaign& c) {
  return calibration_layout(int(c.scenario.truth.markers.size()), estimated_intrinsics(c));
}

// The first line printed: what the campaign runs.
void print_campaign_title(const Campaign& c) {
  const std::string rig = c.rig ? ", every run rig " + std::to_string(*c.rig) : "";
  std::printf(
      "mirrorcal montecarlo: scenario '%s'%s%s%s%s%s%s%s%s, %llu runs on %llu jobs, seed %llu\n",
      c.scenario.name.c_str(), rig.c_str(), markers_note(c.scenario).c_str(),
      c.imu_model != ImuModel::kCalibrated
          ? (std::string(", IMU model ") + to_string(c.imu_model)).c_str()
          : "",
      c.passes.estimate_noise ? ", the noise levels estimated" : "",
      c.lens ? ", the lens's coefficients estimated in stage 2" : "",
      !c.intrinsics ? ""
      : c.one_stage ? (c.hold_skew ? " in one stage with the intrinsics (skew held at 0)"
                                   : " in one stage with the intrinsics")
      : c.hold_skew ? " with stage 2 (intrinsics, skew held at 0)"
                    : " with stage 2 (intrinsics)",
      c.frames.enabled ? ", markers detected in rendered frames, " : "",
      c.frames.enabled ? hal::to_string(c.frames.format) : "", (unsigned long long)c.runs,
      (unsigned long long)c.jobs, (unsigned long long)c.seed);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Run i of the campaign into run; run 0 also gives the parameters' names and units (every run has
// the same) to params, which no other thread touches.
void run_one(const Campaign& c, std::uint64_t i, RunOutcome& run, std::vector<ParamInfo>& params) {
  const std::uint64_t seed = sim::derive_seed(c.seed, 1000 + i);
  const sim::Scenario& rig = c.scenarios[i];
  const auto t0 = std::chrono::steady_clock::now();
  // Either stage: the same statistics of whichever run it was (a family's with its data's limit).
  const auto record = [&](const auto& r) {
    run = run_outcome(r, rig, seed, seconds_since(t0), c.family);
    if (i == 0) params = r.result.params;
  };
  // The rig's markers, checked when the options were read: each run reaches its M here.
  with_markers(int(rig.truth.markers.size()), [&](auto markers) {
    constexpr int M = decltype(markers)::value;
    return with_filter_blocks(estimated_intrinsics(c), c.imu_model, [&](auto k, auto imu) {
      constexpr int NK = decltype(k)::value, NI = decltype(imu)::value;
      if constexpr (NK == 0)
        record(run_simulation<M, NI>(rig, seed, {}, c.frames, nullptr, c.passes));
      else
        record(c.one_stage ? run_one_stage_simulation<M, NK, NI>(rig, seed)
                           : run_two_stage_simulation<M, NK, NI>(rig, seed));
      return 0;
    });
  });
#ifdef MIRRORCAL_BATCH
  if (c.batch) run.batch = solve_batch_outcome(rig, seed, c.imu_model);  // stage 1 only
#endif
}

}  // namespace

int cmd_montecarlo(int argc, char** argv) {
  Options o;
  Campaign c;
  std::string error;
  if (!parse(argc, argv, 2,
             {"runs", "jobs", "seed", "out", "scenario", "format", "pixel-sigma", "spot-noise",
              "passes", "timeshift", "distortion", "line-delay", "filter-line-delay", "markers",
              "outliers", "label-swaps", "rig", "imu-model", "blink"},
             {"no-plots", "intrinsics", "hold-skew", "one-stage", "frames", "estimate-distortion",
              "estimate-noise", "identical-leds", "room", "batch"},
             o, error) ||
      !campaign_options(o, c, error))
    return refuse(error);
  std::string dir;
  if (!make_out_dir(o, "out/montecarlo", dir, error)) return refuse(error, 1);
  print_campaign_title(c);

  std::vector<RunOutcome> out(c.runs);
  std::vector<ParamInfo> params;
  const auto t0 = std::chrono::steady_clock::now();
  if (!run_campaign(
          out, c.jobs, [&](std::uint64_t i, RunOutcome& run) { run_one(c, i, run, params); },
          [](double done) { print_progress("runs done:", done); }, error)) {
    end_progress("stopped");
    return refuse(error, 1);
  }
  const double wall = seconds_since(t0);
  end_progress("all runs done");

  const ErrorStatistics st = error_statistics(out, params.size());
  const auto truth = truth_display(c.scenario, estimated_intrinsics(c));
  CampaignFiles files;
  if (!files.open(dir, c.batch, error)) return refuse(error, 1);
  if (c.family)
    report_family_campaign(stdout, files.summary(), out, layout_of(c), st);
  else
    print_paper_tables(stdout, params, c.one_stage, truth, st);
  print_notable_runs(stdout, out);
  if (c.batch) report_batch(stdout, files.batch(), out, params, layout_of(c));
  const DetectionReport detection = combined_detection(out);  // --frames only
  if (c.frames.enabled) print_detection(detection, c.frames.format);
  std::printf("wall time %.1f s (%.2f s per run on %llu jobs)\n", wall,
              wall / double(c.runs) * double(c.jobs), (unsigned long long)c.jobs);
  if (!c.family)
    write_paper_summary(files.summary(), params, truth, st, wall, c.jobs, c.frames, detection);
  write_runs_csv(files.runs(), out, params, c.frames.enabled);
  if (!files.commit(error)) return refuse(error, 1);
  std::printf("wrote %s/summary.csv, %s/runs.csv%s\n", dir.c_str(), dir.c_str(),
              c.batch ? ", batch.csv" : "");
  if (c.plots) {
    const auto pngs = plot_campaign(dir, out, params, st, error);
    if (pngs.empty()) std::fprintf(stderr, "mirrorcal: no plots: %s\n", error.c_str());
    for (const auto& p : pngs) std::printf("plot: %s\n", p.c_str());
  }
  return 0;
}

}  // namespace mirrorcal::app
