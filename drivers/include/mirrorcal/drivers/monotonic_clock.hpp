// The board's time base: CLOCK_MONOTONIC in nanoseconds, as DESIGN.md fixes for the loop.
#pragma once

#include <cstdint>

#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::drivers {

std::int64_t monotonic_ns();
std::int64_t realtime_ns();
// Sleeps until CLOCK_MONOTONIC reaches t_ns (at once if it has).
void sleep_until_ns(std::int64_t t_ns);

class MonotonicClock final : public hal::Clock {
 public:
  std::int64_t now_ns() override { return monotonic_ns(); }
};

}  // namespace mirrorcal::drivers
