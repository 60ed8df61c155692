// A Monte Carlo campaign's statistics and reports as a library, on small hand-made runs: every
// figure against the same figure computed here on its own (group RMS, RMS over sigma and over the
// data's limit, the NEES and its chi-square interval, the runs beyond 4 sigma and those flagged,
// the family's slices by axis), and summary.csv, runs.csv and batch.csv read back.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include "mirrorcal/evaluation/campaign_report.hpp"

namespace mirrorcal::evaluation {
namespace {

// The paper's rig in stage 1: three markers, 16 states, p_b_c [0, 3), rot [3, 6), markers [6, 15),
// t_d 15 (written out here, not taken from the layout).
constexpr int kMarkers = 3;
constexpr std::size_t kStates = 16;
struct Range {
  std::size_t begin, end;
  double unit;  // display units to the group's: markers cm to mm
};
const Range kGroupRange[4] = {{0, 3, 1.0}, {3, 6, 1.0}, {6, 15, 10.0}, {15, 16, 1.0}};

sim::Scenario rig(const std::string& mirror, const std::string& motion, double camera_hz,
                  double pixel_sigma, double imu_noise, double marker_prior_m,
                  double camera_prior_px = 80.0) {
  sim::Scenario s;
  s.mirror = mirror;
  s.motion_kind = motion;
  s.camera_rate_hz = camera_hz;
  s.pixel_sigma = pixel_sigma;
  s.imu_noise_scale = imu_noise;
  s.priors.marker = marker_prior_m;
  s.priors.intrinsics[0] = camera_prior_px;
  return s;
}

// A run whose state j has error scale * f(j), sigma `sigma` and data limit `limit`.
RunOutcome run_of(std::uint64_t seed, double scale, double sigma, double nees, bool suspect = false,
                  double limit = 0.0) {
  RunOutcome r;
  r.seed = seed;
  r.nees = nees;
  r.suspect = suspect;
  for (std::size_t j = 0; j < kStates; ++j) {
    r.error.push_back(scale * (double(j % 5) - 1.5));
    r.sigma.push_back(sigma * (1.0 + 0.1 * double(j)));
    if (limit > 0.0) r.limit.push_back(limit * (1.0 + 0.05 * double(j)));
  }
  r.scenario = rig("wall", "slow", 30.0, 0.5, 2.0, 0.05);
  return r;
}

// Everything written to a temporary file, as text.
struct Capture {
  std::FILE* f = std::tmpfile();
  ~Capture() { std::fclose(f); }
  std::string text() const {
    std::fflush(f);
    std::rewind(f);
    std::string s;
    for (int c; (c = std::fgetc(f)) != EOF;) s += char(c);
    return s;
  }
  std::vector<std::string> lines() const {
    std::vector<std::string> out;
    std::stringstream ss(text());
    for (std::string l; std::getline(ss, l);) out.push_back(l);
    return out;
  }
};

std::vector<std::string> cells(const std::string& row) {
  std::vector<std::string> out;
  std::stringstream ss(row);
  for (std::string c; std::getline(ss, c, ',');) out.push_back(c);
  return out;
}

// The column of header named `name`.
std::size_t column(const std::string& header, const std::string& name) {
  const auto h = cells(header);
  const auto it = std::find(h.begin(), h.end(), name);
  EXPECT_NE(it, h.end()) << name;
  return std::size_t(it - h.begin());
}

// A group's RMS of x (error or sigma) over runs, in the group's unit, directly.
double group_rms(const std::vector<RunOutcome>& runs, const Range& g,
                 std::vector<double> RunOutcome::*x) {
  double sum = 0.0, n = 0.0;
  for (const RunOutcome& r : runs)
    for (std::size_t j = g.begin; j < g.end; ++j) {
      sum += (r.*x)[j] * (r.*x)[j];
      n += 1.0;
    }
  return g.unit * std::sqrt(sum / n);
}

// The quantile of the chi-square distribution with k degrees of freedom, from its distribution
// function (the regularised lower incomplete gamma function by its series) by bisection.
double chi2_cdf(double x, double k) {
  const double a = k / 2.0, y = x / 2.0;
  double term = 1.0 / a, sum = term;
  for (int n = 1; n < 10000 && term > sum * 1e-16; ++n) {
    term *= y / (a + n);
    sum += term;
  }
  return std::exp(a * std::log(y) - y - std::lgamma(a)) * sum;
}
double chi2_exact_quantile(double p, double k) {
  double lo = 0.0, hi = 10.0 * k;
  for (int i = 0; i < 200; ++i) (chi2_cdf(0.5 * (lo + hi), k) < p ? lo : hi) = 0.5 * (lo + hi);
  return 0.5 * (lo + hi);
}

TEST(CampaignStatistics, ChiSquareIntervalOfTheAverageNees) {
  // The tables' values: chi-square with 100 degrees of freedom, 0.5 % and 99.5 %: 67.328, 140.169.
  const NeesInterval i = average_nees_interval(10.0, 10, kTail99);
  EXPECT_NEAR(i.lo, 6.7328, 0.0067);
  EXPECT_NEAR(i.hi, 14.0169, 0.014);
  // Wilson and Hilferty's approximation, written out: k (1 - 2/(9k) + z sqrt(2/(9k)))^3 / runs.
  const double k = 4.0 * 16.0, a = 2.0 / (9.0 * k), z975 = 1.959963984540054;
  const NeesInterval j = average_nees_interval(4.0, 16, kTail95);
  EXPECT_NEAR(j.hi, k * std::pow(1.0 - a + z975 * std::sqrt(a), 3.0) / 4.0, 1e-6);
  EXPECT_NEAR(j.lo, k * std::pow(1.0 - a - z975 * std::sqrt(a), 3.0) / 4.0, 1e-6);
  // And against the exact quantiles, to the approximation's accuracy.
  for (const double runs : {2.0, 10.0, 100.0}) {
    const NeesInterval n = average_nees_interval(runs, 16, kTail99);
    EXPECT_NEAR(n.lo * runs / chi2_exact_quantile(0.005, runs * 16.0), 1.0, 0.01) << runs;
    EXPECT_NEAR(n.hi * runs / chi2_exact_quantile(0.995, runs * 16.0), 1.0, 0.01) << runs;
  }
  EXPECT_STREQ(j.verdict(16.0), "consistent");
  EXPECT_STREQ(j.verdict(j.hi * 1.01), "NOT consistent");
  EXPECT_STREQ(j.verdict(j.lo * 0.99), "NOT consistent");
}

TEST(CampaignStatistics, ErrorStatisticsOverTheRuns) {
  const std::vector<RunOutcome> runs = {run_of(1, 1.0, 1.0, 12.0), run_of(2, -2.0, 2.0, 20.0),
                                        run_of(3, 0.5, 1.5, 16.0)};
  const ErrorStatistics st = error_statistics(runs, kStates);
  EXPECT_EQ(st.runs, 3u);
  EXPECT_EQ(st.states(), kStates);
  for (std::size_t j = 0; j < kStates; ++j) {
    const double e[3] = {runs[0].error[j], runs[1].error[j], runs[2].error[j]};
    const double mean = (e[0] + e[1] + e[2]) / 3.0;
    double var = 0.0, ms = 0.0, ss = 0.0;
    for (int r = 0; r < 3; ++r) {
      var += (e[r] - mean) * (e[r] - mean) / 2.0;
      ms += e[r] * e[r] / 3.0;
      ss += runs[std::size_t(r)].sigma[j] * runs[std::size_t(r)].sigma[j] / 3.0;
    }
    EXPECT_NEAR(st.mean[j], mean, 1e-12);
    EXPECT_NEAR(st.var[j], var, 1e-12);
    EXPECT_NEAR(st.mean_square[j], ms, 1e-12);
    EXPECT_NEAR(st.sigma_square[j], ss, 1e-12);
  }
  EXPECT_NEAR(st.nees, 16.0, 1e-12);
  EXPECT_NEAR(st.nees95.lo, average_nees_interval(3.0, kStates, kTail95).lo, 1e-12);
  EXPECT_NEAR(st.nees95.hi * 3.0 / chi2_exact_quantile(0.975, 48.0), 1.0, 0.01);
}

TEST(CampaignStatistics, TrustedNeesLeavesTheFlaggedRunsOut) {
  const std::vector<RunOutcome> runs = {run_of(1, 1.0, 1.0, 10.0), run_of(2, 1.0, 1.0, 1e6, true),
                                        run_of(3, 1.0, 1.0, 20.0)};
  const TrustedNees t = trusted_nees(runs);
  EXPECT_EQ(t.runs, 2u);
  EXPECT_DOUBLE_EQ(t.nees, 15.0);
  EXPECT_EQ(trusted_nees({run_of(1, 1.0, 1.0, 10.0, true)}).runs, 0u);
}

TEST(CampaignStatistics, WorstSigmasAndTheRunsBeyondFourSigma) {
  RunOutcome far = run_of(1, 0.1, 1.0, 16.0);
  far.error[7] = -4.5 * far.sigma[7];
  EXPECT_DOUBLE_EQ(worst_sigmas(far), 4.5);
  RunOutcome near = run_of(2, 0.1, 1.0, 16.0);
  near.error[2] = 3.9 * near.sigma[2];
  EXPECT_DOUBLE_EQ(worst_sigmas(near), 3.9);
  RunOutcome flagged_far = far, flagged_near = near;
  flagged_far.suspect = flagged_near.suspect = true;

  GroupStatistics st(calibration_layout(kMarkers, 0));
  for (const RunOutcome& r : {far, near, flagged_far, flagged_near, far}) st.add(r);
  EXPECT_EQ(st.runs(), 5u);
  EXPECT_EQ(st.beyond(), 3);   // far twice, flagged_far
  EXPECT_EQ(st.flagged(), 2);  // flagged_far, flagged_near
  EXPECT_EQ(st.missed(), 2);   // far twice: beyond 4 sigma and not flagged
}

TEST(CampaignStatistics, GroupRmsAndSigmaAndNees) {
  const std::vector<RunOutcome> runs = {run_of(1, 1.0, 1.0, 10.0), run_of(2, -0.3, 0.5, 30.0),
                                        run_of(3, 2.0, 3.0, 14.0), run_of(4, 0.7, 1.0, 18.0)};
  GroupStatistics st(calibration_layout(kMarkers, 0));
  for (const RunOutcome& r : runs) st.add(r);
  const auto rms = st.rms(), sigma = st.sigma();
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_NEAR(rms[k], group_rms(runs, kGroupRange[k], &RunOutcome::error), 1e-12) << k;
    EXPECT_NEAR(sigma[k], group_rms(runs, kGroupRange[k], &RunOutcome::sigma), 1e-12) << k;
    EXPECT_GT(rms[k] / sigma[k], 0.0);
  }
  EXPECT_EQ(rms[4], 0.0);  // no camera group in stage 1
  EXPECT_NEAR(st.mean_nees(), 18.0, 1e-12);
  EXPECT_NEAR(st.median_nees(), 16.0, 1e-12);  // (14 + 18) / 2
  st.add(run_of(5, 1.0, 1.0, 11.0));
  EXPECT_NEAR(st.median_nees(), 14.0, 1e-12);
}

TEST(CampaignStatistics, ErrorsOverTheDataLimit) {
  // Two consistent runs of different limits, and a flagged one that the consistent figures omit.
  const std::vector<RunOutcome> runs = {run_of(1, 1.0, 1.0, 16.0, false, 0.5),
                                        run_of(2, -0.4, 1.0, 16.0, false, 2.0),
                                        run_of(3, 5.0, 1.0, 16.0, true, 1.0)};
  GroupStatistics st(calibration_layout(kMarkers, 0));
  for (const RunOutcome& r : runs) st.add(r);
  const auto all = st.over_limit(false), ok = st.over_limit(true), each = st.per_run_over_limit(),
             effective = st.effective_runs();
  for (std::size_t k = 0; k < 4; ++k) {
    const Range& g = kGroupRange[k];
    double e_all = 0, l_all = 0, e_ok = 0, l_ok = 0, ratio_ok = 0, n_ok = 0, sum_l = 0, sum_l2 = 0;
    for (const RunOutcome& r : runs) {
      double l_run = 0.0;
      for (std::size_t j = g.begin; j < g.end; ++j) {
        const double e2 = r.error[j] * r.error[j], l2 = r.limit[j] * r.limit[j];
        e_all += e2;
        l_all += l2;
        if (r.suspect) continue;
        e_ok += e2;
        l_ok += l2;
        l_run += l2;
        ratio_ok += e2 / l2;
        n_ok += 1.0;
      }
      if (!r.suspect) {
        sum_l += l_run;
        sum_l2 += l_run * l_run;
      }
    }
    EXPECT_NEAR(all[k], std::sqrt(e_all / l_all), 1e-12) << k;
    EXPECT_NEAR(ok[k], std::sqrt(e_ok / l_ok), 1e-12) << k;
    EXPECT_NEAR(each[k], std::sqrt(ratio_ok / n_ok), 1e-12) << k;
    EXPECT_NEAR(effective[k], sum_l * sum_l / sum_l2, 1e-12) << k;
    EXPECT_GT(effective[k], 1.0);  // two runs, one weighing 16 times the other
    EXPECT_LT(effective[k], 1.3);
  }
  // Without limits (stage 2) the ratios are 0.
  GroupStatistics none(calibration_layout(kMarkers, 5));
  none.add(run_of(1, 1.0, 1.0, 16.0));
  EXPECT_EQ(none.over_limit(false)[0], 0.0);
  EXPECT_EQ(none.per_run_over_limit()[0], 0.0);
}

TEST(CampaignStatistics, ReportedGroupsFollowTheCameraBlock) {
  EXPECT_EQ(reported_groups(calibration_layout(kMarkers, 0)), 4u);
  EXPECT_EQ(reported_groups(calibration_layout(kMarkers, 4)), 5u);
  EXPECT_EQ(reported_groups(calibration_layout(kMarkers, 5)), 5u);
  EXPECT_EQ(reported_groups(calibration_layout(kMarkers, 8)), 6u);
  EXPECT_STREQ(group_label(2), "markers [mm]");
  EXPECT_STREQ(group_label(5), "lens [1e-3]");
}

TEST(CampaignStatistics, FamilySlicesPartitionEachAxis) {
  const std::vector<sim::Scenario> rigs = {rig("wall", "slow", 25.0, 0.3, 1.5, 0.04, 30.0),
                                           rig("floor", "fast", 55.0, 0.9, 4.0, 0.09),
                                           rig("wall", "fast", 40.0, 0.6, 3.0, 0.065, 60.0),
                                           rig("floor", "slow", 39.0, 0.59, 2.9, 0.064)};
  for (const std::size_t groups : {std::size_t(4), std::size_t(5)}) {
    const std::vector<FamilyGroup> slices = family_groups(groups);
    ASSERT_EQ(slices.size(), groups == 4 ? 13u : 15u);
    EXPECT_EQ(slices.front().axis, "all");
    for (const sim::Scenario& s : rigs) {
      // Every rig in "all" and in exactly one value of each other axis.
      std::vector<std::string> axes;
      for (const FamilyGroup& g : slices)
        if (g.has(s)) axes.push_back(g.axis);
      std::vector<std::string> distinct = axes;
      std::sort(distinct.begin(), distinct.end());
      distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
      EXPECT_EQ(axes.size(), distinct.size());
      EXPECT_EQ(distinct.size(), groups == 4 ? 7u : 8u);
    }
  }
  // The first rig, slice by slice, as the labels say.
  std::vector<std::string> values;
  for (const FamilyGroup& g : family_groups(5))
    if (g.has(rigs[0])) values.push_back(g.value);
  EXPECT_EQ(values, (std::vector<std::string>{"all", "wall", "slow", "20-40 Hz", "0.25-0.6 px",
                                              "1-3x", "3-6.5 cm", "20-60 px"}));
  values.clear();
  for (const FamilyGroup& g : family_groups(5))
    if (g.has(rigs[2])) values.push_back(g.value);
  EXPECT_EQ(values, (std::vector<std::string>{"all", "wall", "fast", "40-60 Hz", "0.6-1 px", "3-5x",
                                              "6.5-10 cm", "60-100 px"}));
}

TEST(CampaignReport, FamilySummaryRowsReadBack) {
  std::vector<RunOutcome> runs = {run_of(1, 1.0, 1.0, 10.0, false, 1.0),
                                  run_of(2, -0.5, 2.0, 30.0, true, 1.0),
                                  run_of(3, 0.2, 1.0, 14.0, false, 0.5)};
  runs[1].scenario = rig("floor", "fast", 50.0, 0.8, 4.0, 0.08);
  runs[1].error[4] = 9.0 * runs[1].sigma[4];   // beyond 4 sigma, and flagged
  runs[2].error[9] = -5.0 * runs[2].sigma[9];  // beyond 4 sigma, not flagged: missed
  const CalibrationLayout layout = calibration_layout(kMarkers, 0);
  const NeesInterval nees99 = average_nees_interval(3.0, kStates, kTail99);
  Capture text, summary;
  report_family(text.f, summary.f, runs, layout, nees99);
  const std::vector<std::string> rows = summary.lines();
  ASSERT_GE(rows.size(), 3u);
  const std::string& header = rows.front();
  const std::size_t width = cells(header).size();
  std::vector<std::string> all, wall, floor;
  for (std::size_t i = 1; i + 1 < rows.size(); ++i) {
    const auto c = cells(rows[i]);
    EXPECT_EQ(c.size(), width) << rows[i];
    if (c[0] == "all") all = c;
    if (c[0] == "mirror" && c[1] == "wall") wall = c;
    if (c[0] == "mirror" && c[1] == "floor") floor = c;
  }
  ASSERT_FALSE(all.empty());
  EXPECT_EQ(all[column(header, "runs")], "3");
  EXPECT_EQ(wall[column(header, "runs")], "2");
  EXPECT_EQ(floor[column(header, "runs")], "1");
  EXPECT_NEAR(std::stod(all[column(header, "nees_mean")]), 18.0, 1e-4);
  EXPECT_NEAR(std::stod(all[column(header, "nees_median")]), 14.0, 1e-4);
  EXPECT_NEAR(std::stod(wall[column(header, "nees_median")]), 12.0, 1e-4);
  EXPECT_EQ(all[column(header, "runs_beyond_4_sigma")], "2");
  EXPECT_EQ(all[column(header, "flagged")], "1");
  EXPECT_EQ(all[column(header, "unflagged_beyond_4_sigma")], "1");
  EXPECT_EQ(wall[column(header, "runs_beyond_4_sigma")], "1");
  const char* const rms_names[4] = {"rms_p_b_c [cm]", "rms_rot_b_c [deg]", "rms_markers [mm]",
                                    "rms_timeshift [ms]"};
  const char* const sigma_names[4] = {"sigma_p_b_c [cm]", "sigma_rot_b_c [deg]",
                                      "sigma_markers [mm]", "sigma_timeshift [ms]"};
  for (std::size_t k = 0; k < 4; ++k) {
    const double rms = group_rms(runs, kGroupRange[k], &RunOutcome::error);
    const double sigma = group_rms(runs, kGroupRange[k], &RunOutcome::sigma);
    EXPECT_NEAR(std::stod(all[column(header, rms_names[k])]), rms, 1e-5 * std::max(1.0, rms));
    EXPECT_NEAR(std::stod(all[column(header, sigma_names[k])]), sigma, 1e-5 * std::max(1.0, sigma));
  }
  EXPECT_GT(std::stod(all[column(header, "over_limit_rot_b_c")]),
            std::stod(all[column(header, "consistent_over_limit_rot_b_c")]));
  char last[128];
  std::snprintf(last, sizeof last, "# nees_99_lo=%.4f nees_99_hi=%.4f", nees99.lo, nees99.hi);
  EXPECT_EQ(rows.back(), last);
  // The table on text has a row per slice that holds runs, after its header.
  const std::string printed = text.text();
  EXPECT_NE(printed.find("\nall           all            3   18.0   14.0     2    1      1 |"),
            std::string::npos)
      << printed;
  EXPECT_NE(printed.find("consistent / lim rests on"), std::string::npos);
}

TEST(CampaignReport, StageTwoFamilyAddsTheCameraColumns) {
  std::vector<RunOutcome> runs = {run_of(1, 1.0, 1.0, 20.0), run_of(2, 0.5, 1.0, 22.0)};
  for (RunOutcome& r : runs) {
    for (int j = 0; j < 5; ++j) {
      r.error.push_back(3.0 + j);
      r.sigma.push_back(4.0);
    }
  }
  Capture text, summary;
  report_family(text.f, summary.f, runs, calibration_layout(kMarkers, 5), {});
  const auto rows = summary.lines();
  // Both runs on one rig: a row for each slice that holds it (the header, all, one value of each
  // of the seven axes, the interval's line), none for the empty ones.
  ASSERT_EQ(rows.size(), 1u + 8u + 1u) << summary.text();
  for (const std::string& row : rows) EXPECT_NE(row.rfind("mirror,floor,", 0), 0u);
  const std::string& header = rows.front();
  const auto all = cells(rows[1]);
  ASSERT_EQ(all.size(), cells(header).size());
  // fu fv cu cv skew: errors 3..7 in both runs.
  EXPECT_NEAR(std::stod(all[column(header, "rms_intrinsics [px]")]),
              std::sqrt((9.0 + 16.0 + 25.0 + 36.0 + 49.0) / 5.0), 1e-5);
  EXPECT_NEAR(std::stod(all[column(header, "sigma_intrinsics [px]")]), 4.0, 1e-5);
  EXPECT_EQ(std::stod(all[column(header, "over_limit_p_b_c")]), 0.0);
  EXPECT_EQ(text.text().find("RMS / limit"), std::string::npos);
}

TEST(CampaignReport, RunsCsvRowsReadBack) {
  std::vector<RunOutcome> runs = {run_of(11, 1.0, 1.0, 12.5), run_of(22, -2.0, 0.5, 19.25, true)};
  runs[0].gated = 7;
  runs[0].passes = 3;
  runs[1].scenario = rig("floor", "fast", 50.0, 0.8, 4.0, 0.08);
  runs[1].screened = 5;
  const std::vector<ParamInfo> params = calibration::calibration_params(kMarkers, 0);
  ASSERT_EQ(params.size(), kStates);
  Capture csv;
  write_runs_csv(csv.f, runs, params, false);
  const auto rows = csv.lines();
  ASSERT_EQ(rows.size(), 3u);
  const std::string& header = rows[0];
  EXPECT_EQ(cells(header).size(), 2 + 2 * kStates + 10 + 8);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const auto c = cells(rows[i + 1]);
    ASSERT_EQ(c.size(), cells(header).size());
    EXPECT_EQ(c[0], std::to_string(i));
    EXPECT_EQ(c[1], std::to_string(runs[i].seed));
    for (std::size_t j = 0; j < kStates; ++j) {
      EXPECT_NEAR(std::stod(c[2 + j]), runs[i].error[j], 1e-5 * std::abs(runs[i].error[j]));
      EXPECT_NEAR(std::stod(c[2 + kStates + j]), runs[i].sigma[j], 1e-5 * runs[i].sigma[j]);
    }
    EXPECT_NEAR(std::stod(c[column(header, "nees")]), runs[i].nees, 1e-4);
    EXPECT_EQ(c[column(header, "consistent")], runs[i].suspect ? "0" : "1");
    EXPECT_EQ(c[column(header, "mirror")], runs[i].scenario.mirror);
    EXPECT_NEAR(std::stod(c[column(header, "prior_marker [cm]")]),
                100.0 * runs[i].scenario.priors.marker, 1e-9);
  }
  EXPECT_EQ(cells(rows[1])[column(header, "markers_gated")], "7");
  EXPECT_EQ(cells(rows[1])[column(header, "passes")], "3");
  EXPECT_EQ(cells(rows[2])[column(header, "markers_screened")], "5");
  EXPECT_EQ(cells(rows[1])[2], "-1.5");  // (0 % 5) - 1.5
}

TEST(CampaignReport, PaperSummaryRowsReadBack) {
  const std::vector<RunOutcome> runs = {run_of(1, 0.01, 0.02, 15.0), run_of(2, -0.02, 0.02, 17.0)};
  const std::vector<ParamInfo> params = calibration::calibration_params(kMarkers, 0);
  std::vector<double> truth;
  for (std::size_t j = 0; j < kStates; ++j) truth.push_back(10.0 * double(j));
  const ErrorStatistics st = error_statistics(runs, kStates);
  FrameMode frames;
  frames.enabled = true;
  DetectionReport detection;
  detection.markers_drawn = 100;
  detection.wrong_labels = 2;
  Capture summary;
  write_paper_summary(summary.f, params, truth, st, 3.25, 2, frames, detection);
  const auto rows = summary.lines();
  ASSERT_EQ(rows.size(), 1 + kStates + 2);
  EXPECT_EQ(rows[0], "parameter,unit,truth,mean_estimate,std,rms_error,paper_std");
  for (std::size_t j = 0; j < kStates; ++j) {
    const auto c = cells(rows[1 + j]);
    const double e0 = runs[0].error[j], e1 = runs[1].error[j], mean = 0.5 * (e0 + e1);
    EXPECT_EQ(c[0], params[j].name);
    EXPECT_NEAR(std::stod(c[2]), truth[j], 1e-6);
    EXPECT_NEAR(std::stod(c[3]), truth[j] + mean, 1e-6);
    EXPECT_NEAR(std::stod(c[4]), std::abs(e0 - e1) / std::sqrt(2.0), 1e-6);
    EXPECT_NEAR(std::stod(c[5]), std::sqrt(0.5 * (e0 * e0 + e1 * e1)), 1e-6);
  }
  EXPECT_EQ(rows[1 + kStates].rfind("# nees_mean=16.0000 ", 0), 0u) << rows[1 + kStates];
  EXPECT_NE(rows[1 + kStates].find(" runs=2 wall_s=3.25 jobs=2"), std::string::npos);
  EXPECT_EQ(rows.back().rfind("# frames=GREY markers_drawn=100 ", 0), 0u) << rows.back();
}

TEST(CampaignReport, PaperTablesNameTheirStage) {
  const std::vector<RunOutcome> runs = {run_of(1, 0.001, 0.02, 15.0),
                                        run_of(2, -0.002, 0.02, 17.0)};
  const std::vector<double> truth(kStates, 1.0);
  Capture stage1;
  print_paper_tables(stage1.f, calibration::calibration_params(kMarkers, 0), false, truth,
                     error_statistics(runs, kStates));
  EXPECT_NE(stage1.text().find("Tables I and II: final estimates over 2 runs"), std::string::npos);
  EXPECT_NE(stage1.text().find("average NEES of the 16 calibration states: 16.00"),
            std::string::npos);

  std::vector<RunOutcome> stage2_runs = runs;
  for (RunOutcome& r : stage2_runs)
    for (int j = 0; j < 5; ++j) {
      r.error.push_back(0.01);
      r.sigma.push_back(1.0);
    }
  const auto params5 = calibration::calibration_params(kMarkers, 5);
  const std::vector<double> truth5(params5.size(), 1.0);
  for (const bool one_stage : {false, true}) {
    Capture t;
    print_paper_tables(t.f, params5, one_stage, truth5,
                       error_statistics(stage2_runs, params5.size()));
    EXPECT_NE(t.text().find(one_stage ? "Tables I, II and III (one stage)"
                                      : "Tables I, II and III (after stage 2)"),
              std::string::npos)
        << t.text();
  }
}

TEST(CampaignReport, NotableRunsAreNamed) {
  std::vector<RunOutcome> runs = {run_of(1, 1.0, 1.0, 16.0), run_of(2, 1.0, 1.0, 16.0),
                                  run_of(3, 1.0, 1.0, 16.0)};
  runs[1].passes = calibration::kDefaultPasses + 2;
  runs[0].suspect = runs[2].suspect = true;
  runs[2].imu_check = 1.5;
  runs[1].imu_check = 0.9;
  Capture text;
  print_notable_runs(text.f, runs);
  const auto lines = text.lines();
  ASSERT_EQ(lines.size(), 3u) << text.text();
  EXPECT_NE(lines[0].find("passes made): 1 (" + std::to_string(runs[1].passes) + ")"),
            std::string::npos);
  EXPECT_NE(lines[1].find("included above): 0, 2"), std::string::npos);
  EXPECT_NE(lines[2].find("bound): 2 (1.50)"), std::string::npos);
  Capture quiet;
  runs[0].suspect = runs[2].suspect = false;
  runs[1].passes = calibration::kDefaultPasses;
  runs[2].imu_check = 0.0;
  print_notable_runs(quiet.f, runs);
  EXPECT_EQ(quiet.text(), "");
}

TEST(CampaignReport, FilterAgainstTheBatch) {
  std::vector<RunOutcome> runs(3);
  const std::vector<ParamInfo> params = calibration::calibration_params(kMarkers, 0);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    RunOutcome& r = runs[i];
    r.seed = 100 + i;
    r.wall_s = 1.0 + double(i);
    r.filter_error = Eigen::VectorXd::Constant(kStates, 0.001 * double(i + 1));
    r.batch.error = Eigen::VectorXd::Constant(kStates, 0.002);
    r.batch.sigma.assign(kStates, 0.5);
    r.batch.nees = 10.0 + 4.0 * double(i);
    r.batch.cpu_s = 5.0 * double(i + 1);
    r.batch.converged = i != 2;
  }
  runs[1].batch.failure = "no frames within the IMU's span";
  BatchComparison cmp(calibration_layout(kMarkers, 0));
  cmp.add(runs[0].filter_error, runs[0].batch.error, runs[0].batch.nees);
  cmp.add(runs[2].filter_error, runs[2].batch.error, runs[2].batch.nees);
  EXPECT_NEAR(cmp.filter_rms(CalibrationGroup::kMarkers), std::sqrt((1e-6 + 9e-6) / 2.0), 1e-15);
  EXPECT_NEAR(cmp.batch_rms(CalibrationGroup::kMarkers), 0.002, 1e-15);
  EXPECT_NEAR(cmp.ratio(CalibrationGroup::kTimeOffset), std::sqrt(5e-6) / 0.002, 1e-12);
  EXPECT_EQ(cmp.ratio(CalibrationGroup::kIntrinsics), 0.0);
  EXPECT_NEAR(cmp.mean_batch_nees(), 14.0, 1e-12);

  Capture text, csv;
  report_batch(text.f, csv.f, runs, params, calibration_layout(kMarkers, 0));
  const auto rows = csv.lines();
  ASSERT_EQ(rows.size(), 3u);  // the header, runs 0 and 2
  EXPECT_EQ(cells(rows[0]).size(), 6 + 2 * kStates);
  const auto row2 = cells(rows[2]);
  EXPECT_EQ(row2[0], "2");
  EXPECT_EQ(row2[1], "102");
  EXPECT_EQ(row2[4], "0");  // did not converge
  EXPECT_NEAR(std::stod(row2[6]), 0.002 * params[0].scale, 1e-9);
  const std::string printed = text.text();
  EXPECT_NE(printed.find("run 1: the batch failed: no frames within the IMU's span"),
            std::string::npos);
  EXPECT_NE(printed.find("(2 runs)"), std::string::npos);
  EXPECT_NE(printed.find("the batch's average NEES 14.00"), std::string::npos);
  EXPECT_NE(printed.find("1 of its solves did not converge"), std::string::npos);
  // Medians of two: (1 + 3) / 2 s of the filter, (5 + 15) / 2 s of the batch.
  EXPECT_NE(printed.find("the filter 2.00 s (wall, passes and refinement), the batch 10.00 s"),
            std::string::npos)
      << printed;
}

}  // namespace
}  // namespace mirrorcal::evaluation
