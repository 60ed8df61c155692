#include "mirrorcal/firmware/triggering_imu.hpp"

namespace mirrorcal::firmware {

TriggeringImu::~TriggeringImu() {
  if (active_) trigger_.set(false);
}

hal::SourceStatus TriggeringImu::next(ImuSample& s) {
  if (failed_) return hal::SourceStatus::kError;
  const hal::SourceStatus st = device_.next(s);
  if (st != hal::SourceStatus::kOk) return st;
  const bool fire = samples_++ % static_cast<std::uint64_t>(every_) == 0;
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

}  // namespace mirrorcal::firmware
