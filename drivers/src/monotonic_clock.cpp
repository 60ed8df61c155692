#include "mirrorcal/drivers/monotonic_clock.hpp"

#include <cerrno>
#include <ctime>

namespace mirrorcal::drivers {
namespace {

std::int64_t read_ns(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

std::int64_t monotonic_ns() {
  return read_ns(CLOCK_MONOTONIC);
}
std::int64_t realtime_ns() {
  return read_ns(CLOCK_REALTIME);
}

void sleep_until_ns(std::int64_t t_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(t_ns % 1'000'000'000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

Timebase& monotonic_timebase() {
  static MonotonicClock clock;
  return clock;
}

}  // namespace mirrorcal::drivers
