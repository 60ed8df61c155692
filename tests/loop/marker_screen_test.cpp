// The marker screen on frames whose truth is known: reflections of a rigid rig that translate,
// turn and grow in the image, with pixel noise, and the detector's mistakes put in by hand.
#include "mirrorcal/loop/marker_screen.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace {

using mirrorcal::MarkerFrame;
using mirrorcal::loop::MarkerScreen;
using mirrorcal::loop::MarkerScreenConfig;

constexpr int kM = 4;
constexpr double kPixelSigma = 1.0;
constexpr std::int64_t kFramePeriodNs = 50'000'000;  // 20 Hz, the family's slowest camera

// Frame k of markers about a centre that sweeps across the image at up to 60 px a frame, turning
// about the camera's axis at up to 0.1 rad a frame and scaling by 10 %: every marker seen.
class RigidRig {
 public:
  explicit RigidRig(unsigned seed) : rng_(seed) {}
  MarkerFrame<kM> frame(int k) {
    const double t = k * 0.05;
    const Eigen::Vector2d centre(320.0 + 250.0 * std::sin(2.4 * t),
                                 240.0 + 180.0 * std::cos(3.1 * t));
    const double angle = 0.6 * std::sin(3.2 * t), scale = 1.0 + 0.1 * std::sin(1.7 * t);
    const Eigen::Matrix2d turn = Eigen::Rotation2Dd(angle).toRotationMatrix();
    MarkerFrame<kM> f;
    f.t_ns = k * kFramePeriodNs;
    for (std::size_t i = 0; i < kM; ++i) {
      f.seen[i] = true;
      f.uv[i] = centre + scale * (turn * kLayout[i]) +
                kPixelSigma * Eigen::Vector2d(noise_(rng_), noise_(rng_));
    }
    return f;
  }

 private:
  static inline const std::array<Eigen::Vector2d, kM> kLayout = {
      Eigen::Vector2d(-60, -40), Eigen::Vector2d(70, -30), Eigen::Vector2d(10, 80),
      Eigen::Vector2d(-50, 50)};
  std::mt19937 rng_;
  std::normal_distribution<double> noise_;
};

// Shows the screen the rig's first n frames, as they come.
void show(RigidRig& rig, MarkerScreen<kM>& screen, int n, bool confirm = false) {
  for (int k = 0; k < n; ++k) {
    MarkerFrame<kM> f = rig.frame(k);
    screen.screen(f, confirm);
  }
}

TEST(MarkerScreen, WithholdsNothingOfARigidRig) {
  RigidRig rig(1);
  MarkerScreen<kM> screen(MarkerScreenConfig{}, kPixelSigma);
  int withheld = 0;
  for (int k = 0; k < 2000; ++k) {
    MarkerFrame<kM> f = rig.frame(k);
    withheld += screen.screen(f, false);
  }
  EXPECT_EQ(withheld, 0);
}

TEST(MarkerScreen, WithholdsAWrongBlobAndTakesTheMarkerBackNextFrame) {
  RigidRig rig(2);
  MarkerScreen<kM> screen(MarkerScreenConfig{}, kPixelSigma);
  show(rig, screen, 10);
  MarkerFrame<kM> wrong = rig.frame(10);
  wrong.uv[2] += Eigen::Vector2d(150.0, -90.0);  // a room light taken for marker 2
  EXPECT_EQ(screen.screen(wrong, false), 1);
  EXPECT_FALSE(wrong.seen[2]);
  EXPECT_TRUE(wrong.seen[0] && wrong.seen[1] && wrong.seen[3]);
  EXPECT_EQ(screen.rejected(2), 1u);
  EXPECT_TRUE(screen.withheld_from(wrong.t_ns)[2]);
  // Its reference moved with the others' step: the next frame's true reflection is taken.
  MarkerFrame<kM> next = rig.frame(11);
  EXPECT_EQ(screen.screen(next, false), 0);
  EXPECT_TRUE(next.seen[2]);
}

TEST(MarkerScreen, WithholdsTwoSwappedLabels) {
  RigidRig rig(3);
  MarkerScreen<kM> screen(MarkerScreenConfig{}, kPixelSigma);
  show(rig, screen, 10);
  MarkerFrame<kM> swapped = rig.frame(10);
  std::swap(swapped.uv[0], swapped.uv[1]);
  EXPECT_EQ(screen.screen(swapped, false), 2);
  EXPECT_FALSE(swapped.seen[0]);
  EXPECT_FALSE(swapped.seen[1]);
  EXPECT_TRUE(swapped.seen[2] && swapped.seen[3]);
}

TEST(MarkerScreen, OfTwoThatDisagreeWithholdsBoth) {
  RigidRig rig(4);
  MarkerScreen<kM> screen(MarkerScreenConfig{}, kPixelSigma);
  for (int k = 0; k < 5; ++k) {
    MarkerFrame<kM> f = rig.frame(k);
    f.seen[2] = f.seen[3] = false;
    screen.screen(f, false);
  }
  // Frames in which only markers 0 and 1 were ever seen; then 1 jumps.
  MarkerFrame<kM> f = rig.frame(5);
  f.seen[2] = f.seen[3] = false;
  f.uv[1] += Eigen::Vector2d(0.0, 200.0);
  EXPECT_EQ(screen.screen(f, false), 2);
  EXPECT_FALSE(f.seen[0] || f.seen[1]);
}

TEST(MarkerScreen, UnconfirmedMarkersWaitForASecondFrameWhenAsked) {
  RigidRig rig(5);
  MarkerScreen<kM> screen(MarkerScreenConfig{}, kPixelSigma);
  MarkerFrame<kM> first = rig.frame(0);
  first.uv[3] = Eigen::Vector2d(600.0, 20.0);  // the first frame's marker 3 is a wrong blob
  EXPECT_EQ(screen.screen(first, true), 0);    // unconfirmed: withheld, not counted as screened
  for (std::size_t i = 0; i < kM; ++i) EXPECT_FALSE(first.seen[i]) << i;
  EXPECT_TRUE(screen.withheld_from(first.t_ns)[3]);
  // The second frame confirms 0..2; 3's reference was the wrong blob: withheld, until that
  // reference lapses and a later frame confirms the true reflection.
  MarkerFrame<kM> second = rig.frame(1);
  EXPECT_EQ(screen.screen(second, true), 1);
  EXPECT_TRUE(second.seen[0] && second.seen[1] && second.seen[2]);
  EXPECT_FALSE(second.seen[3]);
  bool back = false;
  for (int k = 2; k < 10 && !back; ++k) {
    MarkerFrame<kM> f = rig.frame(k);
    screen.screen(f, true);
    back = f.seen[3];
  }
  EXPECT_TRUE(back);
  // Without confirm, a first sighting is taken as it comes.
  MarkerScreen<kM> trusting(MarkerScreenConfig{}, kPixelSigma);
  MarkerFrame<kM> taken = rig.frame(20);
  EXPECT_EQ(trusting.screen(taken, false), 0);
  for (std::size_t i = 0; i < kM; ++i) EXPECT_TRUE(taken.seen[i]) << i;
}

TEST(MarkerScreen, ForgetsItsReferencesAcrossAGapInTheFrames) {
  RigidRig rig(6);
  MarkerScreen<kM> screen(MarkerScreenConfig{}, kPixelSigma);
  show(rig, screen, 5);
  // Two seconds later the rig is elsewhere: nothing to judge against, nothing withheld.
  MarkerFrame<kM> later = rig.frame(45);
  later.uv[1] += Eigen::Vector2d(300.0, 0.0);
  EXPECT_EQ(screen.screen(later, false), 0);
  EXPECT_TRUE(later.seen[1]);
}

TEST(MarkerScreen, DisabledItWithholdsNothing) {
  RigidRig rig(7);
  MarkerScreenConfig off;
  off.enabled = false;
  MarkerScreen<kM> screen(off, kPixelSigma);
  show(rig, screen, 5, true);
  MarkerFrame<kM> wrong = rig.frame(5);
  wrong.uv[0] += Eigen::Vector2d(200.0, 200.0);
  EXPECT_EQ(screen.screen(wrong, true), 0);
  EXPECT_TRUE(wrong.seen[0]);
}

}  // namespace
