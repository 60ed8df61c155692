// mirrorcal montecarlo: N independent simulated calibrations, statistics beside the paper's.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cli.hpp"
#include "loop_options.hpp"
#include "mirrorcal/sim_host/simulator.hpp"
#include "plots.hpp"
#include "report.hpp"
#include "sim_frames.hpp"
#include "sim_run.hpp"

namespace mirrorcal::app {

int cmd_montecarlo(int argc, char** argv) {
  const Options o = parse(
      argc, argv, 2,
      {"runs", "jobs", "seed", "out", "scenario", "format", "pixel-sigma", "spot-noise", "passes"},
      {"no-plots", "intrinsics", "hold-skew", "one-stage", "frames"});
  const bool intrinsics = o.flag("intrinsics"), hold_skew = o.flag("hold-skew"),
             one_stage = o.flag("one-stage");
  if ((hold_skew || one_stage) && !intrinsics)
    fail("--hold-skew and --one-stage apply with --intrinsics");
  const FrameMode frames = frame_mode_option(o);
  if (intrinsics && frames.enabled)
    fail("--intrinsics runs on listed markers (not yet with --frames)");
  if (!o.flag("runs")) fail(std::string("montecarlo needs --runs N\n") + usage());
  // --hold-skew: a camera without skew, and a stage 2 that holds it at zero.
  const sim::Scenario s = hold_skew ? without_skew(scenario_option(o)) : scenario_option(o);
  const std::uint64_t runs = parse_count(o, "runs", 0, 1);
  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  const std::uint64_t jobs = std::min<std::uint64_t>(parse_count(o, "jobs", hw, 1), runs);
  const std::uint64_t seed = parse_count(o, "seed", 1, 0);
  // --passes N: exactly N; by default kDefaultPasses, more while the last gated too many.
  const Passes passes = o.flag("passes")
                            ? Passes::exactly(static_cast<int>(parse_count(o, "passes", 0, 1)))
                            : Passes{};
  if (intrinsics && o.flag("passes"))
    fail("--passes applies to stage 1 only (without --intrinsics)");
  const std::string dir = make_out_dir(o, "out/montecarlo");
  std::printf("mirrorcal montecarlo: scenario '%s'%s%s%s, %llu runs on %llu jobs, seed %llu\n",
              s.name.c_str(),
              !intrinsics ? ""
              : one_stage ? (hold_skew ? " in one stage with the intrinsics (skew held at 0)"
                                       : " in one stage with the intrinsics")
              : hold_skew ? " with stage 2 (intrinsics, skew held at 0)"
                          : " with stage 2 (intrinsics)",
              frames.enabled ? ", markers detected in rendered frames, " : "",
              frames.enabled ? hal::to_string(frames.format) : "", (unsigned long long)runs,
              (unsigned long long)jobs, (unsigned long long)seed);

  struct Outcome {
    std::uint64_t seed = 0;
    std::vector<double> error, sigma;  // display units
    double nees = 0, wall_s = 0;
    std::uint64_t gated = 0, failures = 0;
    int passes = 0;        // passes over the data (more than the default after a bad one)
    bool suspect = false;  // convergence_warning() would warn a user of this run
    ErrorSeries series;
    DetectionReport detection;  // --frames only
  };
  std::vector<Outcome> out(runs);
  std::vector<ParamInfo> params;
  std::atomic<std::uint64_t> next{0}, done{0};
  std::mutex mu;
  const auto t0 = std::chrono::steady_clock::now();
  auto worker = [&] {
    for (std::uint64_t i; (i = next++) < runs;) {
      const std::uint64_t run_seed = sim::derive_seed(seed, 1000 + i);
      const auto t = std::chrono::steady_clock::now();
      Outcome& oc = out[i];
      // Either stage: the same statistics of whichever run it was.
      const auto record = [&](const auto& r) {
        oc.seed = run_seed;
        oc.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
        const auto& last = r.history.back();
        for (std::size_t j = 0; j < r.result.params.size(); ++j) {
          oc.error.push_back(last.error(int(j)) * r.result.params[j].scale);
          oc.sigma.push_back(last.sigma(int(j)) * r.result.params[j].scale);
        }
        oc.nees = last.nees;
        oc.gated = r.filter_counters.markers_gated;
        oc.suspect = !convergence_warning(r.result).empty();
        oc.passes = r.result.passes;
        oc.failures = r.filter_counters.failures;
        oc.series = error_series(r.history, r.result.params);
        oc.detection = r.detection;
        std::lock_guard<std::mutex> lock(mu);
        if (params.empty()) params = r.result.params;
      };
      if (intrinsics && hold_skew)
        record(one_stage ? run_one_stage_simulation<4>(s, run_seed)
                         : run_two_stage_simulation<4>(s, run_seed));
      else if (intrinsics)
        record(one_stage ? run_one_stage_simulation<5>(s, run_seed)
                         : run_two_stage_simulation<5>(s, run_seed));
      else
        record(run_simulation(s, run_seed, {}, frames, nullptr, passes));
      std::lock_guard<std::mutex> lock(mu);
      print_progress("runs done:", double(++done) / double(runs));
    }
  };
  std::vector<std::thread> pool;
  for (std::uint64_t j = 0; j < jobs; ++j) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::fprintf(stderr, "\n");

  const std::size_t np = params.size();
  const auto truth = truth_display(s, !intrinsics ? 0 : hold_skew ? 4 : 5);
  const double n = double(runs);
  std::vector<double> mean(np, 0), std_(np, 0), rms(np, 0), sig(np, 0);
  for (const auto& oc : out)
    for (std::size_t j = 0; j < np; ++j) {
      mean[j] += oc.error[j] / n;
      rms[j] += oc.error[j] * oc.error[j] / n;
      sig[j] += oc.sigma[j] * oc.sigma[j] / n;
    }
  for (const auto& oc : out)
    for (std::size_t j = 0; j < np; ++j)
      std_[j] += (oc.error[j] - mean[j]) * (oc.error[j] - mean[j]) / std::max(1.0, n - 1.0);
  double nees = 0;
  for (const auto& oc : out) nees += oc.nees / n;
  const double nees_lo = chi2_quantile(0.025, n * double(np)) / n;
  const double nees_hi = chi2_quantile(0.975, n * double(np)) / n;

  std::printf("\nTables I%s: final estimates over %llu runs (ours) beside the paper's\n",
              !intrinsics ? " and II"
              : one_stage ? ", II and III (one stage)"
                          : ", II and III (after stage 2)",
              (unsigned long long)runs);
  std::printf("%-7s %-4s %9s | %9s %7s | %9s %8s %8s %8s | %s\n", "param", "unit", "truth", "paper",
              "sigma", "mean", "std", "rms err", "filter s", "rms < paper sigma");
  int beaten = 0;
  for (std::size_t j = 0; j < np; ++j) {
    const double r = std::sqrt(rms[j]);
    const PaperRow& p = paper_tables()[j];
    const bool ok = r < p.sigma;
    beaten += ok ? 1 : 0;
    std::printf("%-7s %-4s %9.3f | %9.2f %7.2f | %9.4f %8.4f %8.4f %8.4f | %s\n",
                params[j].name.c_str(), params[j].unit.c_str(), truth[j], p.final_value, p.sigma,
                truth[j] + mean[j], std::sqrt(std_[j]), r, std::sqrt(sig[j]), ok ? "yes" : "NO");
  }
  std::printf("\n%d of %zu parameters below the paper's sigma\n", beaten, np);
  std::printf(
      "average NEES of the %zu calibration states: %.2f (95 %% interval %.2f..%.2f, 99 %% "
      "%.2f..%.2f): %s\n",
      np, nees, nees_lo, nees_hi, chi2_quantile(0.005, n * double(np)) / n,
      chi2_quantile(0.995, n * double(np)) / n,
      nees >= nees_lo && nees <= nees_hi ? "consistent" : "NOT consistent");
  std::string suspects;
  for (std::size_t i = 0; i < out.size(); ++i)
    if (out[i].suspect) suspects += (suspects.empty() ? "" : ", ") + std::to_string(i);
  std::string extra;
  for (std::size_t i = 0; i < out.size(); ++i)
    if (out[i].passes > kDefaultPasses)
      extra += (extra.empty() ? "" : ", ") + std::to_string(i) + " (" +
               std::to_string(out[i].passes) + ")";
  if (!extra.empty())
    std::printf(
        "runs given more passes because a pass gated more than 0.5 %% of the markers (passes "
        "made): %s\n",
        extra.c_str());
  if (!suspects.empty())
    std::printf(
        "runs a user would have been warned of (more than 0.5 %% of the markers gated; included "
        "above): %s\n",
        suspects.c_str());
  DetectionReport detection;
  if (frames.enabled) {
    std::vector<DetectionReport> each;
    for (const auto& oc : out) each.push_back(oc.detection);
    detection = combine(each);
    print_detection(detection, frames.format);
  }
  std::printf("wall time %.1f s (%.2f s per run on %llu jobs)\n", wall, wall / n * double(jobs),
              (unsigned long long)jobs);

  std::FILE* f = std::fopen((dir + "/summary.csv").c_str(), "w");
  if (!f) fail("cannot write " + dir + "/summary.csv", 1);
  std::fprintf(f, "parameter,unit,truth,mean_estimate,std,rms_error,paper_std\n");
  for (std::size_t j = 0; j < np; ++j)
    std::fprintf(f, "%s,%s,%.6f,%.6f,%.6f,%.6f,%.6f\n", params[j].name.c_str(),
                 params[j].unit.c_str(), truth[j], truth[j] + mean[j], std::sqrt(std_[j]),
                 std::sqrt(rms[j]), paper_tables()[j].sigma);
  std::fprintf(f,
               "# nees_mean=%.4f nees_95_lo=%.4f nees_95_hi=%.4f runs=%llu wall_s=%.2f jobs=%llu\n",
               nees, nees_lo, nees_hi, (unsigned long long)runs, wall, (unsigned long long)jobs);
  if (frames.enabled)
    std::fprintf(f,
                 "# frames=%s markers_drawn=%llu markers_labelled=%llu wrong_labels=%llu "
                 "centroid_rms_px=%.4f centroid_max_px=%.4f ms_per_frame=%.3f\n",
                 hal::to_string(frames.format), (unsigned long long)detection.markers_drawn,
                 (unsigned long long)detection.markers_labelled,
                 (unsigned long long)detection.wrong_labels, detection.centroid_rms_px,
                 detection.centroid_max_px, detection.ms_per_frame);
  std::fclose(f);
  f = std::fopen((dir + "/runs.csv").c_str(), "w");
  if (!f) fail("cannot write " + dir + "/runs.csv", 1);
  std::fprintf(f, "run,seed");
  for (const auto& p : params) std::fprintf(f, ",err_%s [%s]", p.name.c_str(), p.unit.c_str());
  for (const auto& p : params) std::fprintf(f, ",sigma_%s [%s]", p.name.c_str(), p.unit.c_str());
  std::fprintf(f, ",nees,markers_gated,filter_failures,wall_s,passes");
  if (frames.enabled)
    std::fprintf(f, ",markers_drawn,markers_labelled,wrong_labels,centroid_rms_px,centroid_max_px");
  std::fprintf(f, "\n");
  for (std::size_t i = 0; i < out.size(); ++i) {
    std::fprintf(f, "%zu,%llu", i, (unsigned long long)out[i].seed);
    for (double e : out[i].error) std::fprintf(f, ",%.6g", e);
    for (double e : out[i].sigma) std::fprintf(f, ",%.6g", e);
    std::fprintf(f, ",%.4f,%llu,%llu,%.3f,%d", out[i].nees, (unsigned long long)out[i].gated,
                 (unsigned long long)out[i].failures, out[i].wall_s, out[i].passes);
    if (frames.enabled) {
      const DetectionReport& d = out[i].detection;
      std::fprintf(f, ",%llu,%llu,%llu,%.4f,%.4f", (unsigned long long)d.markers_drawn,
                   (unsigned long long)d.markers_labelled, (unsigned long long)d.wrong_labels,
                   d.centroid_rms_px, d.centroid_max_px);
    }
    std::fprintf(f, "\n");
  }
  std::fclose(f);
  std::printf("wrote %s/summary.csv, %s/runs.csv\n", dir.c_str(), dir.c_str());
  if (!o.flag("no-plots")) {
    std::vector<ErrorSeries> series;
    for (auto& oc : out) series.push_back(std::move(oc.series));
    std::string err;
    const auto pngs = plot_errors(dir, "mirrorcal Monte Carlo, " + std::to_string(runs) + " runs",
                                  params, series, nees_lo, nees_hi, err);
    if (pngs.empty()) std::fprintf(stderr, "mirrorcal: no plots: %s\n", err.c_str());
    for (const auto& p : pngs) std::printf("plot: %s\n", p.c_str());
  }
  return 0;
}

}  // namespace mirrorcal::app
