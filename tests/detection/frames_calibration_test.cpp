// mirrorcal sim --frames against mirrorcal sim: the markers detected in rendered frames by the
// board's code calibrate the rig as well as the listed reflections do, with no wrong label.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/evaluation/simulated_run.hpp"
#include "mirrorcal/sim/scenario.hpp"

namespace mc = mirrorcal;

namespace {

// A random rig (seed) calibrated from rendered frames (mode) for duration_s: how its detection
// went and the verdict, printed.
struct RenderedRun {
  mc::calibration::DetectionReport detection;
  double nees = 0.0;
  bool consistent = false;
};
RenderedRun rendered_run(std::uint64_t seed, double duration_s, mc::evaluation::FrameMode mode) {
  mc::sim::Scenario s = mc::sim::random_scenario(seed);
  s.duration_s = duration_s;
  mode.enabled = true;
  const auto run = mc::evaluation::run_simulation<3>(s, seed, {}, mode);
  const RenderedRun r{run.detection, run.history.back().nees,
                      mc::calibration::consistent(run.result)};
  const mc::calibration::DetectionReport& d = r.detection;
  std::printf(
      "seed %llu: %llu of %llu reflections labelled, %llu wrong (%llu before the last pass), "
      "NEES %.1f, %s\n",
      (unsigned long long)seed, (unsigned long long)d.markers_labelled,
      (unsigned long long)d.markers_drawn, (unsigned long long)d.wrong_labels,
      (unsigned long long)d.wrong_labels_before, r.nees, r.consistent ? "consistent" : "flagged");
  return r;
}

// The same with identical LEDs (with the blink code when blink_period > 0).
RenderedRun identical_leds_run(std::uint64_t seed, double duration_s, int blink_period) {
  mc::evaluation::FrameMode mode;
  mode.identical_leds = true;
  mode.blink_period = blink_period;
  return rendered_run(seed, duration_s, mode);
}

}  // namespace

// One test per pixel format, so that the two run side by side.
class FramesCalibration : public testing::TestWithParam<mc::hal::PixelFormat> {};

TEST_P(FramesCalibration, MatchesTheListedMarkersRun) {
  // Half the paper's minute: every frame is rendered and detected again in each of the
  // calibration's passes (about 8), and the bars below scale with the sigmas.
  mc::sim::Scenario s = mc::sim::paper_scenario();
  s.duration_s = 30.0;
  const auto listed = mc::evaluation::run_simulation<3>(s, 4);
  const mc::hal::PixelFormat format = GetParam();
  mc::evaluation::FrameMode mode;
  mode.enabled = true;
  mode.format = format;
  const auto framed = mc::evaluation::run_simulation<3>(s, 4, {}, mode);
  const mc::calibration::DetectionReport& d = framed.detection;
  std::printf("%s: %llu frames, %llu of %llu labelled, %llu wrong, %.3f px RMS, %.2f ms/frame\n",
              mc::hal::to_string(format), (unsigned long long)d.frames,
              (unsigned long long)d.markers_labelled, (unsigned long long)d.markers_drawn,
              (unsigned long long)d.wrong_labels, d.centroid_rms_px, d.ms_per_frame);
  // Every frame but those exposed before the first IMU sample at the time offset's guess.
  EXPECT_EQ(d.frames + framed.loop_counters.frames_before_filter, listed.frames);
  EXPECT_EQ(d.wrong_labels, 0u);
  EXPECT_GE(d.markers_labelled, d.markers_drawn * 98 / 100);
  EXPECT_LT(d.centroid_rms_px, 0.1);

  // Both runs end near the truth and near each other. Bars: the paper's Table I and II
  // accuracies (1 mm, 0.1 deg) and, for what one mirror observes poorly (p_b_c along the
  // mirror's plane, sigma several mm), three of the filter's sigmas.
  const auto& a = listed.history.back();
  const auto& b = framed.history.back();
  for (int j = 0; j < 15; ++j) {
    const double bar = (j >= 3 && j < 6) ? 0.1 * M_PI / 180.0 : 0.001;
    const double tol = 3.0 * bar + 3.0 * a.sigma(j);
    EXPECT_LT(std::abs(b.error(j)), tol) << "parameter " << j;
    EXPECT_LT(std::abs(b.error(j) - a.error(j)), tol) << "parameter " << j;
  }
}

INSTANTIATE_TEST_SUITE_P(PixelFormats, FramesCalibration,
                         testing::Values(mc::hal::PixelFormat::kGrey, mc::hal::PixelFormat::kYuyv),
                         [](const testing::TestParamInfo<mc::hal::PixelFormat>& info) {
                           return info.param == mc::hal::PixelFormat::kGrey ? "Grey" : "Yuyv";
                         });

// Identical LEDs (sim --frames --identical-leds): no brightness code, the random family's loose
// priors (10 cm). The labels come from the rig's shape fitted to the reflections tracked over the
// first seconds (detection/shape_bootstrap.hpp), then from the filter's prediction. On three random
// rigs: no label against the run's names in the last pass, most reflections labelled, and the
// calibration as the self-check says (consistent, or flagged), its NEES against the truth (as the
// detection named the LEDs) within the 99.9 % quantile when unflagged.
TEST(IdenticalLeds, RenderedFramesOfRandomRigsAreLabelledAndCalibrated) {
  int unflagged = 0;
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    const RenderedRun r = identical_leds_run(seed, 20.0, 0);
    const mc::calibration::DetectionReport& d = r.detection;
    EXPECT_EQ(d.wrong_labels, 0u) << "seed " << seed;
    EXPECT_GE(d.markers_labelled, d.markers_drawn * 80 / 100) << "seed " << seed;
    if (!r.consistent) continue;
    ++unflagged;
    EXPECT_LT(r.nees, 37.7) << "seed " << seed;  // chi-square, 15 dof, 99.9 %
  }
  EXPECT_GE(unflagged, 2);
}

// Identical LEDs that the rig's shape names otherwise than the truth's order (the room campaign's
// rig 6, here without the room): a pass's IMU start is fitted to the simulator's own first frames
// (imu_start_from), which must carry the names the detection gave the LEDs. Under the truth's,
// that fit put every reflection behind the camera, and the second pass used no marker (NEES 819,
// flagged).
TEST(IdenticalLeds, NamedOtherwiseThanTheTruthAreCalibratedInEveryPass) {
  const RenderedRun r = identical_leds_run(698117188945754371ull, 20.0, 0);
  EXPECT_TRUE(r.consistent);
  // 2 of 2,075 in the last pass: where reflections pass close by, as with blinking LEDs below.
  EXPECT_LE(r.detection.wrong_labels * 1000, r.detection.markers_labelled);
  EXPECT_LT(r.nees, 39.3);  // chi-square, 16 dof, 99.9 %
}

// Identical LEDs that blink their names (sim --frames --identical-leds --blink 8): each track is
// named by the frames it goes dark in (detection/blink_names.hpp), so the names are the truth's
// from the first periods, with no shape to fit and no look ahead. On three random rigs: at most one
// label in a thousand wrong in the last pass, most reflections drawn labelled, and the calibration
// as the self-check says, its NEES within the 99.9 % quantile when unflagged.
TEST(IdenticalLeds, ThatBlinkTheirNamesAreLabelledFromTheStartAndCalibrated) {
  int unflagged = 0;
  for (std::uint64_t seed = 4; seed <= 6; ++seed) {
    const RenderedRun r = identical_leds_run(seed, 15.0, 8);
    const mc::calibration::DetectionReport& d = r.detection;
    // Measured: rigs 5 and 6 none wrong in any pass; rig 4, whose reflections leave the image
    // and cross often, 1 of 1,711 in the last pass (the bar is none: a name carried onto
    // a crossing reflection is caught only at its marker's next dark frame).
    EXPECT_LE(d.wrong_labels * 1000, d.markers_labelled) << "seed " << seed;
    EXPECT_GE(d.markers_labelled, d.markers_drawn * 85 / 100) << "seed " << seed;
    if (!r.consistent) continue;
    ++unflagged;
    EXPECT_LT(r.nees, 37.7) << "seed " << seed;  // chi-square, 15 dof, 99.9 %
  }
  EXPECT_GE(unflagged, 2);
}

// A real room in the frames (sim --frames --room): two lights of the room and each LED's ghost in
// the mirror, an exposure that clips the brightest LED, motion blur. With the brightness code and
// with identical LEDs, on three random rigs each: every calibration is as the self-check says,
// flagged, or consistent with its NEES within the 99.9 % quantile and no label against the truth
// in the last pass. Measured: with the code rigs 4 and 5 consistent (0 wrong labels, NEES 10.8
// each), rig 6 flagged (half its reflections labelled); identical LEDs, all three flagged.
TEST(RealRoom, RenderedFramesOfRandomRigsAreRightOrFlagged) {
  for (const bool identical : {false, true}) {
    int unflagged = 0;
    for (std::uint64_t seed = 4; seed <= 6; ++seed) {
      mc::evaluation::FrameMode mode;
      mode.room = true;
      mode.identical_leds = identical;
      const RenderedRun r = rendered_run(seed, 20.0, mode);
      if (!r.consistent) continue;
      ++unflagged;
      EXPECT_EQ(r.detection.wrong_labels, 0u) << "seed " << seed << " identical " << identical;
      EXPECT_LT(r.nees, 39.3) << "seed " << seed << " identical " << identical;  // 16 dof, 99.9 %
    }
    // Identical LEDs in a room are often flagged today (docs/campaign/room: 29 of 50 not).
    if (!identical) {
      EXPECT_GE(unflagged, 2);
    }
  }
}

// A pass whose identification failed is followed by others, as one that gated too many is: on the
// paper's rig with this seed, the first pass took 10 wrong labels in its first frames (labelled by
// brightness while the prediction was vague) and diverged, and the second, started from it,
// labelled 6 of 8,764 reflections. The passes after it start again from the guesses (Passes) and
// label the markers.
TEST(FramesCalibration, APassWhoseIdentificationFailedIsFollowedByAnother) {
  const std::uint64_t seed = 16005901576247775254ull;
  mc::evaluation::FrameMode mode;
  mode.enabled = true;
  const auto run = mc::evaluation::run_simulation<3>(mc::sim::paper_scenario(), seed, {}, mode);
  const mc::calibration::DetectionReport& d = run.detection;
  EXPECT_GT(run.result.passes, mc::calibration::kDefaultPasses);
  EXPECT_FALSE(mc::calibration::identification_failed(run.result));
  EXPECT_GT(double(d.markers_labelled), 0.9 * double(d.markers_drawn));
  EXPECT_EQ(d.wrong_labels, 0u);
  EXPECT_LT(run.history.back().nees, 39.3);  // 16 dof, 99.9 %
}
