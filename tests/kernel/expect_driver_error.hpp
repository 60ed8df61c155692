// For guest programs that check how a driver refuses a device: fn must throw a DriverError of the
// given fault; what it says is printed, so the test log shows the message a user would see.
#pragma once

#include <cstdio>

#include "guest_check.hpp"
#include "mirrorcal/drivers/driver_error.hpp"

namespace mirrorcal::guest {

template <class Fn>
void expect_driver_error(const char* what, drivers::Fault fault, Fn fn) {
  try {
    fn();
    std::printf("FAILED: %s: opened\n", what);
    GUEST_CHECK(false);
  } catch (const drivers::DriverError& e) {
    std::printf("%s: %s\n", what, e.what());
    GUEST_CHECK(e.fault() == fault);
  }
}

}  // namespace mirrorcal::guest
