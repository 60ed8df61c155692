// The V4L2 driver's messages for what a user meets without the right device; the kernel tests
// (label kernel) run it against vivid for the rest.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>

#include "mirrorcal/drivers/v4l2.hpp"

namespace mc = mirrorcal;

TEST(V4l2Errors, MissingDeviceIsNamed) {
  mc::drivers::V4l2Capture cam;
  EXPECT_FALSE(cam.open("/dev/video-mirrorcal-none", {}));
  EXPECT_EQ(std::string(cam.error()), "/dev/video-mirrorcal-none: no such device");
  mc::hal::FrameView v;
  EXPECT_EQ(cam.poll(v), mc::hal::SourceStatus::kError);
}

TEST(V4l2Errors, SomethingElseIsNotAV4l2Device) {
  for (const char* path : {"/dev/null", "/proc/self/cmdline"}) {
    mc::drivers::V4l2Capture cam;
    EXPECT_FALSE(cam.open(path, {}));
    EXPECT_EQ(std::string(cam.error()), std::string(path) + " is not a V4L2 device");
    EXPECT_FALSE(cam.is_open());
  }
  mc::drivers::V4l2Output out;
  EXPECT_FALSE(out.open("/dev/null", {}));
  EXPECT_EQ(std::string(out.error()), "/dev/null is not a V4L2 device");
  EXPECT_FALSE(out.write(nullptr, 0, 0));
}

TEST(V4l2Errors, StartBeforeOpenFails) {
  mc::drivers::V4l2Capture cam;
  EXPECT_FALSE(cam.start());
  EXPECT_NE(std::string(cam.error()).find("not open"), std::string::npos);
}
