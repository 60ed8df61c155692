// GPIO on a real kernel (arm64 virt, PL061 /dev/gpiochip0, libgpiod 1.6): line 3 is the power
// button, which qemu pulses (a rising edge, a falling edge about 100 ms later) on each
// system_powerdown; the guest asks the harness for one with "@@qemu-monitor system_powerdown".
// The data-ready driver must deliver exactly one rising edge per pulse, with kernel timestamps on
// CLOCK_MONOTONIC, and of edges that queued up while nobody waited only the newest; the trigger
// driver drives another line and reads it back; a held line, a line the chip lacks and a missing
// chip give their messages.
#include <unistd.h>

#include <cstdio>
#include <memory>

#include "expect_driver_error.hpp"
#include "guest_check.hpp"
#include "mirrorcal/drivers/device_spec.hpp"
#include "mirrorcal/drivers/gpio_lines.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"

namespace {

using namespace mirrorcal;
using namespace mirrorcal::drivers;

}  // namespace

int main() {
  try {
    GpioDataReady drdy(parse_line_spec("gpiochip0:3"));
    const int pulses = 3;
    std::int64_t last = 0;
    for (int i = 0; i < pulses; ++i) {
      const std::int64_t before = monotonic_ns();
      std::printf("@@qemu-monitor system_powerdown\n");
      std::fflush(stdout);
      std::int64_t t = 0;
      const hal::SourceStatus s = drdy.wait_rising(5'000'000'000, t);
      const std::int64_t after = monotonic_ns();
      if (!GUEST_CHECK(s == hal::SourceStatus::kOk)) break;
      std::printf("edge %d at %lld ns, %.3f ms after the request, %.3f ms before the wake-up\n", i,
                  static_cast<long long>(t), (t - before) / 1e6, (after - t) / 1e6);
      GUEST_CHECK(t >= before && t <= after);  // a CLOCK_MONOTONIC time of this boot
      GUEST_CHECK(t > last);
      last = t;
      usleep(300'000);  // past the falling edge, which must not show up as a rising one
    }
    std::int64_t t = 0;
    GUEST_CHECK(drdy.wait_rising(300'000'000, t) == hal::SourceStatus::kNotReady);
    GUEST_CHECK(drdy.edges() == static_cast<std::uint64_t>(pulses));

    // A loop that comes late finds several edges queued: it gets the newest one's time (the
    // part's registers hold the newest sample), and the older ones are counted, not delivered.
    std::int64_t last_request = 0;
    for (int i = 0; i < pulses; ++i) {
      last_request = monotonic_ns();
      std::printf("@@qemu-monitor system_powerdown\n");
      std::fflush(stdout);
      usleep(300'000);
    }
    const hal::SourceStatus queued = drdy.wait_rising(1'000'000'000, t);
    std::printf("%d queued edges: newest at %lld ns, %.3f ms after the last request\n", pulses,
                static_cast<long long>(t), (t - last_request) / 1e6);
    GUEST_CHECK(queued == hal::SourceStatus::kOk);
    GUEST_CHECK(t >= last_request && t > last);
    GUEST_CHECK(drdy.edges() == static_cast<std::uint64_t>(2 * pulses));
    GUEST_CHECK(drdy.wait_rising(300'000'000, t) == hal::SourceStatus::kNotReady);

    guest::expect_driver_error("busy", Fault::kBusy,
                               [] { GpioDataReady again(parse_line_spec("gpiochip0:3")); });
    guest::expect_driver_error("busy trigger", Fault::kBusy,
                               [] { GpioOutput trigger(parse_line_spec("gpiochip0:3")); });

    GpioOutput trigger(parse_line_spec("/dev/gpiochip0:0"));
    for (const bool level : {true, false, true, false}) {
      GUEST_CHECK(trigger.set(level));
      GUEST_CHECK(trigger.get() == level);
    }
  } catch (const DriverError& e) {
    std::printf("FAILED: %s\n", e.what());
    GUEST_CHECK(false);
  }
  guest::expect_driver_error("no such line", Fault::kMissing,
                             [] { GpioDataReady l(parse_line_spec("gpiochip0:8")); });
  guest::expect_driver_error("no such chip", Fault::kMissing,
                             [] { GpioDataReady l(parse_line_spec("gpiochip7:0")); });
  return mirrorcal::guest::finish("kernel GPIO");
}
