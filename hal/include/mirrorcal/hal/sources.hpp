// What the loop sees of the hardware: a clock, a stream of IMU samples, and a stream of marker
// observations (detected in frames by a driver, or synthesised by the simulator). Implemented by
// drivers/ on the board, io/ and sim/ on the host; no Linux headers here.
#pragma once

#include <cstdint>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::hal {

enum class SourceStatus : std::uint8_t {
  kOk,           // an item was delivered
  kNotReady,     // nothing yet (non-blocking sources only)
  kEndOfStream,  // the source is exhausted (a recording ended, the simulation finished)
  kError,        // the device failed; the source says why through error()
};

// The loop's time base: CLOCK_MONOTONIC on the board, simulated time on the host.
class Clock {
 public:
  virtual ~Clock() = default;
  virtual std::int64_t now_ns() = 0;
};

// IMU samples in timestamp order. next() blocks until a sample arrives or the stream ends.
class ImuSource {
 public:
  virtual ~ImuSource() = default;
  virtual SourceStatus next(ImuSample& sample) = 0;
  virtual const char* error() const { return ""; }
  // How much of the last next() went into waiting for the sample (ns): blocked in poll, on the
  // data-ready line or asleep until the next period. The loop's timing budget counts it apart
  // from the cost of reading and decoding; 0 where the samples come ready-made.
  virtual std::int64_t wait_ns() const { return 0; }
};

// Marker observations of each frame, in timestamp order. poll() does not block: it returns the
// next frame if one is available, kNotReady otherwise. A frame may be delivered before the IMU
// has reached its timestamp; the loop holds it until it has.
template <int M>
class MarkerSource {
 public:
  virtual ~MarkerSource() = default;
  virtual SourceStatus poll(MarkerFrame<M>& frame) = 0;
  virtual const char* error() const { return ""; }
  // How much of the last poll that delivered a frame went into detecting its markers (ns), for
  // the loop's timing budget; 0 where the markers come ready-made.
  virtual std::int64_t detection_ns() const { return 0; }
};

}  // namespace mirrorcal::hal
