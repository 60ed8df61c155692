// LEDs that name themselves: the board drives each marker's LED from a GPIO line and darkens it
// in one frame of every `period`, marker i in the frames whose sequence number is i + 1 modulo the
// period (frame 0 of each period, and those after the last marker's, show every LED). A track of
// reflections that goes dark in exactly those frames is marker i, however alike the LEDs look:
// the detection (blink_names.hpp) reads the code, the LED lines and the simulated renderer write
// it. Locked to the camera's frames by the frame's sequence number, so the board's frames must
// be counted as its LEDs were set (a triggered camera: one frame per trigger pulse).
#pragma once

#include <cstdint>

namespace mirrorcal::hal {

struct BlinkCode {
  static constexpr int kMaxPeriod = 64;  // frames: a longer code names its LEDs too slowly

  // Frames per period; 0: the LEDs stay lit (no code). At least M + 1 for M markers: every
  // marker one dark frame, and one frame with all lit.
  int period = 0;

  bool on() const { return period > 0; }
  // Which of `markers` markers is dark in frame `sequence`, or -1 (all lit).
  int dark_marker(std::uint32_t sequence, int markers) const {
    if (period <= 0) return -1;
    const int phase = static_cast<int>(sequence % static_cast<std::uint32_t>(period));
    return phase >= 1 && phase <= markers ? phase - 1 : -1;
  }
  bool lit(int marker, int markers, std::uint32_t sequence) const {
    return dark_marker(sequence, markers) != marker;
  }
};

}  // namespace mirrorcal::hal
