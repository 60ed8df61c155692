// A camera that stops delivering frames, at the HAL boundary: a scripted frame source and a clock
// the test moves. The kernel test (vivid dropping every buffer) checks it on a real driver.
#include <gtest/gtest.h>

#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include "mirrorcal/detection/detecting_marker_source.hpp"
#include "mirrorcal/drivers/frame_watchdog.hpp"

namespace mirrorcal::drivers {
namespace {

constexpr std::int64_t kMs = 1'000'000;

class ManualClock final : public hal::Clock {
 public:
  std::int64_t t = 5'000 * kMs;
  std::int64_t now_ns() override { return t; }
};

// Delivers a blank frame when told to, nothing otherwise; or fails with its own message.
class ScriptedFrames final : public hal::FrameSource {
 public:
  bool frame_ready = false;
  bool broken = false;
  hal::SourceStatus poll(hal::FrameView& f) override {
    if (broken) return hal::SourceStatus::kError;
    if (!frame_ready) return hal::SourceStatus::kNotReady;
    frame_ready = false;
    f = hal::FrameView{};
    f.width = 64;
    f.height = 48;
    f.bytes_per_line = 64;
    f.data = image_.data();
    f.bytes = image_.size();
    ++counters_.frames;
    return hal::SourceStatus::kOk;
  }
  const char* error() const override { return broken ? "cam: VIDIOC_DQBUF failed: EIO" : ""; }
  hal::FrameCounters counters() const override { return counters_; }

 private:
  std::vector<std::uint8_t> image_ = std::vector<std::uint8_t>(64 * 48, 10);
  hal::FrameCounters counters_{};
};

TEST(FrameWatchdog, TimeoutIsTwentyPeriodsButAtLeastTwoSeconds) {
  EXPECT_EQ(FrameWatchdog::timeout_for(16'666'667), 2'000 * kMs);  // 60 Hz
  EXPECT_EQ(FrameWatchdog::timeout_for(200 * kMs), 4'000 * kMs);   // 5 Hz
}

TEST(FrameWatchdog, GapsShorterThanTheTimeoutPassSilenceLongerEndsTheStream) {
  ScriptedFrames frames;
  ManualClock clock;
  FrameWatchdog watchdog(frames, clock, "/dev/video7", 1'000 * kMs);
  hal::FrameView v;
  // Frames with gaps up to the timeout itself: never an error.
  for (const std::int64_t gap : {10, 500, 1'000, 20}) {
    for (std::int64_t waited = 0; waited < gap; waited += 10) {
      ASSERT_EQ(watchdog.poll(v), hal::SourceStatus::kNotReady) << gap;
      clock.t += 10 * kMs;
    }
    frames.frame_ready = true;
    ASSERT_EQ(watchdog.poll(v), hal::SourceStatus::kOk) << gap;
  }
  // Then silence: not ready up to the timeout, an error past it, and for good.
  clock.t += 1'000 * kMs;
  EXPECT_EQ(watchdog.poll(v), hal::SourceStatus::kNotReady);
  clock.t += 1 * kMs;
  EXPECT_EQ(watchdog.poll(v), hal::SourceStatus::kError);
  EXPECT_EQ(std::string(watchdog.error()),
            "/dev/video7: stops answering: no frame for 1001 ms (4 delivered before)");
  frames.frame_ready = true;
  EXPECT_EQ(watchdog.poll(v), hal::SourceStatus::kError);
  EXPECT_EQ(watchdog.counters().frames, 4u);
}

TEST(FrameWatchdog, ACameraThatNeverDeliversIsReportedToo) {
  ScriptedFrames frames;
  ManualClock clock;
  FrameWatchdog watchdog(frames, clock, "/dev/video7", 2'000 * kMs);
  hal::FrameView v;
  clock.t += 60'000 * kMs;  // the run started long before the first poll: count from that poll
  EXPECT_EQ(watchdog.poll(v), hal::SourceStatus::kNotReady);
  clock.t += 2'500 * kMs;
  EXPECT_EQ(watchdog.poll(v), hal::SourceStatus::kError);
  EXPECT_NE(std::string(watchdog.error()).find("no frame for 2500 ms (0 delivered"),
            std::string::npos)
      << watchdog.error();
}

TEST(FrameWatchdog, TheDevicesOwnErrorPassesThroughUnchanged) {
  ScriptedFrames frames;
  ManualClock clock;
  FrameWatchdog watchdog(frames, clock, "/dev/video7", 1'000 * kMs);
  frames.broken = true;
  hal::FrameView v;
  EXPECT_EQ(watchdog.poll(v), hal::SourceStatus::kError);
  EXPECT_EQ(std::string(watchdog.error()), "cam: VIDIOC_DQBUF failed: EIO");
}

// What the loop sees: the detecting marker source over the watched camera fails with the
// watchdog's message (the loop ends with kMarkerError; `run` writes what it has, exits 1).
TEST(FrameWatchdog, TheMarkerSourceOverItFailsWithTheMessage) {
  ScriptedFrames frames;
  ManualClock clock;
  FrameWatchdog watchdog(frames, clock, "/dev/video7", 1'000 * kMs);
  detection::DetectingMarkerSource<3> markers(watchdog, detection::DetectionConfig<3>{}, 64, 48);
  MarkerFrame<3> m;
  frames.frame_ready = true;
  ASSERT_EQ(markers.poll(m), hal::SourceStatus::kOk);
  clock.t += 1'500 * kMs;
  EXPECT_EQ(markers.poll(m), hal::SourceStatus::kError);
  EXPECT_NE(std::string(markers.error()).find("/dev/video7: stops answering"), std::string::npos)
      << markers.error();
}

}  // namespace
}  // namespace mirrorcal::drivers
