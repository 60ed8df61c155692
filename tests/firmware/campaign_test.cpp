// A small Monte Carlo campaign of the paper scenario through the program, as CI runs it: every
// parameter of Tables I and II (and III with --intrinsics) within twice the paper's final sigma,
// and the filter consistent.
// Ten runs estimate an RMS to about +-25 %, so the bounds are loose enough never to fail on a good
// filter and tight enough to fail on one that regresses (a single pass, for instance, gives an
// average NEES of about 30, and the second-order IMU integration over-confident marker depths).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <unistd.h>

#include "report.hpp"

namespace {

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
    EXPECT_LT(std::stod(rms), 2.0 * std::stod(paper)) << name << " [" << unit << "]";
    ++rows;
  }
  EXPECT_EQ(rows, params);
  // The average NEES of the states over the runs: chi-square with runs * params dof, divided by
  // the runs; its 99.9 % interval.
  const double lo = mirrorcal::app::chi2_quantile(0.0005, double(params) * runs) / runs;
  const double hi = mirrorcal::app::chi2_quantile(0.9995, double(params) * runs) / runs;
  EXPECT_GT(nees, lo);
  EXPECT_LT(nees, hi);
  std::printf("campaign: average NEES %.2f (99.9 %% interval %.2f..%.2f)\n", nees, lo, hi);
  std::filesystem::remove_all(dir);
}

TEST(Campaign, TenRunsOfThePaperScenarioMeetTheBar) {
  expect_campaign_meets_bar("", 15);  // p, rotation, 3 markers
}

// Stage 2 (Table III): the intrinsics too, from guesses 100 px off.
TEST(Campaign, TenRunsOfStageTwoMeetTheBar) {
  expect_campaign_meets_bar("--intrinsics", 20);
}

// Stage 2 holding skew at zero on a camera without skew: fu, fv, cu, cv only.
TEST(Campaign, TenRunsOfStageTwoWithSkewHeldMeetTheBar) {
  expect_campaign_meets_bar("--intrinsics --hold-skew", 19);
}

// The markers detected and identified in rendered frames (the paper's 1 px pixel noise drawn into
// them): two runs, as rendering costs about 10 s of CPU per run.
TEST(Campaign, TwoRunsFromRenderedFramesMeetTheBar) {
  expect_campaign_meets_bar("--frames", 15, 2);
}

}  // namespace
