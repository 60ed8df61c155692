#include "mirrorcal/evaluation/campaign_report.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "mirrorcal/calibration/report.hpp"
#include "mirrorcal/evaluation/paper_tables.hpp"

namespace mirrorcal::evaluation {

namespace {

double median(const std::vector<double>& values) {
  return calibration::sample_stats(values).median;
}

// summary.csv's header and the table's in text, for `groups` parameter groups.
void family_headers(std::FILE* text, std::FILE* summary, std::size_t groups, bool has_limit) {
  std::fprintf(summary,
               "axis,value,runs,nees_mean,nees_median,runs_beyond_4_sigma,flagged,"
               "unflagged_beyond_4_sigma,rms_p_b_c [cm],rms_rot_b_c [deg],rms_markers [mm],"
               "rms_timeshift [ms],sigma_p_b_c [cm],sigma_rot_b_c [deg],sigma_markers [mm],"
               "sigma_timeshift [ms],over_limit_p_b_c,over_limit_rot_b_c,over_limit_markers,"
               "over_limit_timeshift,consistent_over_limit_p_b_c,consistent_over_limit_rot_b_c,"
               "consistent_over_limit_markers,consistent_over_limit_timeshift");
  for (std::size_t k = 4; k < groups; ++k)
    std::fprintf(summary, ",rms_%s,sigma_%s", group_label(k), group_label(k));
  std::fprintf(summary,
               ",consistent_per_run_over_limit_p_b_c,consistent_per_run_over_limit_rot_b_c,"
               "consistent_per_run_over_limit_markers,consistent_per_run_over_limit_timeshift\n");
  std::fprintf(text, "\n%-13s %-11s %4s %6s %6s %5s %4s %6s |", "axis", "value", "runs", "NEES",
               "median", ">4sig", "flag", "missed");
  for (std::size_t k = 0; k < groups; ++k) std::fprintf(text, " %15s", group_label(k));
  if (has_limit)
    std::fprintf(text, " | %23s | %23s | %23s", "RMS / limit", "consistent / lim",
                 "each run / lim");
  std::fprintf(text, "\n");
}

// The paper's row of parameter j: none for the lens's coefficients (estimate_distortion), which
// follow cv where the skew's row is.
const PaperRow& paper_row(const std::vector<ParamInfo>& params, std::size_t j) {
  static const PaperRow kNotInPaper{NAN, NAN};
  return params[j].group == CalibrationGroup::kLens ? kNotInPaper : paper_tables()[j];
}

// "a, b, c" of the runs that pass, each as item(i, run) writes it.
template <class Pass, class Item>
std::string run_list(const std::vector<RunOutcome>& runs, Pass pass, Item item) {
  std::string list;
  for (std::size_t i = 0; i < runs.size(); ++i)
    if (pass(runs[i])) list += (list.empty() ? "" : ", ") + item(i, runs[i]);
  return list;
}

}  // namespace

bool CampaignFiles::open(const std::string& dir, bool batch, std::string& error) {
  summary_ = set_.add(dir + "/summary.csv", error);
  runs_ = summary_ != nullptr ? set_.add(dir + "/runs.csv", error) : nullptr;
  batch_ = batch && runs_ != nullptr ? set_.add(dir + "/batch.csv", error) : nullptr;
  return runs_ != nullptr && (!batch || batch_ != nullptr);
}

void report_family_campaign(std::FILE* text, std::FILE* summary,
                            const std::vector<RunOutcome>& runs, const CalibrationLayout& layout,
                            const ErrorStatistics& st) {
  std::vector<double> each;
  for (const RunOutcome& run : runs) each.push_back(run.nees);
  const std::size_t np = st.states();
  const NeesInterval i = average_nees_interval(double(runs.size()), np, kTail99);
  std::fprintf(text,
               "\naverage NEES of the %zu calibration states over %llu rigs: %.2f (99 %% interval "
               "%.2f..%.2f), median of the runs %.2f: %s\n",
               np, (unsigned long long)runs.size(), st.nees, i.lo, i.hi, median(each),
               i.verdict(st.nees));
  // One run that diverged moves the average over all runs by orders of magnitude; those a user
  // was warned of aside, this is the verdict on the calibrations a user would have kept.
  const TrustedNees trusted = trusted_nees(runs);
  if (trusted.runs > 0 && trusted.runs < runs.size()) {
    const NeesInterval t = average_nees_interval(double(trusted.runs), np, kTail99);
    std::fprintf(
        text,
        "over the %zu runs that said consistent: true: %.2f (99 %% interval %.2f..%.2f): %s\n",
        trusted.runs, trusted.nees, t.lo, t.hi, t.verdict(trusted.nees));
  }
  report_family(text, summary, runs, layout, i);
}

void report_family(std::FILE* text, std::FILE* summary, const std::vector<RunOutcome>& runs,
                   const CalibrationLayout& layout, const NeesInterval& nees99) {
  const std::size_t groups = reported_groups(layout);
  const bool has_limit = groups == 4;  // over_limit's columns are 0 in stage 2's summary.csv
  family_headers(text, summary, groups, has_limit);
  GroupStatistics::PerGroup effective{};  // of all runs
  for (const FamilyGroup& g : family_groups(groups)) {
    GroupStatistics st(layout);
    for (const RunOutcome& run : runs)
      if (g.has(run.scenario)) st.add(run);
    if (st.runs() == 0) continue;
    if (g.axis == "all") effective = st.effective_runs();
    const auto rms = st.rms(), sig = st.sigma(), lim = st.over_limit(false),
               lim_ok = st.over_limit(true), per_run = st.per_run_over_limit();
    const double mean = st.mean_nees(), med = st.median_nees();
    std::fprintf(text, "%-13s %-11s %4zu %6.1f %6.1f %5d %4d %6d |", g.axis.c_str(),
                 g.value.c_str(), st.runs(), mean, med, st.beyond(), st.flagged(), st.missed());
    for (std::size_t k = 0; k < groups; ++k) std::fprintf(text, " %7.4f/%-7.4f", rms[k], sig[k]);
    if (has_limit)
      std::fprintf(text,
                   " | %5.2f %5.2f %5.2f %5.2f | %5.2f %5.2f %5.2f %5.2f | %5.2f %5.2f %5.2f %5.2f",
                   lim[0], lim[1], lim[2], lim[3], lim_ok[0], lim_ok[1], lim_ok[2], lim_ok[3],
                   per_run[0], per_run[1], per_run[2], per_run[3]);
    std::fprintf(text, "\n");
    std::fprintf(summary,
                 "%s,%s,%zu,%.4f,%.4f,%d,%d,%d,%.5f,%.5f,%.5f,%.6f,%.5f,%.5f,%.5f,%.6f,%.4f,%.4f,"
                 "%.4f,%.4f,%.4f,%.4f,%.4f,%.4f",
                 g.axis.c_str(), g.value.c_str(), st.runs(), mean, med, st.beyond(), st.flagged(),
                 st.missed(), rms[0], rms[1], rms[2], rms[3], sig[0], sig[1], sig[2], sig[3],
                 lim[0], lim[1], lim[2], lim[3], lim_ok[0], lim_ok[1], lim_ok[2], lim_ok[3]);
    for (std::size_t k = 4; k < groups; ++k) std::fprintf(summary, ",%.5f,%.5f", rms[k], sig[k]);
    std::fprintf(summary, ",%.4f,%.4f,%.4f,%.4f\n", per_run[0], per_run[1], per_run[2], per_run[3]);
  }
  std::fprintf(summary, "# nees_99_lo=%.4f nees_99_hi=%.4f\n", nees99.lo, nees99.hi);
  std::fprintf(
      text,
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
      nees99.lo, nees99.hi);
  if (has_limit) {
    std::fprintf(text,
                 "consistent / lim rests on, in effect, so many runs (it weighs each by its "
                 "limit's variance; chance alone moves it by about 1/sqrt(2n)):");
    for (std::size_t k = 0; k < groups; ++k)
      std::fprintf(text, " %s %.0f (+-%.2f)", group_label(k), effective[k],
                   effective[k] > 0.0 ? 1.0 / std::sqrt(2.0 * effective[k]) : 0.0);
    std::fprintf(text, "\n");
  }
}

void print_paper_tables(std::FILE* text, const std::vector<ParamInfo>& params, bool one_stage,
                        const std::vector<double>& truth, const ErrorStatistics& st) {
  const std::size_t np = params.size();
  const bool stage1 = std::none_of(params.begin(), params.end(), [](const ParamInfo& p) {
    return p.group == CalibrationGroup::kIntrinsics;
  });
  std::fprintf(text, "\nTables I%s: final estimates over %llu runs (ours) beside the paper's\n",
               stage1      ? " and II"
               : one_stage ? ", II and III (one stage)"
                           : ", II and III (after stage 2)",
               (unsigned long long)st.runs);
  std::fprintf(text, "%-17s %-4s %9s | %9s %7s | %9s %8s %8s %8s | %s\n", "param", "unit", "truth",
               "paper", "sigma", "mean", "std", "rms err", "filter s", "rms < paper sigma");
  int beaten = 0, in_paper = 0;
  for (std::size_t j = 0; j < np; ++j) {
    const double r = std::sqrt(st.mean_square[j]);
    const PaperRow& p = paper_row(params, j);
    const bool compared = !std::isnan(p.sigma), ok = r < p.sigma;
    in_paper += compared ? 1 : 0;
    beaten += ok ? 1 : 0;
    std::fprintf(text, "%-17s %-4s %9.3f | %9.2f %7.2f | %9.4f %8.4f %8.4f %8.4f | %s\n",
                 params[j].name.c_str(), params[j].unit.c_str(), truth[j], p.final_value, p.sigma,
                 truth[j] + st.mean[j], std::sqrt(st.var[j]), r, std::sqrt(st.sigma_square[j]),
                 !compared ? "(not in the paper)"
                 : ok      ? "yes"
                           : "NO");
  }
  const NeesInterval i99 = average_nees_interval(double(st.runs), np, kTail99);
  std::fprintf(text, "\n%d of the paper's %d parameters below its sigma\n", beaten, in_paper);
  std::fprintf(text,
               "average NEES of the %zu calibration states: %.2f (95 %% interval %.2f..%.2f, 99 %% "
               "%.2f..%.2f): %s\n",
               np, st.nees, st.nees95.lo, st.nees95.hi, i99.lo, i99.hi, st.nees95.verdict(st.nees));
}

void print_notable_runs(std::FILE* text, const std::vector<RunOutcome>& runs) {
  const auto index = [](std::size_t i, const RunOutcome&) { return std::to_string(i); };
  const std::string suspects = run_list(
      runs, [](const RunOutcome& run) { return run.suspect; }, index);
  const std::string extra = run_list(
      runs, [](const RunOutcome& run) { return run.passes > calibration::kDefaultPasses; },
      [](std::size_t i, const RunOutcome& run) {
        return std::to_string(i) + " (" + std::to_string(run.passes) + ")";
      });
  if (!extra.empty())
    std::fprintf(text,
                 "runs given more passes because a pass looked suspect (more than 0.5 %% of the "
                 "markers gated, a normalised innovation squared well above 1, or few markers "
                 "labelled in the frames; passes made): %s\n",
                 extra.c_str());
  if (!suspects.empty())
    std::fprintf(text,
                 "runs a user would have been warned of (consistent: false; included above): %s\n",
                 suspects.c_str());
  std::string not_ideal;
  for (std::size_t i = 0; i < runs.size(); ++i)
    if (runs[i].imu_check > 1.0) {
      char run[64];
      std::snprintf(run, sizeof run, "%s%zu (%.2f)", not_ideal.empty() ? "" : ", ", i,
                    runs[i].imu_check);
      not_ideal += run;
    }
  if (!not_ideal.empty())
    std::fprintf(text,
                 "runs whose ideal-IMU check failed (model calibrated; its statistic over its "
                 "bound): %s\n",
                 not_ideal.c_str());
}

void write_paper_summary(std::FILE* summary, const std::vector<ParamInfo>& params,
                         const std::vector<double>& truth, const ErrorStatistics& st, double wall_s,
                         std::uint64_t jobs, const FrameMode& frames,
                         const DetectionReport& detection) {
  std::fprintf(summary, "parameter,unit,truth,mean_estimate,std,rms_error,paper_std\n");
  for (std::size_t j = 0; j < params.size(); ++j)
    std::fprintf(summary, "%s,%s,%.6f,%.6f,%.6f,%.6f,%.6f\n", params[j].name.c_str(),
                 params[j].unit.c_str(), truth[j], truth[j] + st.mean[j], std::sqrt(st.var[j]),
                 std::sqrt(st.mean_square[j]), paper_row(params, j).sigma);
  std::fprintf(summary,
               "# nees_mean=%.4f nees_95_lo=%.4f nees_95_hi=%.4f runs=%llu wall_s=%.2f jobs=%llu\n",
               st.nees, st.nees95.lo, st.nees95.hi, (unsigned long long)st.runs, wall_s,
               (unsigned long long)jobs);
  if (frames.enabled)
    std::fprintf(summary,
                 "# frames=%s markers_drawn=%llu markers_labelled=%llu wrong_labels=%llu "
                 "centroid_rms_px=%.4f centroid_max_px=%.4f ms_per_frame=%.3f\n",
                 hal::to_string(frames.format), (unsigned long long)detection.markers_drawn,
                 (unsigned long long)detection.markers_labelled,
                 (unsigned long long)detection.wrong_labels, detection.centroid_rms_px,
                 detection.centroid_max_px, detection.ms_per_frame);
}

void report_batch(std::FILE* text, std::FILE* batch_csv, const std::vector<RunOutcome>& runs,
                  const std::vector<ParamInfo>& params, const CalibrationLayout& layout) {
  BatchComparison cmp(layout);
  std::vector<double> filter_s, batch_s;
  int unconverged = 0;
  std::fprintf(batch_csv, "run,seed,batch_nees,batch_cpu_s,batch_converged,filter_wall_s");
  for (const auto& p : params)
    std::fprintf(batch_csv, ",err_%s [%s]", p.name.c_str(), p.unit.c_str());
  for (const auto& p : params)
    std::fprintf(batch_csv, ",sigma_%s [%s]", p.name.c_str(), p.unit.c_str());
  std::fprintf(batch_csv, "\n");
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const RunOutcome& run = runs[i];
    const BatchOutcome& b = run.batch;
    if (!b.failure.empty()) {
      std::fprintf(text, "run %zu: the batch failed: %s\n", i, b.failure.c_str());
      continue;
    }
    cmp.add(run.filter_error, b.error, b.nees);
    filter_s.push_back(run.wall_s);
    batch_s.push_back(b.cpu_s);
    unconverged += b.converged ? 0 : 1;
    std::fprintf(batch_csv, "%zu,%llu,%.4f,%.3f,%d,%.3f", i, (unsigned long long)run.seed, b.nees,
                 b.cpu_s, b.converged ? 1 : 0, run.wall_s);
    for (std::size_t j = 0; j < params.size(); ++j)
      std::fprintf(batch_csv, ",%.6g", b.error(static_cast<long>(j)) * params[j].scale);
    for (const double sg : b.sigma) std::fprintf(batch_csv, ",%.6g", sg);
    std::fprintf(batch_csv, "\n");
  }
  if (cmp.runs() == 0) return;
  // SI to the family tables' units: cm, deg, mm, ms.
  constexpr double kUnit[] = {100.0, 180.0 / M_PI, 1000.0, 1000.0};
  std::fprintf(text,
               "\nthe filter against the batch maximum-likelihood solution of the same data and "
               "priors (%zu runs):\n  %-15s %11s %11s %13s\n",
               cmp.runs(), "group", "filter RMS", "batch RMS", "filter/batch");
  for (std::size_t k = 0; k < 4; ++k) {
    const auto g = static_cast<CalibrationGroup>(k);
    std::fprintf(text, "  %-15s %11.5f %11.5f %13.3f\n", group_label(k),
                 cmp.filter_rms(g) * kUnit[k], cmp.batch_rms(g) * kUnit[k], cmp.ratio(g));
  }
  const NeesInterval i = average_nees_interval(double(cmp.runs()), params.size(), kTail99);
  std::fprintf(
      text,
      "  the batch's average NEES %.2f (99 %% interval %.2f..%.2f): %s; %d of its solves did not "
      "converge\n  median time per run: the filter %.2f s (wall, passes and refinement), the "
      "batch %.2f s (CPU)\n",
      cmp.mean_batch_nees(), i.lo, i.hi, i.verdict(cmp.mean_batch_nees()), unconverged,
      median(filter_s), median(batch_s));
}

void write_runs_csv(std::FILE* runs_csv, const std::vector<RunOutcome>& runs,
                    const std::vector<ParamInfo>& params, bool frames) {
  std::FILE* const f = runs_csv;
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
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const RunOutcome& run = runs[i];
    std::fprintf(f, "%zu,%llu", i, (unsigned long long)run.seed);
    for (double e : run.error) std::fprintf(f, ",%.6g", e);
    for (double e : run.sigma) std::fprintf(f, ",%.6g", e);
    std::fprintf(f, ",%.4f,%llu,%llu,%.3f,%d,%.4f,%.4f,%.4f", run.nees,
                 (unsigned long long)run.gated, (unsigned long long)run.failures, run.wall_s,
                 run.passes, run.nis_per_dof, run.sigma_ratio, run.refinement_step);
    std::fprintf(f, ",%d,%llu", run.suspect ? 0 : 1, (unsigned long long)run.screened);
    const sim::Scenario& rs = run.scenario;
    std::fprintf(f, ",%s,%s,%.2f,%.3f,%.2f,%.2f,%.2f,%.2f", rs.mirror.c_str(),
                 rs.motion_kind.c_str(), rs.camera_rate_hz, rs.pixel_sigma, rs.imu_noise_scale,
                 100.0 * rs.priors.marker, 100.0 * rs.priors.p_b_c,
                 rs.priors.rot_b_c * 180.0 / M_PI);
    if (frames) {
      const DetectionReport& d = run.detection;
      std::fprintf(f, ",%llu,%llu,%llu,%.4f,%.4f", (unsigned long long)d.markers_drawn,
                   (unsigned long long)d.markers_labelled, (unsigned long long)d.wrong_labels,
                   d.centroid_rms_px, d.centroid_max_px);
    }
    std::fprintf(f, "\n");
  }
}

std::vector<std::string> plot_campaign(const std::string& dir, std::vector<RunOutcome>& runs,
                                       const std::vector<ParamInfo>& params,
                                       const ErrorStatistics& st, std::string& error) {
  std::vector<ErrorSeries> series;
  for (RunOutcome& run : runs) series.push_back(std::move(run.series));
  return plot_errors(dir, "mirrorcal Monte Carlo, " + std::to_string(runs.size()) + " runs", params,
                     series, st.nees95.lo, st.nees95.hi, error);
}

}  // namespace mirrorcal::evaluation
