// IMU gaps survived: the IMU silent for 100-200 ms (a USB hiccup) is propagated across with the
// uncertainty of the signal it did not give, and the calibration stays consistent; silent for
// longer (400 ms, 5 s), the motion states restart and the calibration goes on as consistent.
// Full calibrations (run_loop) of the paper scenario and of random-family rigs, the gap at 30 s;
// and twenty-one more random rigs, with gaps of 200 ms, 400 ms or 2 s, each either within 4 sigma
// in every state or flagged.
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

// Random-family rigs 7-27 (slow and fast sweeps, wall and floor mirrors, 20-60 Hz cameras), each
// with a gap at 30 s of 200 ms (propagated across), 400 ms or 2 s (a restart of the motion states)
// in turn: every run lies within 4 sigma of the truth in every calibration state or says
// consistent: false, as the campaigns judge a run (montecarlo's unflagged beyond 4 sigma). With
// the Gauss-Newton refinement off (Passes{2, 4, false}: the free passes alone, as before it came
// in) rig 11 ended 18 sigma off unflagged after 400 ms (NEES 1719, where it was 7.6 sigma without
// the gap), and rigs 22 and 25 5.0 and 10.8 sigma.
void expect_each_run_right_or_flagged() {
  constexpr std::int64_t kGapsMs[] = {200, 400, 2000};
  for (std::uint64_t seed = 7; seed <= 27; ++seed) {
    const std::int64_t gap_ms = kGapsMs[(seed - 7) % 3];
    const Run run = calibrate_with_gap(mc::sim::random_scenario(seed), seed, gap_ms);
    SCOPED_TRACE("random seed " + std::to_string(seed) + ", gap " + std::to_string(gap_ms) + " ms");
    EXPECT_EQ(run.loop_counters.imu_gaps, 1u);
    EXPECT_EQ(run.loop_counters.imu_restarts, gap_ms > 300 ? 1u : 0u);
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

TEST(ImuGap, OnTwentyOneRandomRigsLeavesEachRunRightOrFlagged) {
  expect_each_run_right_or_flagged();
}
