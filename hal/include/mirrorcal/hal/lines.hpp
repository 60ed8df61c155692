// Digital lines the loop may use beside the sensor streams: the IMU's data-ready output (the loop
// wakes on its rising edges, timestamped by the kernel), and outputs the board drives: a camera's
// trigger input, the markers' LEDs (hal/blink_code.hpp). Implemented by drivers/ (libgpiod) on the
// board and by fakes in tests; no Linux headers.
#pragma once

#include <cstdint>

#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::hal {

// Rising edges of a data-ready line, each with its time on the loop's clock.
class DataReadyLine {
 public:
  virtual ~DataReadyLine() = default;
  // Waits up to timeout_ns for the next rising edge: kOk with its time in t_ns, kNotReady when
  // none came in time, kError when the line failed (error() says why). Edges that queued up since
  // the last call (the loop was late) give the newest one's time: a part's data registers hold
  // only its newest sample, and the caller sees the gap to the previous edge as missed samples.
  virtual SourceStatus wait_rising(std::int64_t timeout_ns, std::int64_t& t_ns) = 0;
  virtual const char* error() const { return ""; }
};

// An output line: the camera's trigger input, a marker's LED.
class OutputLine {
 public:
  virtual ~OutputLine() = default;
  // Drives the line (true: active); false when the line failed (error() says why).
  virtual bool set(bool active) = 0;
  virtual const char* error() const { return ""; }
};

}  // namespace mirrorcal::hal
