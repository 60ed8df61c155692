// A camera triggered by the board: the camera's trigger input, a GPIO output, driven from the IMU
// stream, so that exposures start on IMU sample times at a rate the board sets; and the markers'
// LEDs, set for each exposure as their blink code has it (hal/blink_code.hpp), locked to the
// frames by the pulses' count.
#pragma once

#include <array>
#include <cstdint>

#include "mirrorcal/hal/blink_code.hpp"
#include "mirrorcal/hal/lines.hpp"
#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::loop {

// The markers' LEDs blinking their names: show(sequence) sets each as the code has it in frame
// `sequence`, writing only the lines that change.
class BlinkingLeds {
 public:
  static constexpr int kMaxLeds = 16;
  // lines[i]: marker i's LED (count <= kMaxLeds), all lit to begin with.
  BlinkingLeds(hal::OutputLine* const* lines, int count, const hal::BlinkCode& code);
  // False when a line failed (error() says which).
  bool show(std::uint32_t sequence);
  const char* error() const { return failed_ != nullptr ? failed_->error() : ""; }
  int count() const { return count_; }
  const hal::BlinkCode& code() const { return code_; }

 private:
  std::array<hal::OutputLine*, kMaxLeds> lines_{};
  std::array<bool, kMaxLeds> lit_{};
  int count_;
  hal::BlinkCode code_;
  hal::OutputLine* failed_ = nullptr;
};

// Passes the IMU stream on and drives the trigger line active on every `every`-th sample (every
// >= 2), starting with the first, and inactive at the next one: a pulse one IMU period long.
// With LEDs, pulse n (from 0) exposes frame n of their code: they are set just before it. A line
// that fails ends the stream with its message.
class TriggeringImu final : public hal::ImuSource {
 public:
  TriggeringImu(hal::ImuSource& device, hal::OutputLine& trigger, int every,
                BlinkingLeds* leds = nullptr)
      : device_(device), trigger_(trigger), every_(every < 2 ? 2 : every), leds_(leds) {}
  ~TriggeringImu() override;  // leaves the line inactive
  TriggeringImu(const TriggeringImu&) = delete;
  TriggeringImu& operator=(const TriggeringImu&) = delete;

  hal::SourceStatus next(ImuSample& s) override;
  const char* error() const override {
    if (leds_failed_) return leds_->error();
    return failed_ ? trigger_.error() : device_.error();
  }
  std::int64_t wait_ns() const override { return device_.wait_ns(); }
  std::uint64_t pulses() const { return pulses_; }
  int every() const { return every_; }

 private:
  hal::ImuSource& device_;
  hal::OutputLine& trigger_;
  int every_;
  BlinkingLeds* leds_;
  std::uint64_t samples_ = 0, pulses_ = 0;
  bool active_ = false, failed_ = false, leds_failed_ = false;
};

}  // namespace mirrorcal::loop
