// What a camera's marker detection reported, frame by frame, and HAL sources that replay IMU
// samples and such frames from memory to the loop (a recording read whole, or a simulated run).
#pragma once

#include <cstdint>
#include <vector>

#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::io {

struct ObservedMarker {
  int id = 0;
  double u = 0.0, v = 0.0;
};

struct ObservedFrame {
  std::int64_t t_ns = 0;
  std::vector<ObservedMarker> markers;  // the reflections in the image, any subset
};

// Replays recorded or simulated IMU samples.
class VectorImuSource final : public hal::ImuSource {
 public:
  explicit VectorImuSource(const std::vector<ImuSample>& samples) : samples_(samples) {}
  hal::SourceStatus next(ImuSample& sample) override {
    if (next_ >= samples_.size()) return hal::SourceStatus::kEndOfStream;
    sample = samples_[next_++];
    return hal::SourceStatus::kOk;
  }

 private:
  const std::vector<ImuSample>& samples_;
  std::size_t next_ = 0;
};

// Replays observed frames; markers with an id at or above M are ignored (the loader refuses them).
template <int M>
class VectorMarkerSource final : public hal::MarkerSource<M> {
 public:
  explicit VectorMarkerSource(const std::vector<ObservedFrame>& frames) : frames_(frames) {}
  hal::SourceStatus poll(MarkerFrame<M>& frame) override {
    if (next_ >= frames_.size()) return hal::SourceStatus::kEndOfStream;
    const ObservedFrame& f = frames_[next_++];
    frame.t_ns = f.t_ns;
    frame.seen.fill(false);
    for (const ObservedMarker& m : f.markers) {
      if (m.id < 0 || m.id >= M) continue;
      frame.seen[static_cast<std::size_t>(m.id)] = true;
      frame.uv[static_cast<std::size_t>(m.id)] = Eigen::Vector2d(m.u, m.v);
    }
    return hal::SourceStatus::kOk;
  }

 private:
  const std::vector<ObservedFrame>& frames_;
  std::size_t next_ = 0;
};

}  // namespace mirrorcal::io
