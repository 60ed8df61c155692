#include "mirrorcal/loop/triggering_imu.hpp"

namespace mirrorcal::loop {

BlinkingLeds::BlinkingLeds(hal::OutputLine* const* lines, int count, const hal::BlinkCode& code)
    : count_(count < 0          ? 0
             : count > kMaxLeds ? kMaxLeds
                                : count),
      code_(code) {
  for (int i = 0; i < count_; ++i) {
    lines_[std::size_t(i)] = lines[i];
    lit_[std::size_t(i)] = true;
  }
}

bool BlinkingLeds::show(std::uint32_t sequence) {
  for (int i = 0; i < count_; ++i) {
    const bool lit = code_.lit(i, count_, sequence);
    if (lit == lit_[std::size_t(i)]) continue;
    if (!lines_[std::size_t(i)]->set(lit)) {
      failed_ = lines_[std::size_t(i)];
      return false;
    }
    lit_[std::size_t(i)] = lit;
  }
  return true;
}

TriggeringImu::~TriggeringImu() {
  if (active_) trigger_.set(false);
}

hal::SourceStatus TriggeringImu::next(ImuSample& s) {
  if (failed_) return hal::SourceStatus::kError;
  const hal::SourceStatus st = device_.next(s);
  if (st != hal::SourceStatus::kOk) return st;
  const bool fire = samples_++ % static_cast<std::uint64_t>(every_) == 0;
  if (fire && leds_ != nullptr && !leds_->show(static_cast<std::uint32_t>(pulses_))) {
    failed_ = leds_failed_ = true;
    return hal::SourceStatus::kError;
  }
  if (active_ != fire) {
    if (!trigger_.set(fire)) {
      failed_ = true;
      return hal::SourceStatus::kError;
    }
    active_ = fire;
  }
  if (fire) ++pulses_;
  return st;
}

}  // namespace mirrorcal::loop
