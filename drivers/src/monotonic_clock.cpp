#include "mirrorcal/drivers/monotonic_clock.hpp"

#include <poll.h>

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

int Timebase::wait_readable(int fd, std::int64_t timeout_ns) {
  pollfd p{fd, POLLIN, 0};
  const int ready = ::poll(&p, 1, static_cast<int>((timeout_ns + 999'999) / 1'000'000));
  return ready < 0 ? -1 : ready > 0 ? 1 : 0;
}

Timebase& monotonic_timebase() {
  static MonotonicClock clock;
  return clock;
}

}  // namespace mirrorcal::drivers
