// GPIO lines through libgpiod 1.6 (Debian 12): the IMU's data-ready output as rising-edge events
// with the kernel's timestamps (CLOCK_MONOTONIC for the character device's line events since
// Linux 5.7), and output lines: the camera's trigger, the markers' LEDs. Opening throws
// DriverError: no such chip or line (missing), the line held by someone else (busy, naming the
// holder).
#pragma once

#include <cstdint>

#include "mirrorcal/drivers/device_spec.hpp"
#include "mirrorcal/drivers/driver_error.hpp"
#include "mirrorcal/hal/lines.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace mirrorcal::drivers {

class GpioDataReady final : public hal::DataReadyLine {
 public:
  explicit GpioDataReady(const LineSpec& spec, const char* consumer = "mirrorcal-drdy");
  ~GpioDataReady() override;
  GpioDataReady(const GpioDataReady&) = delete;
  GpioDataReady& operator=(const GpioDataReady&) = delete;

  hal::SourceStatus wait_rising(std::int64_t timeout_ns, std::int64_t& t_ns) override;
  const char* error() const override { return error_.c_str(); }
  // Rising edges read from the kernel, those skipped for a newer one included.
  std::uint64_t edges() const { return edges_; }

 private:
  gpiod_chip* chip_ = nullptr;
  gpiod_line* line_ = nullptr;
  LineSpec spec_;
  std::uint64_t edges_ = 0;
  ErrorText error_;
};

class GpioOutput final : public hal::OutputLine {
 public:
  // The line starts active if initially_active (a marker's LED lit), else inactive.
  explicit GpioOutput(const LineSpec& spec, bool active_low = false,
                      const char* consumer = "mirrorcal-trigger", bool initially_active = false);
  ~GpioOutput() override;
  GpioOutput(const GpioOutput&) = delete;
  GpioOutput& operator=(const GpioOutput&) = delete;

  bool set(bool active) override;
  // The line's level as the chip reads it back (true: active); false on failure too.
  bool get();
  const char* error() const override { return error_.c_str(); }

 private:
  gpiod_chip* chip_ = nullptr;
  gpiod_line* line_ = nullptr;
  LineSpec spec_;
  ErrorText error_;
};

}  // namespace mirrorcal::drivers
