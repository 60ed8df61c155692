// The V4L2 driver without a device: its messages for what a user meets without the right one, and
// the clock frames are timed on. The kernel tests (label kernel) run it against vivid for the rest.
#include <gtest/gtest.h>

#include <linux/videodev2.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "mirrorcal/drivers/v4l2.hpp"

namespace mc = mirrorcal;

TEST(V4l2Errors, MissingDeviceIsNamed) {
  mc::drivers::V4l2Capture cam;
  EXPECT_FALSE(cam.open("/dev/video-mirrorcal-none", {}));
  EXPECT_EQ(std::string(cam.error()), "/dev/video-mirrorcal-none: no such device");
  EXPECT_EQ(cam.fault(), mc::drivers::Fault::kMissing);
  mc::hal::FrameView v;
  EXPECT_EQ(cam.poll(v), mc::hal::SourceStatus::kError);
}

TEST(V4l2Errors, SomethingElseIsNotAV4l2Device) {
  for (const char* path : {"/dev/null", "/proc/self/cmdline"}) {
    mc::drivers::V4l2Capture cam;
    EXPECT_FALSE(cam.open(path, {}));
    EXPECT_EQ(std::string(cam.error()), std::string(path) + " is not a V4L2 device");
    EXPECT_EQ(cam.fault(), mc::drivers::Fault::kWrongKind);
    EXPECT_FALSE(cam.is_open());
  }
  mc::drivers::V4l2Output out;
  EXPECT_FALSE(out.open("/dev/null", {}));
  EXPECT_EQ(std::string(out.error()), "/dev/null is not a V4L2 device");
  EXPECT_FALSE(out.write(nullptr, 0, 0));
}

TEST(V4l2Errors, FramesAreTimedOnTheLoopsClockOnly) {
  // A driver stamping on CLOCK_MONOTONIC keeps its time (the exposure's, not the dequeue's); one
  // that copies timestamps (memory-to-memory devices) or leaves them unknown is on no clock the
  // IMU's can be compared with, so the dequeue time stands in.
  const std::int64_t buffer_ns = 5'000'000'000, dequeued_ns = 5'020'000'000;
  EXPECT_EQ(
      mc::drivers::capture_time_ns(V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE,
                                   buffer_ns, dequeued_ns),
      buffer_ns);
  for (const std::uint32_t other : {V4L2_BUF_FLAG_TIMESTAMP_COPY, V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN})
    EXPECT_EQ(mc::drivers::capture_time_ns(other | V4L2_BUF_FLAG_MAPPED, buffer_ns, dequeued_ns),
              dequeued_ns);
}

TEST(V4l2Errors, StartBeforeOpenFails) {
  mc::drivers::V4l2Capture cam;
  EXPECT_FALSE(cam.start());
  EXPECT_NE(std::string(cam.error()).find("not open"), std::string::npos);
}
