// IMU gaps survived: the IMU silent for 100-200 ms (a USB hiccup) is propagated across with the
// uncertainty of the signal it did not give, and the calibration stays consistent; silent for
// longer (400 ms, 5 s), the motion states restart and the calibration goes on as consistent.
// Full calibrations (run_loop) of the paper scenario and of random-family rigs, the gap at 30 s;
// and twenty more random rigs, each either within 4 sigma in every state or flagged.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "imu_gap_run.hpp"

namespace mc = mirrorcal;
using mc::gaptest::Run;

namespace {

constexpr std::int64_t kGapStartMs = 30'000;

Run calibrate_with_gap(const mc::sim::Scenario& s, std::uint64_t seed, std::int64_t gap_ms) {
  return mc::gaptest::calibrate_with_gap(s, seed, kGapStartMs, gap_ms);
}

// The chi-square quantile p of k degrees of freedom (Wilson-Hilferty: within 0.1 % at k >= 48).
double chi2_quantile(double p, double k) {
  const double z = p > 0.5 ? 1.959964 : -1.959964;  // the 2.5 % and 97.5 % points
  const double c = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - c + z * std::sqrt(c), 3);
}

// Runs of the paper scenario (seeds 1-3) and of three random-family rigs (seeds 4-6), each with
// the gap: every run counts the gap once and stays consistent (at most 0.5 % of its markers
// gated), and their average NEES lies in its 95 % interval.
void expect_gap_survived(std::int64_t gap_ms, std::uint64_t restarts) {
  constexpr int kCalibration = 16;
  std::vector<std::pair<mc::sim::Scenario, std::uint64_t>> rigs;
  for (std::uint64_t seed : {1, 2, 3}) rigs.emplace_back(mc::sim::paper_scenario(), seed);
  for (std::uint64_t seed : {4, 5, 6}) rigs.emplace_back(mc::sim::random_scenario(seed), seed);
  double nees_sum = 0.0;
  for (const auto& [scenario, seed] : rigs) {
    const Run run = calibrate_with_gap(scenario, seed, gap_ms);
    SCOPED_TRACE(scenario.name + " seed " + std::to_string(seed));
    EXPECT_EQ(run.loop_counters.imu_gaps, 1u);
    EXPECT_EQ(run.loop_counters.imu_restarts, restarts);
    EXPECT_EQ(run.filter_counters.failures, 0u);
    EXPECT_FALSE(mc::calibration::suspect(run.result))
        << run.result.markers_gated << " gated of " << run.result.markers_used << " used";
    nees_sum += run.history.back().nees;
  }
  const double dof = kCalibration * static_cast<double>(rigs.size());
  const double n = static_cast<double>(rigs.size());
  EXPECT_GT(nees_sum / n, chi2_quantile(0.025, dof) / n);
  EXPECT_LT(nees_sum / n, chi2_quantile(0.975, dof) / n);
}

// Random-family rigs 7-26 (slow and fast sweeps, wall and floor mirrors, 20-60 Hz cameras) with
// the gap at 30 s: every run lies within 4 sigma of the truth in every calibration state or says
// consistent: false, as the campaigns judge a run (montecarlo's unflagged beyond 4 sigma). With
// the Gauss-Newton refinement off (Passes{2, 4, false}: the free passes alone, as before it came
// in) three of the twenty end beyond 4 sigma unflagged after 400 ms (rig 11: 18 sigma, NEES 1719,
// where it was 7.6 sigma without the gap; rigs 22 and 25: 5.0 and 10.8).
void expect_each_run_right_or_flagged(std::int64_t gap_ms, std::uint64_t restarts) {
  for (std::uint64_t seed = 7; seed <= 26; ++seed) {
    const Run run = calibrate_with_gap(mc::sim::random_scenario(seed), seed, gap_ms);
    SCOPED_TRACE("random seed " + std::to_string(seed));
    EXPECT_EQ(run.loop_counters.imu_gaps, 1u);
    EXPECT_EQ(run.loop_counters.imu_restarts, restarts);
    EXPECT_TRUE(mc::gaptest::worst_sigmas(run) <= 4.0 || !mc::calibration::consistent(run.result))
        << mc::gaptest::worst_sigmas(run) << " sigmas, NEES " << run.history.back().nees;
  }
}

}  // namespace

TEST(ImuGap, Of100MsIsPropagatedAcrossAndTheCalibrationStaysConsistent) {
  expect_gap_survived(100, 0);
}

TEST(ImuGap, Of200MsIsPropagatedAcrossAndTheCalibrationStaysConsistent) {
  expect_gap_survived(200, 0);
}

// Beyond LoopConfig::restart_gap_s (0.3 s) the crossing knows no more than a restart.
TEST(ImuGap, Of400MsRestartsTheMotionStatesAndTheCalibrationStaysConsistent) {
  expect_gap_survived(400, 1);
}

TEST(ImuGap, Of5SRestartsTheMotionStatesAndTheCalibrationStaysConsistent) {
  expect_gap_survived(5000, 1);
}

TEST(ImuGap, Of200MsOnTwentyRandomRigsLeavesEachRunRightOrFlagged) {
  expect_each_run_right_or_flagged(200, 0);
}

TEST(ImuGap, Of400MsOnTwentyRandomRigsLeavesEachRunRightOrFlagged) {
  expect_each_run_right_or_flagged(400, 1);
}

TEST(ImuGap, Of2SOnTwentyRandomRigsLeavesEachRunRightOrFlagged) {
  expect_each_run_right_or_flagged(2000, 1);
}
