// vivid (Linux 6.1) set up as a loop-back camera for the guest programs: one HDMI input
// (/dev/video0) shows what is written to one HDMI output (/dev/video1).
// docs/design.md, "Kernel-in-the-loop tests", says how vivid loops video.
#pragma once

#include <fcntl.h>
#include <linux/v4l2-dv-timings.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>

#include "guest_check.hpp"
#include "mirrorcal/drivers/v4l2.hpp"

namespace mirrorcal::guest {

constexpr const char* kVividCapture = "/dev/video0";
constexpr const char* kVividOutput = "/dev/video1";
// vivid's own controls (drivers/media/test-drivers/vivid/vivid-ctrls.c, Linux 6.1).
constexpr std::uint32_t kOsdTextMode = 0x00f0f001;     // 2: no text drawn into frames
constexpr std::uint32_t kLoopVideo = 0x00f0f025;       // capture shows what the output sends
constexpr std::uint32_t kPercentDropped = 0x00f0f040;  // buffers the capture drops

inline bool set_control(int fd, std::uint32_t id, int value) {
  v4l2_control c{};
  c.id = id;
  c.value = value;
  return ioctl(fd, VIDIOC_S_CTRL, &c) == 0;
}

// The id of the control named `name` (vivid's error-injection buttons have no fixed public id),
// 0 when the node has none.
inline std::uint32_t find_control(int fd, const char* name) {
  v4l2_queryctrl q{};
  q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
  while (ioctl(fd, VIDIOC_QUERYCTRL, &q) == 0) {
    if (std::strcmp(reinterpret_cast<const char*>(q.name), name) == 0) return q.id;
    q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
  }
  return 0;
}

// 640x480p59.94. The kernel's macro mixes designated and positional initializers: valid C, an
// extension in C++ that clang warns of.
inline v4l2_dv_timings vga_timings() {
#ifdef __clang__
#pragma clang diagnostic push
#pragma clang diagnostic ignored "-Wc99-designator"
#pragma clang diagnostic ignored "-Wmissing-field-initializers"
#endif
  v4l2_dv_timings timings = V4L2_DV_BT_CEA_640X480P59_94;
#ifdef __clang__
#pragma clang diagnostic pop
#endif
  return timings;
}

// Same DV timings (640x480p59.94) on both nodes, text off, loop on (or not), drops as asked:
// before any stream starts.
inline bool configure_vivid(bool loop, int percent_dropped) {
  const int cap = open(kVividCapture, O_RDWR);
  const int out = open(kVividOutput, O_RDWR);
  bool ok = GUEST_CHECK(cap >= 0 && out >= 0);
  v4l2_dv_timings timings = vga_timings();
  ok = ok && GUEST_CHECK(ioctl(cap, VIDIOC_S_DV_TIMINGS, &timings) == 0);
  timings = vga_timings();
  ok = ok && GUEST_CHECK(ioctl(out, VIDIOC_S_DV_TIMINGS, &timings) == 0);
  ok = ok && GUEST_CHECK(set_control(cap, kOsdTextMode, 2));
  ok = ok && GUEST_CHECK(set_control(cap, kLoopVideo, loop ? 1 : 0));
  ok = ok && GUEST_CHECK(set_control(cap, kPercentDropped, percent_dropped));
  if (cap >= 0) close(cap);
  if (out >= 0) close(out);
  return ok;
}

// 640x480 in the given format, four buffers.
inline drivers::V4l2Config vivid_config(hal::PixelFormat f) {
  drivers::V4l2Config c;
  c.format = f;
  c.width = 640;
  c.height = 480;
  c.buffers = 4;
  return c;
}

}  // namespace mirrorcal::guest
