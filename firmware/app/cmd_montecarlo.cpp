// mirrorcal montecarlo: N independent simulated calibrations, statistics beside the paper's.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "cli.hpp"
#include "loop_options.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/evaluation/paper_tables.hpp"
#include "mirrorcal/evaluation/plots.hpp"
#include "mirrorcal/evaluation/rendered_markers.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#ifdef MIRRORCAL_BATCH
#include "mirrorcal/evaluation/batch.hpp"
#endif
#include "mirrorcal/sim_host/simulator.hpp"
#include "sim_options.hpp"

namespace mirrorcal::app {

using namespace calibration;
using namespace evaluation;

namespace {

// One run of a campaign, as the reports need it.
struct Outcome {
  std::uint64_t seed = 0;
  std::vector<double> error, sigma;  // display units
  double nees = 0, wall_s = 0;
  std::uint64_t gated = 0, failures = 0;
  int passes = 0;  // passes over the data (more than the default after a bad one)
  double nis_per_dof = 0, sigma_ratio = 1, refinement_step = 0;
  // The ideal-IMU check's statistic over its bound (IdealImuCheck; 0 when not made): above 1,
  // the run said consistent: false for it.
  double imu_check = 0;
  bool suspect = false;        // convergence_warning() would warn a user of this run
  std::uint64_t screened = 0;  // reflections the loop's marker screen withheld, last pass
  ErrorSeries series;
  DetectionReport detection;  // --frames only
  sim::Scenario scenario;     // the run's rig (a family draws one per run)
  std::vector<double> limit;  // data_limit_sigmas(), display units (a family's campaign only)
  // --batch: the filter's error (SI), and the batch solution of the same data and prior: its
  // error (SI), sigma (display units), NEES and CPU time, or why it failed.
  Eigen::VectorXd filter_error;
  Eigen::VectorXd batch_error;
  std::vector<double> batch_sigma;
  double batch_nees = 0.0, batch_cpu_s = 0.0;
  bool batch_converged = false;
  std::string batch_failure;
};

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// The largest |error| / sigma over a run's calibration states.
double worst_sigmas(const Outcome& oc) {
  double worst = 0.0;
  for (std::size_t j = 0; j < oc.error.size(); ++j)
    worst = std::max(worst, std::abs(oc.error[j]) / oc.sigma[j]);
  return worst;
}

// Statistics of a group of a family's runs, by parameter group (CalibrationGroup, the layout's):
// p_b_c in cm, rotation in deg, markers in mm, the time offset in ms, and in stage 2 the camera's
// fu fv cu cv (skew) in px and the lens's coefficients in thousandths.
constexpr std::size_t kGroups = kCalibrationGroups;
const char* const kGroupName[kGroups] = {"p_b_c [cm]",     "rot_b_c [deg]",   "markers [mm]",
                                         "timeshift [ms]", "intrinsics [px]", "lens [1e-3]"};
struct GroupStats {
  using PerGroup = std::array<double, kGroups>;
  CalibrationLayout layout;  // the runs' calibration block
  std::vector<double> nees;
  int beyond = 0, flagged = 0, missed = 0;  // beyond 4 sigma; consistent: false; both but flagged
  PerGroup sq{}, var{}, lim{}, count{}, sq_ok{}, lim_ok{};  // _ok: consistent runs
  // Each consistent run's limit (its group's coordinates' variances summed), squared, summed:
  // effective_runs().
  PerGroup run_lim_sq_ok{};
  // Each consistent run's squared error over its own limit, summed, and how many: a run whose rig
  // the data see poorly (large sigmas and errors) weighs no more than any other here.
  PerGroup per_run_ok{}, count_ok{};

  std::size_t group_of(std::size_t row) const {
    return static_cast<std::size_t>(layout.group_of(static_cast<int>(row)));
  }
  void add(const Outcome& oc) {
    nees.push_back(oc.nees);
    const bool far = worst_sigmas(oc) > 4.0;
    beyond += far ? 1 : 0;
    flagged += oc.suspect ? 1 : 0;
    missed += far && !oc.suspect ? 1 : 0;
    PerGroup run_lim{};
    for (std::size_t j = 0; j < oc.error.size(); ++j) {
      const std::size_t k = group_of(j);
      const double e2 = oc.error[j] * oc.error[j];
      const double l2 = j < oc.limit.size() ? oc.limit[j] * oc.limit[j] : 0.0;
      sq[k] += e2;
      var[k] += oc.sigma[j] * oc.sigma[j];
      lim[k] += l2;
      count[k] += 1.0;
      if (!oc.suspect) {
        sq_ok[k] += e2;
        lim_ok[k] += l2;
        run_lim[k] += l2;
        if (l2 > 0.0) {
          per_run_ok[k] += e2 / l2;
          count_ok[k] += 1.0;
        }
      }
    }
    for (std::size_t k = 0; k < kGroups; ++k) run_lim_sq_ok[k] += run_lim[k] * run_lim[k];
  }
  double mean_nees() const {
    double m = 0;
    for (double v : nees) m += v / double(nees.size());
    return m;
  }
  static double unit(std::size_t k) { return k == 2 ? 10.0 : 1.0; }  // markers in mm
  PerGroup rms() const {
    PerGroup r{};
    for (std::size_t k = 0; k < kGroups; ++k)
      r[k] = count[k] > 0 ? unit(k) * std::sqrt(sq[k] / count[k]) : 0.0;
    return r;
  }
  PerGroup sigma() const {
    PerGroup r{};
    for (std::size_t k = 0; k < kGroups; ++k)
      r[k] = count[k] > 0 ? unit(k) * std::sqrt(var[k] / count[k]) : 0.0;
    return r;
  }
  // The RMS error over the RMS of what the data can hold (data_limit_sigmas()): 1 is the limit.
  PerGroup over_limit(bool consistent_only) const {
    PerGroup r{};
    for (std::size_t k = 0; k < kGroups; ++k) {
      const double e = consistent_only ? sq_ok[k] : sq[k], l = consistent_only ? lim_ok[k] : lim[k];
      r[k] = l > 0.0 ? std::sqrt(e / l) : 0.0;
    }
    return r;
  }

  // How many runs the consistent runs' RMS over the limit rests on, in effect: it weighs each run
  // by its limit's variance, so a few weakly seen rigs can carry a group (the sum of the runs'
  // variances, squared, over the sum of their squares). Chance moves the ratio of a one-coordinate
  // group by about 1 / sqrt(2 n) (docs/campaign/random/README.md, "Over the whole family").
  PerGroup effective_runs() const {
    PerGroup r{};
    for (std::size_t k = 0; k < kGroups; ++k)
      r[k] = run_lim_sq_ok[k] > 0.0 ? lim_ok[k] * lim_ok[k] / run_lim_sq_ok[k] : 0.0;
    return r;
  }

  // The consistent runs' errors, each over its own run's limit, RMS: 1 is the limit.
  PerGroup per_run_over_limit() const {
    PerGroup r{};
    for (std::size_t k = 0; k < kGroups; ++k)
      r[k] = count_ok[k] > 0.0 ? std::sqrt(per_run_ok[k] / count_ok[k]) : 0.0;
    return r;
  }
};

// A slice of a family's runs by one axis the family draws: runs whose rig has() it.
struct FamilyGroup {
  std::string axis, value;
  std::function<bool(const sim::Scenario&)> has;
};

// The slices report_family gives statistics for: all runs, then by mirror, motion, camera rate,
// pixel noise, IMU noise and marker prior, and in stage 2 (groups_used > 4) by the camera's prior.
std::vector<FamilyGroup> family_groups(std::size_t groups_used) {
  std::vector<FamilyGroup> groups = {
      {"all", "all", [](const sim::Scenario&) { return true; }},
      {"mirror", "wall", [](const sim::Scenario& s) { return s.mirror == "wall"; }},
      {"mirror", "floor", [](const sim::Scenario& s) { return s.mirror == "floor"; }},
      {"motion", "slow", [](const sim::Scenario& s) { return s.motion_kind == "slow"; }},
      {"motion", "fast", [](const sim::Scenario& s) { return s.motion_kind == "fast"; }},
      {"camera", "20-40 Hz", [](const sim::Scenario& s) { return s.camera_rate_hz < 40.0; }},
      {"camera", "40-60 Hz", [](const sim::Scenario& s) { return s.camera_rate_hz >= 40.0; }},
      {"pixel noise", "0.25-0.6 px", [](const sim::Scenario& s) { return s.pixel_sigma < 0.6; }},
      {"pixel noise", "0.6-1 px", [](const sim::Scenario& s) { return s.pixel_sigma >= 0.6; }},
      {"imu noise", "1-3x", [](const sim::Scenario& s) { return s.imu_noise_scale < 3.0; }},
      {"imu noise", "3-5x", [](const sim::Scenario& s) { return s.imu_noise_scale >= 3.0; }},
      {"marker prior", "3-6.5 cm", [](const sim::Scenario& s) { return s.priors.marker < 0.065; }},
      {"marker prior", "6.5-10 cm",
       [](const sim::Scenario& s) { return s.priors.marker >= 0.065; }},
  };
  if (groups_used > 4) {  // stage 2: the camera's prior too
    groups.push_back({"camera prior", "20-60 px",
                      [](const sim::Scenario& s) { return s.priors.intrinsics[0] < 60.0; }});
    groups.push_back({"camera prior", "60-100 px",
                      [](const sim::Scenario& s) { return s.priors.intrinsics[0] >= 60.0; }});
  }
  return groups;
}

// summary.csv's header and the table's on stdout, for groups_used parameter groups.
void family_headers(std::size_t groups_used, bool has_limit, std::FILE* f) {
  std::fprintf(f,
               "axis,value,runs,nees_mean,nees_median,runs_beyond_4_sigma,flagged,"
               "unflagged_beyond_4_sigma,rms_p_b_c [cm],rms_rot_b_c [deg],rms_markers [mm],"
               "rms_timeshift [ms],sigma_p_b_c [cm],sigma_rot_b_c [deg],sigma_markers [mm],"
               "sigma_timeshift [ms],over_limit_p_b_c,over_limit_rot_b_c,over_limit_markers,"
               "over_limit_timeshift,consistent_over_limit_p_b_c,consistent_over_limit_rot_b_c,"
               "consistent_over_limit_markers,consistent_over_limit_timeshift");
  for (std::size_t k = 4; k < groups_used; ++k)
    std::fprintf(f, ",rms_%s,sigma_%s", kGroupName[k], kGroupName[k]);
  std::fprintf(f,
               ",consistent_per_run_over_limit_p_b_c,consistent_per_run_over_limit_rot_b_c,"
               "consistent_per_run_over_limit_markers,consistent_per_run_over_limit_timeshift\n");
  std::printf("\n%-13s %-11s %4s %6s %6s %5s %4s %6s |", "axis", "value", "runs", "NEES", "median",
              ">4sig", "flag", "missed");
  for (std::size_t k = 0; k < groups_used; ++k) std::printf(" %15s", kGroupName[k]);
  if (has_limit)
    std::printf(" | %23s | %23s | %23s", "RMS / limit", "consistent / lim", "each run / lim");
  std::printf("\n");
}

// A random family's campaign: no common truth, so statistics of the errors by parameter group
// (groups of them: stage 1's four, and the camera's and the lens's in stage 2), over all runs and
// by each axis the family draws (mirror, motion, camera rate, pixel noise, prior width), into
// summary.csv (f) and on stdout. Stage 1's columns come first, in stage 1's order; stage 2 adds
// the RMS error and sigma of its groups at the end of each row. Only stage 1 has the data's limit.
void report_family(const std::vector<Outcome>& out, std::size_t groups_used,
                   const CalibrationLayout& layout, double nees_lo, double nees_hi, std::FILE* f) {
  const bool has_limit = groups_used == 4;  // over_limit's columns are 0 in stage 2's summary.csv
  family_headers(groups_used, has_limit, f);
  GroupStats::PerGroup effective{};  // of all runs
  for (const FamilyGroup& g : family_groups(groups_used)) {
    GroupStats st;
    st.layout = layout;
    for (const Outcome& oc : out)
      if (g.has(oc.scenario)) st.add(oc);
    if (st.nees.empty()) continue;
    if (g.axis == "all") effective = st.effective_runs();
    const auto rms = st.rms(), sig = st.sigma(), lim = st.over_limit(false),
               lim_ok = st.over_limit(true), per_run = st.per_run_over_limit();
    const double mean = st.mean_nees(), med = median(st.nees);
    std::printf("%-13s %-11s %4zu %6.1f %6.1f %5d %4d %6d |", g.axis.c_str(), g.value.c_str(),
                st.nees.size(), mean, med, st.beyond, st.flagged, st.missed);
    for (std::size_t k = 0; k < groups_used; ++k) std::printf(" %7.4f/%-7.4f", rms[k], sig[k]);
    if (has_limit)
      std::printf(" | %5.2f %5.2f %5.2f %5.2f | %5.2f %5.2f %5.2f %5.2f | %5.2f %5.2f %5.2f %5.2f",
                  lim[0], lim[1], lim[2], lim[3], lim_ok[0], lim_ok[1], lim_ok[2], lim_ok[3],
                  per_run[0], per_run[1], per_run[2], per_run[3]);
    std::printf("\n");
    std::fprintf(f,
                 "%s,%s,%zu,%.4f,%.4f,%d,%d,%d,%.5f,%.5f,%.5f,%.6f,%.5f,%.5f,%.5f,%.6f,%.4f,%.4f,"
                 "%.4f,%.4f,%.4f,%.4f,%.4f,%.4f",
                 g.axis.c_str(), g.value.c_str(), st.nees.size(), mean, med, st.beyond, st.flagged,
                 st.missed, rms[0], rms[1], rms[2], rms[3], sig[0], sig[1], sig[2], sig[3], lim[0],
                 lim[1], lim[2], lim[3], lim_ok[0], lim_ok[1], lim_ok[2], lim_ok[3]);
    for (std::size_t k = 4; k < groups_used; ++k) std::fprintf(f, ",%.5f,%.5f", rms[k], sig[k]);
    std::fprintf(f, ",%.4f,%.4f,%.4f,%.4f\n", per_run[0], per_run[1], per_run[2], per_run[3]);
  }
  std::fprintf(f, "# nees_99_lo=%.4f nees_99_hi=%.4f\n", nees_lo, nees_hi);
  std::printf(
      "(by parameter group: RMS error / root-mean-square reported sigma; >4sig: runs with a "
      "state beyond 4 sigma, flag: runs that said consistent: false, missed: runs beyond 4 sigma "
      "that did not;%s NEES of the calibration states, its 99 %% interval over the runs "
      "%.2f..%.2f)\n",
      has_limit ? " RMS / limit: the RMS error over the RMS of what the data can hold, the sigmas "
                  "of a filter linearised at the truth on noise-free data, for p, rotation, "
                  "markers, time offset; consistent / lim: the same over the runs that said "
                  "consistent: true; each run / lim: those runs' errors each over its own run's "
                  "limit, RMS, so that a rig the data see poorly weighs no more than another;"
                : "",
      nees_lo, nees_hi);
  if (has_limit) {
    std::printf(
        "consistent / lim rests on, in effect, so many runs (it weighs each by its "
        "limit's variance; chance alone moves it by about 1/sqrt(2n)):");
    for (std::size_t k = 0; k < groups_used; ++k)
      std::printf(" %s %.0f (+-%.2f)", kGroupName[k], effective[k],
                  effective[k] > 0.0 ? 1.0 / std::sqrt(2.0 * effective[k]) : 0.0);
    std::printf("\n");
  }
}

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

#ifdef MIRRORCAL_BATCH
// The batch solution of run i's data and prior (those run_simulation draws from its seed), into
// oc.
template <int M>
void run_batch(const sim::Scenario& rs, std::uint64_t run_seed, ImuModel imu_model, Outcome& oc) {
  const sim::SimData data = sim::simulate(rs, run_seed);
  const sim::RecordingPriors priors = sim::from_prior(sim::simulation_prior<M>(rs, data, run_seed),
                                                      rs.gravity_n, rs.pixel_sigma, false);
  CalibrationResult r;
  BatchReport report;
  if (!solve_batch(simulated_batch_input(rs, data, priors, 0, imu_model), {}, r, report,
                   oc.batch_failure))
    return;
  const TruthError t = truth_error(r, sim::recording_truth(rs));
  oc.batch_error = t.error;
  oc.batch_nees = t.nees;
  for (std::size_t j = 0; j < r.params.size(); ++j)
    oc.batch_sigma.push_back(r.sigma[j] * r.params[j].scale);
  oc.batch_cpu_s = report.cpu_s;
  oc.batch_converged = report.converged;
}
#endif

// Run i of the campaign into oc; the parameters' names and units into params (from the first run
// to finish, under mu).
void run_one(const Campaign& c, std::uint64_t i, Outcome& oc, std::vector<ParamInfo>& params,
             std::mutex& mu) {
  const std::uint64_t run_seed = sim::derive_seed(c.seed, 1000 + i);
  const sim::Scenario& rs = c.scenarios[i];
  const auto t = std::chrono::steady_clock::now();
  // Either stage: the same statistics of whichever run it was.
  const auto record = [&](const auto& r) {
    oc.seed = run_seed;
    oc.scenario = rs;
    oc.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    const auto& last = r.history.back();
    for (std::size_t j = 0; j < r.result.params.size(); ++j) {
      oc.error.push_back(last.error(int(j)) * r.result.params[j].scale);
      oc.sigma.push_back(last.sigma(int(j)) * r.result.params[j].scale);
    }
    oc.nees = last.nees;
    oc.filter_error = last.error.template cast<double>();
    oc.gated = r.filter_counters.markers_gated;
    oc.suspect = !convergence_warning(r.result).empty();
    for (const std::uint64_t n : r.result.markers_screened) oc.screened += n;
    oc.passes = r.result.passes;
    oc.nis_per_dof = r.result.nis_per_dof;
    oc.sigma_ratio = r.result.sigma_ratio;
    oc.refinement_step = r.result.refinement_step_sigmas;
    const IdealImuCheck& check = r.result.imu.ideal_check;
    oc.imu_check = check.made ? check.statistic / check.bound : 0.0;
    oc.failures = r.filter_counters.failures;
    oc.series = error_series(r.history, r.result.params);
    if (c.family && !c.intrinsics) {  // stage 1's limit (stage 2's is not computed yet)
      using State = typename std::decay_t<decltype(r)>::State;
      const std::vector<double> limit =
          data_limit_sigmas<State::kMarkers, State::kImuIntrinsics>(rs, run_seed);
      for (std::size_t j = 0; j < limit.size(); ++j)
        oc.limit.push_back(limit[j] * r.result.params[j].scale);
    }
    oc.detection = r.detection;
    std::lock_guard<std::mutex> lock(mu);
    if (params.empty()) params = r.result.params;
  };
  // The rig's markers, checked when the options were read: each run reaches its M here.
  with_markers(int(rs.truth.markers.size()), [&](auto markers) {
    constexpr int M = decltype(markers)::value;
    return with_filter_blocks(estimated_intrinsics(c), c.imu_model, [&](auto k, auto imu) {
      constexpr int NK = decltype(k)::value, NI = decltype(imu)::value;
      if constexpr (NK == 0) {
        record(run_simulation<M, NI>(rs, run_seed, {}, c.frames, nullptr, c.passes));
#ifdef MIRRORCAL_BATCH
        if (c.batch) run_batch<M>(rs, run_seed, c.imu_model, oc);
#endif
      } else {
        record(c.one_stage ? run_one_stage_simulation<M, NK, NI>(rs, run_seed)
                           : run_two_stage_simulation<M, NK, NI>(rs, run_seed));
      }
      return 0;
    });
  });
}

// The campaign's runs on c.jobs threads, into out (one per run) and params. False, with the
// message, when a run's temporary store could not be written (a full $TMPDIR): no more runs start.
bool run_campaign(const Campaign& c, std::vector<Outcome>& out, std::vector<ParamInfo>& params,
                  std::string& store_error) {
  std::atomic<std::uint64_t> next{0}, done{0};
  std::mutex mu;
  auto worker = [&] {
    for (std::uint64_t i; (i = next++) < c.runs;) {
      try {
        run_one(c, i, out[i], params, mu);
      } catch (const files::StoreError& e) {  // a full $TMPDIR: no more runs, main says why
        std::lock_guard<std::mutex> lock(mu);
        if (store_error.empty()) store_error = e.what();
        next = c.runs;
        return;
      }
      std::lock_guard<std::mutex> lock(mu);
      print_progress("runs done:", double(++done) / double(c.runs));
    }
  };
  std::vector<std::thread> pool;
  for (std::uint64_t j = 0; j < c.jobs; ++j) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  return store_error.empty();
}

// Each parameter's error over the runs (mean, variance, mean square) and reported variance, and
// the average NEES of the calibration states with its 95 % interval.
struct ErrorStatistics {
  std::vector<double> mean, var, mean_square, sigma_square;
  double nees = 0, nees_lo = 0, nees_hi = 0;
};

ErrorStatistics error_statistics(const std::vector<Outcome>& out, std::size_t np) {
  const double n = double(out.size());
  ErrorStatistics st;
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
  st.mean = mean;
  st.var = std_;
  st.mean_square = rms;
  st.sigma_square = sig;
  st.nees = nees;
  st.nees_lo = chi2_quantile(0.025, n * double(np)) / n;
  st.nees_hi = chi2_quantile(0.975, n * double(np)) / n;
  return st;
}

// The paper's row of parameter j: none for the lens's coefficients (estimate_distortion), which
// follow cv where the skew's row is.
const PaperRow& paper_row(const std::vector<ParamInfo>& params, std::size_t j) {
  static const PaperRow kNotInPaper{NAN, NAN};
  return params[j].group == CalibrationGroup::kLens ? kNotInPaper : paper_tables()[j];
}

// Where the average NEES of `runs` runs of np states lies with probability 99 % (chi-square with
// runs * np degrees of freedom, divided by runs), and the verdict on one such average.
struct NeesInterval {
  double lo, hi;
  const char* verdict(double nees) const {
    return nees >= lo && nees <= hi ? "consistent" : "NOT consistent";
  }
};
NeesInterval average_nees_interval99(double runs, std::size_t np) {
  return {chi2_quantile(0.005, runs * double(np)) / runs,
          chi2_quantile(0.995, runs * double(np)) / runs};
}

// The average NEES over the runs that said consistent: true, against its own 99 % interval, when
// some did not: those were warned of, and one run that diverged moves the average over all runs by
// orders of magnitude, so that this is the verdict on the calibrations a user would have kept.
void print_trusted_nees(const std::vector<Outcome>& out, std::size_t np) {
  double sum = 0.0;
  std::size_t trusted = 0;
  for (const auto& oc : out)
    if (!oc.suspect) {
      sum += oc.nees;
      ++trusted;
    }
  if (trusted == 0 || trusted == out.size()) return;
  const double nees = sum / double(trusted);
  const NeesInterval i = average_nees_interval99(double(trusted), np);
  std::printf(
      "over the %zu runs that said consistent: true: %.2f (99 %% interval %.2f..%.2f): %s\n",
      trusted, nees, i.lo, i.hi, i.verdict(nees));
}

// A family's verdict: the average NEES over the rigs against its 99 % interval, then
// report_family's tables (also into summary).
void report_family_campaign(const Campaign& c, const std::vector<Outcome>& out, std::size_t np,
                            double nees, std::FILE* summary) {
  std::vector<double> each;
  for (const auto& oc : out) each.push_back(oc.nees);
  const NeesInterval i = average_nees_interval99(double(c.runs), np);
  std::printf(
      "\naverage NEES of the %zu calibration states over %llu rigs: %.2f (99 %% interval "
      "%.2f..%.2f), median of the runs %.2f: %s\n",
      np, (unsigned long long)c.runs, nees, i.lo, i.hi, median(each), i.verdict(nees));
  print_trusted_nees(out, np);
  const std::size_t groups_used = !c.intrinsics ? 4 : c.lens ? 6 : 5;
  const int markers = int(c.scenario.truth.markers.size());
  report_family(out, groups_used, calibration_layout(markers, estimated_intrinsics(c)), i.lo, i.hi,
                summary);
}

// Tables I-III: each parameter's truth, the paper's final value and sigma, and ours over the runs.
void print_paper_tables(const Campaign& c, const std::vector<ParamInfo>& params,
                        const std::vector<double>& truth, const ErrorStatistics& st) {
  const std::size_t np = params.size();
  const double n = double(c.runs);
  std::printf("\nTables I%s: final estimates over %llu runs (ours) beside the paper's\n",
              !c.intrinsics ? " and II"
              : c.one_stage ? ", II and III (one stage)"
                            : ", II and III (after stage 2)",
              (unsigned long long)c.runs);
  std::printf("%-17s %-4s %9s | %9s %7s | %9s %8s %8s %8s | %s\n", "param", "unit", "truth",
              "paper", "sigma", "mean", "std", "rms err", "filter s", "rms < paper sigma");
  int beaten = 0, in_paper = 0;
  for (std::size_t j = 0; j < np; ++j) {
    const double r = std::sqrt(st.mean_square[j]);
    const PaperRow& p = paper_row(params, j);
    const bool compared = !std::isnan(p.sigma), ok = r < p.sigma;
    in_paper += compared ? 1 : 0;
    beaten += ok ? 1 : 0;
    std::printf("%-17s %-4s %9.3f | %9.2f %7.2f | %9.4f %8.4f %8.4f %8.4f | %s\n",
                params[j].name.c_str(), params[j].unit.c_str(), truth[j], p.final_value, p.sigma,
                truth[j] + st.mean[j], std::sqrt(st.var[j]), r, std::sqrt(st.sigma_square[j]),
                !compared ? "(not in the paper)"
                : ok      ? "yes"
                          : "NO");
  }
  std::printf("\n%d of the paper's %d parameters below its sigma\n", beaten, in_paper);
  std::printf(
      "average NEES of the %zu calibration states: %.2f (95 %% interval %.2f..%.2f, 99 %% "
      "%.2f..%.2f): %s\n",
      np, st.nees, st.nees_lo, st.nees_hi, chi2_quantile(0.005, n * double(np)) / n,
      chi2_quantile(0.995, n * double(np)) / n,
      st.nees >= st.nees_lo && st.nees <= st.nees_hi ? "consistent" : "NOT consistent");
}

// The runs that took more passes than the default, and those a user would have been warned of.
void print_notable_runs(const std::vector<Outcome>& out) {
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
        "runs given more passes because a pass looked suspect (more than 0.5 %% of the markers "
        "gated, or a normalised innovation squared well above 1; passes made): %s\n",
        extra.c_str());
  if (!suspects.empty())
    std::printf("runs a user would have been warned of (consistent: false; included above): %s\n",
                suspects.c_str());
  std::string not_ideal;
  for (std::size_t i = 0; i < out.size(); ++i)
    if (out[i].imu_check > 1.0) {
      char run[64];
      std::snprintf(run, sizeof run, "%s%zu (%.2f)", not_ideal.empty() ? "" : ", ", i,
                    out[i].imu_check);
      not_ideal += run;
    }
  if (!not_ideal.empty())
    std::printf(
        "runs whose ideal-IMU check failed (model calibrated; its statistic over its bound): %s\n",
        not_ideal.c_str());
}

// summary.csv of a campaign on one rig: Tables I-III's columns, then the NEES and the detection.
void write_paper_summary(std::FILE* f, const Campaign& c, const std::vector<ParamInfo>& params,
                         const std::vector<double>& truth, const ErrorStatistics& st, double wall,
                         const DetectionReport& detection) {
  std::fprintf(f, "parameter,unit,truth,mean_estimate,std,rms_error,paper_std\n");
  for (std::size_t j = 0; j < params.size(); ++j)
    std::fprintf(f, "%s,%s,%.6f,%.6f,%.6f,%.6f,%.6f\n", params[j].name.c_str(),
                 params[j].unit.c_str(), truth[j], truth[j] + st.mean[j], std::sqrt(st.var[j]),
                 std::sqrt(st.mean_square[j]), paper_row(params, j).sigma);
  std::fprintf(f,
               "# nees_mean=%.4f nees_95_lo=%.4f nees_95_hi=%.4f runs=%llu wall_s=%.2f jobs=%llu\n",
               st.nees, st.nees_lo, st.nees_hi, (unsigned long long)c.runs, wall,
               (unsigned long long)c.jobs);
  if (c.frames.enabled)
    std::fprintf(f,
                 "# frames=%s markers_drawn=%llu markers_labelled=%llu wrong_labels=%llu "
                 "centroid_rms_px=%.4f centroid_max_px=%.4f ms_per_frame=%.3f\n",
                 hal::to_string(c.frames.format), (unsigned long long)detection.markers_drawn,
                 (unsigned long long)detection.markers_labelled,
                 (unsigned long long)detection.wrong_labels, detection.centroid_rms_px,
                 detection.centroid_max_px, detection.ms_per_frame);
}

#ifdef MIRRORCAL_BATCH
// --batch: each group's RMS error of the filter over the batch's on the same runs, the batch's own
// NEES and both's time, on stdout; batch.csv: a row per run of the batch's errors and sigmas.
void report_batch(const Campaign& c, const std::vector<Outcome>& out,
                  const std::vector<ParamInfo>& params, std::FILE* f) {
  const int markers = static_cast<int>(c.scenario.truth.markers.size());
  BatchComparison cmp(calibration_layout(markers, 0));
  std::vector<double> filter_s, batch_s;
  int unconverged = 0;
  std::fprintf(f, "run,seed,batch_nees,batch_cpu_s,batch_converged,filter_wall_s");
  for (const auto& p : params) std::fprintf(f, ",err_%s [%s]", p.name.c_str(), p.unit.c_str());
  for (const auto& p : params) std::fprintf(f, ",sigma_%s [%s]", p.name.c_str(), p.unit.c_str());
  std::fprintf(f, "\n");
  for (std::size_t i = 0; i < out.size(); ++i) {
    const Outcome& oc = out[i];
    if (!oc.batch_failure.empty()) {
      std::printf("run %zu: the batch failed: %s\n", i, oc.batch_failure.c_str());
      continue;
    }
    cmp.add(oc.filter_error, oc.batch_error, oc.batch_nees);
    filter_s.push_back(oc.wall_s);
    batch_s.push_back(oc.batch_cpu_s);
    unconverged += oc.batch_converged ? 0 : 1;
    std::fprintf(f, "%zu,%llu,%.4f,%.3f,%d,%.3f", i, (unsigned long long)oc.seed, oc.batch_nees,
                 oc.batch_cpu_s, oc.batch_converged ? 1 : 0, oc.wall_s);
    for (std::size_t j = 0; j < params.size(); ++j)
      std::fprintf(f, ",%.6g", oc.batch_error(static_cast<long>(j)) * params[j].scale);
    for (const double sg : oc.batch_sigma) std::fprintf(f, ",%.6g", sg);
    std::fprintf(f, "\n");
  }
  if (cmp.runs() == 0) return;
  // SI to the family tables' units: cm, deg, mm, ms.
  constexpr double kUnit[] = {100.0, 180.0 / M_PI, 1000.0, 1000.0};
  std::printf(
      "\nthe filter against the batch maximum-likelihood solution of the same data and priors "
      "(%zu runs):\n  %-15s %11s %11s %13s\n",
      cmp.runs(), "group", "filter RMS", "batch RMS", "filter/batch");
  for (std::size_t k = 0; k < 4; ++k) {
    const auto g = static_cast<CalibrationGroup>(k);
    std::printf("  %-15s %11.5f %11.5f %13.3f\n", kGroupName[k], cmp.filter_rms(g) * kUnit[k],
                cmp.batch_rms(g) * kUnit[k], cmp.ratio(g));
  }
  const NeesInterval i = average_nees_interval99(double(cmp.runs()), params.size());
  std::printf(
      "  the batch's average NEES %.2f (99 %% interval %.2f..%.2f): %s; %d of its solves did not "
      "converge\n  median time per run: the filter %.2f s (wall, passes and refinement), the "
      "batch %.2f s (CPU)\n",
      cmp.mean_batch_nees(), i.lo, i.hi, i.verdict(cmp.mean_batch_nees()), unconverged,
      median(filter_s), median(batch_s));
}
#endif

// runs.csv: a row per run, its errors, sigmas, counters, rig and (--frames) detection.
void write_runs_csv(std::FILE* f, const std::vector<Outcome>& out,
                    const std::vector<ParamInfo>& params, bool frames) {
  std::fprintf(f, "run,seed");
  for (const auto& p : params) std::fprintf(f, ",err_%s [%s]", p.name.c_str(), p.unit.c_str());
  for (const auto& p : params) std::fprintf(f, ",sigma_%s [%s]", p.name.c_str(), p.unit.c_str());
  std::fprintf(f,
               ",nees,markers_gated,filter_failures,wall_s,passes,nis_per_dof,sigma_ratio,"
               "refinement_step,consistent,markers_screened");
  std::fprintf(f,
               ",mirror,motion,camera_hz,pixel_sigma,imu_noise_scale,prior_marker [cm],"
               "prior_p_b_c [cm],prior_rot_b_c [deg]");
  if (frames)
    std::fprintf(f, ",markers_drawn,markers_labelled,wrong_labels,centroid_rms_px,centroid_max_px");
  std::fprintf(f, "\n");
  for (std::size_t i = 0; i < out.size(); ++i) {
    std::fprintf(f, "%zu,%llu", i, (unsigned long long)out[i].seed);
    for (double e : out[i].error) std::fprintf(f, ",%.6g", e);
    for (double e : out[i].sigma) std::fprintf(f, ",%.6g", e);
    std::fprintf(f, ",%.4f,%llu,%llu,%.3f,%d,%.4f,%.4f,%.4f", out[i].nees,
                 (unsigned long long)out[i].gated, (unsigned long long)out[i].failures,
                 out[i].wall_s, out[i].passes, out[i].nis_per_dof, out[i].sigma_ratio,
                 out[i].refinement_step);
    std::fprintf(f, ",%d,%llu", out[i].suspect ? 0 : 1, (unsigned long long)out[i].screened);
    const sim::Scenario& rs = out[i].scenario;
    std::fprintf(f, ",%s,%s,%.2f,%.3f,%.2f,%.2f,%.2f,%.2f", rs.mirror.c_str(),
                 rs.motion_kind.c_str(), rs.camera_rate_hz, rs.pixel_sigma, rs.imu_noise_scale,
                 100.0 * rs.priors.marker, 100.0 * rs.priors.p_b_c,
                 rs.priors.rot_b_c * 180.0 / M_PI);
    if (frames) {
      const DetectionReport& d = out[i].detection;
      std::fprintf(f, ",%llu,%llu,%llu,%.4f,%.4f", (unsigned long long)d.markers_drawn,
                   (unsigned long long)d.markers_labelled, (unsigned long long)d.wrong_labels,
                   d.centroid_rms_px, d.centroid_max_px);
    }
    std::fprintf(f, "\n");
  }
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

  std::vector<Outcome> out(c.runs);
  std::vector<ParamInfo> params;
  const auto t0 = std::chrono::steady_clock::now();
  if (!run_campaign(c, out, params, error)) {
    end_progress("stopped");
    return refuse(error, 1);
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  end_progress("all runs done");

  const std::size_t np = params.size();
  const auto truth = truth_display(c.scenario, estimated_intrinsics(c));
  const ErrorStatistics st = error_statistics(out, np);
  // summary.csv and runs.csv, written together when both are complete.
  files::OutputSet results;
  std::string err;
  std::FILE* const summary = results.add(dir + "/summary.csv", err);
  std::FILE* const runs_csv = summary != nullptr ? results.add(dir + "/runs.csv", err) : nullptr;
  std::FILE* const batch_csv =
      c.batch && runs_csv != nullptr ? results.add(dir + "/batch.csv", err) : nullptr;
  if (runs_csv == nullptr || (c.batch && batch_csv == nullptr)) return refuse(err, 1);
  if (c.family)
    report_family_campaign(c, out, np, st.nees, summary);
  else
    print_paper_tables(c, params, truth, st);
  print_notable_runs(out);
#ifdef MIRRORCAL_BATCH
  if (c.batch) report_batch(c, out, params, batch_csv);
#endif
  DetectionReport detection;
  if (c.frames.enabled) {
    std::vector<DetectionReport> each;
    for (const auto& oc : out) each.push_back(oc.detection);
    detection = combine(each);
    print_detection(detection, c.frames.format);
  }
  std::printf("wall time %.1f s (%.2f s per run on %llu jobs)\n", wall,
              wall / double(c.runs) * double(c.jobs), (unsigned long long)c.jobs);
  if (!c.family) write_paper_summary(summary, c, params, truth, st, wall, detection);
  write_runs_csv(runs_csv, out, params, c.frames.enabled);
  if (!results.commit(err)) return refuse(err, 1);
  std::printf("wrote %s/summary.csv, %s/runs.csv%s\n", dir.c_str(), dir.c_str(),
              c.batch ? ", batch.csv" : "");
  if (c.plots) {
    std::vector<ErrorSeries> series;
    for (auto& oc : out) series.push_back(std::move(oc.series));
    const auto pngs = plot_errors(dir, "mirrorcal Monte Carlo, " + std::to_string(c.runs) + " runs",
                                  params, series, st.nees_lo, st.nees_hi, err);
    if (pngs.empty()) std::fprintf(stderr, "mirrorcal: no plots: %s\n", err.c_str());
    for (const auto& p : pngs) std::printf("plot: %s\n", p.c_str());
  }
  return 0;
}

}  // namespace mirrorcal::app
