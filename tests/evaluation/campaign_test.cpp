// A small Monte Carlo campaign of the paper scenario through the program, as CI runs it: every
// parameter of Tables I and II (and III with --intrinsics) within twice the paper's final sigma,
// and the filter consistent.
// Ten runs estimate an RMS to about +-25 %, so the bounds are loose enough never to fail on a good
// filter and tight enough to fail on one that regresses (a single pass, for instance, gives an
// average NEES of about 30, and the second-order IMU integration over-confident marker depths).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/estimator/marker_counts.hpp"
#include "mirrorcal/estimator/mirror_model.hpp"

namespace {

// A CSV row's cells (montecarlo writes no quoted commas).
std::vector<std::string> csv_cells(const std::string& row) {
  std::vector<std::string> cells;
  std::stringstream ss(row);
  for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
  return cells;
}

// Runs a campaign of `runs` runs with the extra options and checks summary.csv's `params` rows.
void expect_campaign_meets_bar(const std::string& options, int params, int runs = 10) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("mirrorcal-campaign-" + std::to_string(getpid()));
  const std::string cmd = std::string(MIRRORCAL_BIN) + " montecarlo --runs " +
                          std::to_string(runs) + " --jobs 2 --seed 11 --no-plots " + options +
                          " --out " + dir.string() + " > " + (dir.string() + ".log") + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;

  std::ifstream in(dir / "summary.csv");
  ASSERT_TRUE(in) << "no summary.csv";
  std::string line;
  std::getline(in, line);
  ASSERT_EQ(line, "parameter,unit,truth,mean_estimate,std,rms_error,paper_std");
  int rows = 0;
  double nees = -1.0;
  while (std::getline(in, line)) {
    if (line.rfind("# nees_mean=", 0) == 0) nees = std::stod(line.substr(12));
    if (line.rfind("#", 0) == 0) continue;
    std::stringstream ss(line);
    std::string name, unit, truth, mean, sd, rms, paper;
    std::getline(ss, name, ',');
    std::getline(ss, unit, ',');
    std::getline(ss, truth, ',');
    std::getline(ss, mean, ',');
    std::getline(ss, sd, ',');
    std::getline(ss, rms, ',');
    std::getline(ss, paper, ',');
    if (paper == "nan") {  // not in the paper: the time offset, against the issue's 0.1 ms
      EXPECT_EQ(name, "timeshift_cam_imu");
      EXPECT_LT(std::stod(rms), 0.1) << name << " [" << unit << "]";
    } else {
      EXPECT_LT(std::stod(rms), 2.0 * std::stod(paper)) << name << " [" << unit << "]";
    }
    ++rows;
  }
  EXPECT_EQ(rows, params);
  // The average NEES of the states over the runs: chi-square with runs * params dof, divided by
  // the runs; its 99.9 % interval.
  const double lo = mirrorcal::calibration::chi2_quantile(0.0005, double(params) * runs) / runs;
  const double hi = mirrorcal::calibration::chi2_quantile(0.9995, double(params) * runs) / runs;
  EXPECT_GT(nees, lo);
  EXPECT_LT(nees, hi);
  std::printf("campaign: average NEES %.2f (99.9 %% interval %.2f..%.2f)\n", nees, lo, hi);
  std::filesystem::remove_all(dir);
}

TEST(Campaign, TenRunsOfThePaperScenarioMeetTheBar) {
  expect_campaign_meets_bar("", 16);  // p, rotation, 3 markers, time offset
}

// A rolling shutter reading a row every 30 us (14 ms a frame), known from camchain.yaml.
TEST(Campaign, TenRunsThroughARollingShutterMeetTheBar) {
  expect_campaign_meets_bar("--line-delay 3e-5", 16);
}

// Stage 2 (Table III): the intrinsics too, from guesses 100 px off.
TEST(Campaign, TenRunsOfStageTwoMeetTheBar) {
  expect_campaign_meets_bar("--intrinsics", 21);
}

// Stage 2 holding skew at zero on a camera without skew: fu, fv, cu, cv only.
TEST(Campaign, TenRunsOfStageTwoWithSkewHeldMeetTheBar) {
  expect_campaign_meets_bar("--intrinsics --hold-skew", 20);
}

// Stage 2 estimating the lens too (estimate_distortion: fu fv cu cv and EuRoC cam0's radtan k1 k2
// p1 p2, skew held at zero on a camera without it), six runs: consistent (the average NEES of the
// 24 states inside its 99.9 % chi-square interval), every parameter the paper has within twice its
// sigma, and each coefficient's error within 3 of its sigmas in every run, their RMS over the runs
// within 2 (chi-square with 6 dof: 99.9 % below 1.93^2). A filter that ignored its coefficients
// (predicting through the prior's guesses) would be off by the guesses' 0.2, 0.1, 0.002 sigmas
// with sigmas that shrink: far outside.
TEST(Campaign, SixRunsOfStageTwoWithTheRadtanLensEstimatedAreConsistent) {
  constexpr int kRuns = 6, kParams = 24;
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("mirrorcal-lens-" + std::to_string(getpid()));
  const std::string cmd = std::string(MIRRORCAL_BIN) + " montecarlo --runs " +
                          std::to_string(kRuns) +
                          " --jobs 2 --seed 11 --no-plots --intrinsics --hold-skew --distortion "
                          "radtan --estimate-distortion --out " +
                          dir.string() + " > " + (dir.string() + ".log") + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream summary(dir / "summary.csv");
  ASSERT_TRUE(summary) << "no summary.csv";
  std::string line;
  std::getline(summary, line);
  int rows = 0;
  double nees = -1.0;
  std::vector<std::string> names;
  while (std::getline(summary, line)) {
    if (line.rfind("# nees_mean=", 0) == 0) nees = std::stod(line.substr(12));
    if (line.rfind("#", 0) == 0) continue;
    const auto c = csv_cells(line);
    ASSERT_EQ(c.size(), 7u) << line;
    names.push_back(c[0]);
    if (c[6] != "nan") {
      EXPECT_LT(std::stod(c[5]), 2.0 * std::stod(c[6])) << c[0] << " [" << c[1] << "]";
    }
    ++rows;
  }
  ASSERT_EQ(rows, kParams);
  const std::vector<std::string> lens(names.end() - 4, names.end());
  EXPECT_EQ(lens, (std::vector<std::string>{"k1", "k2", "p1", "p2"}));
  const double lo = mirrorcal::calibration::chi2_quantile(0.0005, double(kParams) * kRuns) / kRuns;
  const double hi = mirrorcal::calibration::chi2_quantile(0.9995, double(kParams) * kRuns) / kRuns;
  EXPECT_GT(nees, lo);
  EXPECT_LT(nees, hi);

  std::ifstream runs(dir / "runs.csv");
  ASSERT_TRUE(runs) << "no runs.csv";
  std::getline(runs, line);
  const auto header = csv_cells(line);
  double sum_sq[4] = {0, 0, 0, 0};
  int n = 0;
  while (std::getline(runs, line)) {
    const auto c = csv_cells(line);
    ASSERT_GE(c.size(), std::size_t(2 + 2 * kParams));
    for (int j = 0; j < 4; ++j) {
      const std::size_t e = std::size_t(2 + kParams - 4 + j), s = e + std::size_t(kParams);
      ASSERT_EQ(header[e], "err_" + lens[std::size_t(j)] + " [1e-3]");
      ASSERT_EQ(header[s], "sigma_" + lens[std::size_t(j)] + " [1e-3]");
      const double z = std::stod(c[e]) / std::stod(c[s]);
      EXPECT_LT(std::abs(z), 3.0) << lens[std::size_t(j)] << ", run " << c[0];
      sum_sq[j] += z * z;
    }
    ++n;
  }
  ASSERT_EQ(n, kRuns);
  for (int j = 0; j < 4; ++j)
    EXPECT_LT(std::sqrt(sum_sq[j] / n), 2.0) << lens[std::size_t(j)] << ": RMS of error / sigma";
  std::printf("lens campaign: average NEES %.2f (99.9 %% interval %.2f..%.2f)\n", nees, lo, hi);
  std::filesystem::remove_all(dir);
}

// The markers detected and identified in rendered frames (the paper's 1 px pixel noise drawn into
// them): two runs, as rendering costs about 10 s of CPU per run.
TEST(Campaign, TwoRunsFromRenderedFramesMeetTheBar) {
  expect_campaign_meets_bar("--frames", 16, 2);
}

}  // namespace

namespace {

// The random family (20 rigs, a rig of its own per run, both mirrors, the priors a user has, time
// offsets in +-30 ms): not yet consistent over 200 rigs (docs/campaign/random), so the bounds hold
// today's figures (16 states: average NEES 16.2, median 17.0, no run beyond 4 sigma; the runs that
// said consistent: true within 1.22, 1.22, 1.07 and 0.98 times what their data hold, RMS, for
// p_b_c, rotation, markers and time offset) with room for sampling noise, and fail on a
// regression: the transform that dropped every marker a sigma point put behind the mirror (markers
// at their prior, 10s of times the limit), the per-frame curvature shift of the prediction (median
// NEES 21-36 over the same rigs), the free passes' own estimate and covariance reported (average
// 33, 2 of 3 runs beyond 4 sigma not flagged), or the refinement linearised at the tracking pass's
// estimate after each frame's update (average 23.9, median 18.1, a run beyond 4 sigma, markers
// 1.50 times their limit) or before it (19.0, 17.5, markers 1.50) instead of along the smoothed
// track. Runs that said
// consistent: false are judged by being flagged, not by their errors.
// montecarlo --scenario random with `options`, into a folder named `name`: summary.csv's header
// and the cells of its first row (the family over all rigs). The folder and its log are removed.
struct RandomSummary {
  std::string header;
  std::vector<std::string> cell;
  std::string printed;       // what montecarlo printed
  std::vector<double> nees;  // each run's, from runs.csv
  std::vector<std::string> runs_header;
  std::vector<std::vector<std::string>> runs;  // runs.csv's rows, cell by cell
};
RandomSummary random_campaign(const std::string& name, const std::string& options,
                              const std::string& seed = "11") {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("mirrorcal-" + name + "-" + std::to_string(getpid()));
  const std::string log = dir.string() + ".log";
  const std::string cmd = std::string(MIRRORCAL_BIN) + " montecarlo --scenario random " + options +
                          " --jobs 2 --seed " + seed + " --no-plots --out " + dir.string() + " > " +
                          log + " 2>&1";
  RandomSummary out;
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::stringstream printed;
  printed << std::ifstream(log).rdbuf();
  out.printed = printed.str();
  std::ifstream runs(dir / "runs.csv");
  std::string row;
  std::getline(runs, row);
  out.runs_header = csv_cells(row);
  const std::size_t nees_column = static_cast<std::size_t>(
      std::find(out.runs_header.begin(), out.runs_header.end(), "nees") - out.runs_header.begin());
  while (std::getline(runs, row)) {
    out.runs.push_back(csv_cells(row));
    out.nees.push_back(std::stod(out.runs.back().at(nees_column)));
  }
  std::ifstream in(dir / "summary.csv");
  EXPECT_TRUE(in) << "no summary.csv";
  std::getline(in, out.header);
  std::string line;
  std::getline(in, line);
  out.cell = csv_cells(line);
  std::filesystem::remove_all(dir);
  std::filesystem::remove(log);
  return out;
}

TEST(Campaign, TwentyRandomRigsHoldTheirFigures) {
  const RandomSummary summary = random_campaign("random", "--runs 20");
  ASSERT_EQ(summary.header.rfind("axis,value,runs,nees_mean,nees_median,runs_beyond_4_sigma", 0),
            0u);
  const std::vector<std::string>& cell = summary.cell;
  ASSERT_GE(cell.size(), 14u);
  ASSERT_EQ(cell[0], "all");
  EXPECT_EQ(std::stoi(cell[2]), 20);
  const double mean = std::stod(cell[3]), med = std::stod(cell[4]);
  const int beyond = std::stoi(cell[5]);
  const int missed = std::stoi(cell[7]);
  // What the runs that said consistent: true hold against their data's limit, RMS: p_b_c,
  // rotation, markers, time offset.
  // The same with each run's errors over its own limit (the last four cells).
  ASSERT_EQ(cell.size(), 28u);
  double over[4], per_run[4];
  for (int k = 0; k < 4; ++k) {
    over[k] = std::stod(cell[static_cast<std::size_t>(20 + k)]);
    per_run[k] = std::stod(cell[static_cast<std::size_t>(24 + k)]);
  }
  std::printf(
      "random: NEES average %.1f, median %.1f, %d runs beyond 4 sigma (%d not flagged); the "
      "consistent runs' RMS over the limit: p %.2f, rotation %.2f, markers %.2f, time offset "
      "%.2f; run by run %.2f, %.2f, %.2f, %.2f\n",
      mean, med, beyond, missed, over[0], over[1], over[2], over[3], per_run[0], per_run[1],
      per_run[2], per_run[3]);
  EXPECT_LT(med, 20.0);
  EXPECT_LT(mean, 20.5);
  EXPECT_LE(beyond, 2);
  EXPECT_LE(missed, 1);
  for (int k = 0; k < 4; ++k) {
    EXPECT_GT(over[k], 0.0) << k;
    EXPECT_LT(over[k], 1.45) << k;
    EXPECT_GT(per_run[k], 0.0) << k;
    EXPECT_LT(per_run[k], 1.45) << k;
  }
  // How many runs each ratio rests on, in effect: at least one (all the weight on one run), at
  // most every consistent run (equal weights).
  const std::size_t line = summary.printed.find("consistent / lim rests on");
  ASSERT_NE(line, std::string::npos) << summary.printed;
  double n[4];
  ASSERT_EQ(std::sscanf(summary.printed.c_str() + summary.printed.find("):", line) + 2,
                        " p_b_c [cm] %lf (%*[^)]) rot_b_c [deg] %lf (%*[^)]) markers [mm] %lf "
                        "(%*[^)]) timeshift [ms] %lf",
                        &n[0], &n[1], &n[2], &n[3]),
            4)
      << summary.printed;
  const int consistent = 20 - std::stoi(cell[6]);
  for (int k = 0; k < 4; ++k) {
    EXPECT_GE(n[k], 1.0) << k;
    EXPECT_LE(n[k], consistent + 0.5) << k;  // printed rounded
  }
}

// A campaign with runs that said consistent: false gives a second verdict, on the runs a user would
// have kept: their average NEES against its own 99 % interval. The line must be there exactly when
// the warned list is, and its average must be runs.csv's over the other runs. The seed's first
// seven rigs must hold such a run (the statistics themselves: campaign_statistics_test.cpp).
TEST(Campaign, TheRunsThatSaidConsistentGetTheirOwnVerdict) {
  const RandomSummary summary = random_campaign("random-trusted", "--runs 7", "4");
  const std::string& text = summary.printed;
  ASSERT_EQ(summary.nees.size(), 7u) << text;
  const std::string warned_key = "(consistent: false; included above): ";
  const std::size_t warned_at = text.find(warned_key);
  std::vector<bool> warned(summary.nees.size(), false);
  if (warned_at != std::string::npos) {
    const std::size_t from = warned_at + warned_key.size();
    std::stringstream list(text.substr(from, text.find('\n', from) - from));
    for (std::string run; std::getline(list, run, ',');) warned.at(std::stoul(run)) = true;
  }
  double sum = 0.0;
  int kept = 0;
  for (std::size_t r = 0; r < warned.size(); ++r)
    if (!warned[r]) {
      sum += summary.nees[r];
      ++kept;
    }
  const std::size_t line = text.find(" runs that said consistent: true: ");
  if (kept == 7) {
    EXPECT_EQ(line, std::string::npos) << "a second verdict with no run warned of:\n" << text;
    // Not a skip: a test that stops testing when the filter changes would pass unseen.
    FAIL() << "no run of seed 4's first seven said consistent: false, so the second verdict is "
              "not tested: pick a seed whose first seven runs have one";
  }
  ASSERT_NE(line, std::string::npos) << text;
  const std::size_t start = text.rfind("over the ", line);
  int n = 0;
  double average = 0.0, lo = 0.0, hi = 0.0;
  char verdict[32] = "";
  ASSERT_EQ(std::sscanf(text.c_str() + start,
                        "over the %d runs that said consistent: true: %lf (99 %% interval "
                        "%lf..%lf): %31[^\n]",
                        &n, &average, &lo, &hi, verdict),
            5)
      << text.substr(start, 120);
  EXPECT_EQ(n, kept);
  EXPECT_NEAR(average, sum / kept, 0.006);
  const double states = 16.0;
  EXPECT_NEAR(lo, mirrorcal::calibration::chi2_quantile(0.005, states * kept) / kept, 0.006);
  EXPECT_NEAR(hi, mirrorcal::calibration::chi2_quantile(0.995, states * kept) / kept, 0.006);
  const bool inside = average >= lo && average <= hi;
  EXPECT_STREQ(verdict, inside ? "consistent" : "NOT consistent");
}

// --rig S: every run the rig whose run seed is S (noise and prior guesses of each run's own). The
// rig a campaign drew for its first run comes back in every run of a --rig campaign at that run's
// seed: the same mirror, motion, camera rate, pixel noise, IMU grade and prior widths (continuous
// draws, so a different rig would not match), and a new seed per run.
TEST(Campaign, OneRigWithNewNoiseInEveryRun) {
  const RandomSummary drawn = random_campaign("random-drawn", "--runs 1", "3");
  ASSERT_EQ(drawn.runs.size(), 1u) << drawn.printed;
  const std::vector<std::string>& header = drawn.runs_header;
  const auto column = [&](const std::string& name) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  const std::size_t seed = column("seed"), first_rig_column = column("mirror");
  ASSERT_LT(first_rig_column, header.size());
  const RandomSummary one_rig =
      random_campaign("random-one-rig", "--runs 2 --rig " + drawn.runs[0][seed], "5");
  EXPECT_NE(one_rig.printed.find("every run rig " + drawn.runs[0][seed]), std::string::npos)
      << one_rig.printed;
  ASSERT_EQ(one_rig.runs.size(), 2u) << one_rig.printed;
  ASSERT_EQ(one_rig.runs_header, header);
  for (const std::vector<std::string>& run : one_rig.runs) {
    EXPECT_NE(run[seed], drawn.runs[0][seed]);
    for (std::size_t c = first_rig_column; c < header.size(); ++c)
      EXPECT_EQ(run[c], drawn.runs[0][c]) << header[c];
  }
  EXPECT_NE(one_rig.runs[0][seed], one_rig.runs[1][seed]);
  // The paper scenario has one rig already.
  const std::string refused =
      std::string(MIRRORCAL_BIN) + " montecarlo --runs 1 --rig 3 > /dev/null 2>&1";
  EXPECT_EQ(WEXITSTATUS(std::system(refused.c_str())), 2);
}

// The random family's stage 2 (--intrinsics --hold-skew: each rig's camera guessed within its own
// 20-100 px prior, skew held): ten rigs consistent over the 20 states (100 rigs: average NEES
// 20.79, none beyond 4 sigma, README), no run beyond 4 sigma that did not say so, and the camera's
// RMS error within twice its reported sigma.
TEST(Campaign, TenRandomRigsOfStageTwoAreConsistent) {
  const RandomSummary summary = random_campaign("random2", "--intrinsics --hold-skew --runs 10");
  ASSERT_NE(summary.header.find(",rms_intrinsics [px],sigma_intrinsics [px]"), std::string::npos)
      << summary.header;
  const std::vector<std::string>& cell = summary.cell;
  ASSERT_EQ(cell.size(), 30u);  // stage 1's 24, the camera's RMS and sigma, the per-run ratios
  ASSERT_EQ(cell[0], "all");
  const int runs = std::stoi(cell[2]), missed = std::stoi(cell[7]);
  const double mean = std::stod(cell[3]), rms_k = std::stod(cell[24]),
               sigma_k = std::stod(cell[25]);
  std::printf(
      "random, stage 2: NEES average %.2f, %d unflagged beyond 4 sigma, fu fv cu cv %.3f px "
      "RMS against a reported %.3f\n",
      mean, missed, rms_k, sigma_k);
  EXPECT_EQ(runs, 10);
  const double lo = mirrorcal::calibration::chi2_quantile(0.0005, 20.0 * runs) / runs;
  const double hi = mirrorcal::calibration::chi2_quantile(0.9995, 20.0 * runs) / runs;
  EXPECT_GT(mean, lo);
  EXPECT_LT(mean, hi);
  EXPECT_EQ(missed, 0);
  EXPECT_GT(rms_k, 0.0);
  EXPECT_LT(rms_k, 2.0 * sigma_k);
}

// Two one-stage runs of the paper scenario (montecarlo --intrinsics --one-stage --seed 1, runs
// 43 and 65) lock onto a wrong solution in their first passes whatever passes from that estimate
// do (they ended at NEES 1.4e7 and 1722, flagged). Restarted from the guesses at an inflated
// pixel noise (run.hpp, kAnnealedPixelNoise), each comes back: consistent, its NEES within the
// 99.9 % quantile of its 21 states, and the result says it was restarted. (Run 44 did too until
// the loop's marker screen let a first frame's markers wait for a second: it no longer locks on.)
TEST(Campaign, OneStageRunsThatLockedOnComeBackFromARestart) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("mirrorcal-restart-" + std::to_string(getpid()));
  const double bound = mirrorcal::calibration::chi2_quantile(0.999, 21.0);
  for (const char* seed : {"2950729420637482990", "14466042551222691088"}) {
    const std::string log = dir.string() + ".log";
    const std::string cmd = std::string(MIRRORCAL_BIN) + " sim --intrinsics --one-stage --seed " +
                            seed + " --no-plots --out " + dir.string() + " > " + log + " 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    std::ifstream out(log);
    std::stringstream printed;
    printed << out.rdbuf();
    const std::string text = printed.str();
    const std::string key = "NEES of the 21 calibration states: ";
    const std::size_t at = text.find(key);
    ASSERT_NE(at, std::string::npos) << text;
    EXPECT_LT(std::stod(text.substr(at + key.size())), bound) << seed;
    std::ifstream result(dir / "mirrorcal-result.yaml");
    std::stringstream yaml;
    yaml << result.rdbuf();
    EXPECT_NE(yaml.str().find("\nconsistent: true"), std::string::npos) << seed;
    EXPECT_NE(yaml.str().find("restarted from the guesses"), std::string::npos) << seed;
    std::filesystem::remove_all(dir);
  }
}

// The random family with another number of markers than three (the second count of
// MIRRORCAL_MARKERS: each rig draws that many within the family's rules): ten rigs consistent
// over their calibration states (the average NEES within its 99.9 % interval), and at most one
// run beyond 4 sigma that did not say so.
TEST(Campaign, TenRandomRigsWithAnotherMarkerCountAreConsistent) {
  if (mirrorcal::kMarkerCounts.size() < 2) GTEST_SKIP() << "this build has one marker count";
  const int m = mirrorcal::kMarkerCounts[1];
  const RandomSummary summary = random_campaign("random-m" + std::to_string(m),
                                                "--markers " + std::to_string(m) + " --runs 10");
  const std::vector<std::string>& cell = summary.cell;
  ASSERT_GE(cell.size(), 8u);
  ASSERT_EQ(cell[0], "all");
  const int runs = std::stoi(cell[2]), missed = std::stoi(cell[7]);
  const double mean = std::stod(cell[3]);
  const double states = mirrorcal::calibration_layout(m, 0).size();
  const double lo = mirrorcal::calibration::chi2_quantile(0.0005, states * runs) / runs;
  const double hi = mirrorcal::calibration::chi2_quantile(0.9995, states * runs) / runs;
  std::printf(
      "random, %d markers: NEES average %.2f of %.0f states (99.9 %% interval %.2f..%.2f), "
      "%d unflagged beyond 4 sigma\n",
      m, mean, states, lo, hi, missed);
  EXPECT_EQ(runs, 10);
  EXPECT_GT(mean, lo);
  EXPECT_LT(mean, hi);
  EXPECT_LE(missed, 1);  // as the three markers' family (TwentyRandomRigsHoldTheirFigures)
}

// The random family with a detector's mistakes: in one frame of ten, one marker's pixel is a
// random one (--outliers 10%). Without the loop's marker screen every such run diverged (20 of 20
// at 2 %); with it, the runs that said consistent: true are consistent (their average NEES within
// its 99.9 % interval), at most two of ten are flagged, none lies beyond 4 sigma unflagged, and
// the screen withheld reflections in every run.
TEST(Campaign, TenRandomRigsWithAWrongBlobInOneFrameOfTenAreConsistent) {
  const RandomSummary summary = random_campaign("random-outliers", "--outliers 10% --runs 10");
  const std::vector<std::string>& cell = summary.cell;
  ASSERT_GE(cell.size(), 8u);
  ASSERT_EQ(cell[0], "all");
  const int runs = std::stoi(cell[2]), flagged = std::stoi(cell[6]), missed = std::stoi(cell[7]);
  EXPECT_EQ(runs, 10);
  EXPECT_LE(flagged, 2);
  EXPECT_EQ(missed, 0);
  // The unflagged runs' NEES from runs.csv.
  const auto column = [&](const char* name) {
    return static_cast<std::size_t>(
        std::find(summary.runs_header.begin(), summary.runs_header.end(), name) -
        summary.runs_header.begin());
  };
  const std::size_t consistent = column("consistent"), screened = column("markers_screened");
  ASSERT_LT(consistent, summary.runs_header.size());
  ASSERT_LT(screened, summary.runs_header.size());
  double sum = 0.0;
  int trusted = 0;
  for (std::size_t r = 0; r < summary.runs.size(); ++r) {
    EXPECT_GT(std::stoull(summary.runs[r].at(screened)), 0u) << "run " << r;
    if (summary.runs[r].at(consistent) != "1") continue;
    sum += summary.nees[r];
    ++trusted;
  }
  ASSERT_GT(trusted, 0);
  const double states = mirrorcal::calibration_layout(3, 0).size();
  const double lo = mirrorcal::calibration::chi2_quantile(0.0005, states * trusted) / trusted;
  const double hi = mirrorcal::calibration::chi2_quantile(0.9995, states * trusted) / trusted;
  std::printf(
      "random, wrong blobs in 10 %% of the frames: %d of %d runs flagged, unflagged NEES "
      "%.2f (99.9 %% interval %.2f..%.2f)\n",
      flagged, runs, sum / trusted, lo, hi);
  EXPECT_GT(sum / trusted, lo);
  EXPECT_LT(sum / trusted, hi);
}

}  // namespace
