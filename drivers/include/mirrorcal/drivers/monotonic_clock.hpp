// The board's time base: CLOCK_MONOTONIC in nanoseconds (docs/design.md, "Frames and conventions").
#pragma once

#include <cstdint>

#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::drivers {

std::int64_t monotonic_ns();
std::int64_t realtime_ns();
// Sleeps until CLOCK_MONOTONIC reaches t_ns (at once if it has).
void sleep_until_ns(std::int64_t t_ns);

// What a driver paces and times out by: CLOCK_MONOTONIC on the board; tests give a fake one, so
// that pacing, timeouts and late loops are tested without depending on the machine's scheduling.
class Timebase : public hal::Clock {
 public:
  // Returns once now_ns() has reached t_ns (at once if it has).
  virtual void sleep_until_ns(std::int64_t t_ns) = 0;
  // Waits until fd has data to read or timeout_ns (> 0) has passed on this time base: 1 when it
  // has data, 0 on the timeout, -1 on an error (errno set, EINTR included). By default poll(2)
  // on CLOCK_MONOTONIC; a fake time base moves its own time instead of waiting.
  virtual int wait_readable(int fd, std::int64_t timeout_ns);
};

class MonotonicClock final : public Timebase {
 public:
  std::int64_t now_ns() override { return monotonic_ns(); }
  void sleep_until_ns(std::int64_t t_ns) override { drivers::sleep_until_ns(t_ns); }
};

// The board's CLOCK_MONOTONIC, shared (it has no state).
Timebase& monotonic_timebase();

}  // namespace mirrorcal::drivers
