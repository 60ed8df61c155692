// A camera triggered by the board: the camera's trigger input, a GPIO output, driven from the IMU
// stream, so that exposures start on IMU sample times at a rate the board sets.
#pragma once

#include <cstdint>

#include "mirrorcal/hal/lines.hpp"
#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::firmware {

// Passes the IMU stream on and drives the trigger line active on every `every`-th sample (every
// >= 2), starting with the first, and inactive at the next one: a pulse one IMU period long. A
// line that fails ends the stream with its message.
class TriggeringImu final : public hal::ImuSource {
 public:
  TriggeringImu(hal::ImuSource& device, hal::TriggerLine& trigger, int every)
      : device_(device), trigger_(trigger), every_(every < 2 ? 2 : every) {}
  ~TriggeringImu() override;  // leaves the line inactive
  TriggeringImu(const TriggeringImu&) = delete;
  TriggeringImu& operator=(const TriggeringImu&) = delete;

  hal::SourceStatus next(ImuSample& s) override;
  const char* error() const override { return failed_ ? trigger_.error() : device_.error(); }
  std::int64_t wait_ns() const override { return device_.wait_ns(); }
  std::uint64_t pulses() const { return pulses_; }
  int every() const { return every_; }

 private:
  hal::ImuSource& device_;
  hal::TriggerLine& trigger_;
  int every_;
  std::uint64_t samples_ = 0, pulses_ = 0;
  bool active_ = false, failed_ = false;
};

}  // namespace mirrorcal::firmware
