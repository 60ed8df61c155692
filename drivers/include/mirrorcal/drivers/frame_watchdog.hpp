// A camera that stops delivering frames mid-run (unplugged, its stream stalled, a sensor that hangs
// or drops every buffer) shows in a non-blocking poll only as kNotReady, for ever: the loop would
// carry on without markers and say nothing. FrameWatchdog turns a silence longer than its timeout
// into kError, with a message naming the device, so the run ends with the reason. Any source at
// the HAL boundary (a V4L2 capture on the board, a fake in tests); nothing allocates after
// construction.
#pragma once

#include <cstdint>
#include <string>

#include "mirrorcal/drivers/driver_error.hpp"
#include "mirrorcal/hal/frames.hpp"

namespace mirrorcal::drivers {

class FrameWatchdog final : public hal::FrameSource {
 public:
  // The silence a camera is allowed: the frame period's worth of slack a driver may take (dropped
  // buffers, a slow first frame after STREAMON), never less than kMinTimeoutNs.
  static constexpr std::int64_t kMinTimeoutNs = 2'000'000'000;
  static constexpr int kPeriods = 20;
  static std::int64_t timeout_for(std::int64_t frame_period_ns) {
    return frame_period_ns * kPeriods > kMinTimeoutNs ? frame_period_ns * kPeriods : kMinTimeoutNs;
  }

  // Counts the silence on clock from the first poll; device names the camera in the message.
  FrameWatchdog(hal::FrameSource& inner, hal::Clock& clock, const std::string& device,
                std::int64_t timeout_ns)
      : inner_(inner), clock_(clock), device_(device), timeout_ns_(timeout_ns) {}

  hal::SourceStatus poll(hal::FrameView& frame) override {
    if (failed_) return hal::SourceStatus::kError;
    const hal::SourceStatus st = inner_.poll(frame);
    const std::int64_t now = clock_.now_ns();
    if (st == hal::SourceStatus::kOk || last_frame_ns_ < 0) last_frame_ns_ = now;
    if (st != hal::SourceStatus::kNotReady || now - last_frame_ns_ <= timeout_ns_) return st;
    failed_ = true;
    error_.set("%s: stops answering: no frame for %lld ms (%llu delivered before)", device_.c_str(),
               static_cast<long long>((now - last_frame_ns_) / 1'000'000),
               static_cast<unsigned long long>(inner_.counters().frames));
    return hal::SourceStatus::kError;
  }
  const char* error() const override { return failed_ ? error_.c_str() : inner_.error(); }
  hal::FrameCounters counters() const override { return inner_.counters(); }
  std::int64_t timeout_ns() const { return timeout_ns_; }

 private:
  hal::FrameSource& inner_;
  hal::Clock& clock_;
  std::string device_;
  std::int64_t timeout_ns_;
  std::int64_t last_frame_ns_ = -1;
  bool failed_ = false;
  ErrorText error_;
};

}  // namespace mirrorcal::drivers
