// Camera frames as the loop's drivers see them: a view of one image in a driver-owned buffer, and
// the source that delivers them (a V4L2 device on the board, a renderer on the host). No Linux
// headers here.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::hal {

// The pixel formats the detection reads. GREY: one luma byte per pixel. YUYV (4:2:2): Y0 U Y1 V
// per two pixels, luma at every even byte.
enum class PixelFormat : std::uint8_t { kGrey, kYuyv };

constexpr int bytes_per_pixel(PixelFormat f) {
  return f == PixelFormat::kGrey ? 1 : 2;
}
constexpr const char* to_string(PixelFormat f) {
  return f == PixelFormat::kGrey ? "GREY" : "YUYV";
}

// Frame flags.
enum FrameFlag : std::uint32_t {
  kFrameCorrupt = 1u << 0,  // the device marked the buffer as damaged (V4L2_BUF_FLAG_ERROR)
  // The timestamp is taken at the start of exposure; without it, at the end of the frame (the
  // last line read out), which is what most V4L2 drivers report.
  kFrameStartOfExposure = 1u << 1,
};

// One image in a buffer the source owns; valid until the source's next poll().
struct FrameView {
  PixelFormat format = PixelFormat::kGrey;
  int width = 0, height = 0;
  int bytes_per_line = 0;  // stride, >= width * bytes_per_pixel(format)
  const std::uint8_t* data = nullptr;
  std::size_t bytes = 0;  // bytes valid at data
  std::int64_t t_ns = 0;  // on the loop's clock (CLOCK_MONOTONIC on the board)
  std::uint32_t sequence = 0;
  std::uint32_t flags = 0;  // FrameFlag bits

  // Luma of pixel (x, y); no bounds check.
  std::uint8_t luma(int x, int y) const {
    return data[static_cast<std::size_t>(y) * static_cast<std::size_t>(bytes_per_line) +
                static_cast<std::size_t>(x) * static_cast<std::size_t>(bytes_per_pixel(format))];
  }
};

// What a source met on its stream; nothing is dropped without being counted here.
struct FrameCounters {
  std::uint64_t frames = 0;    // frames delivered
  std::uint64_t dropped = 0;   // frames missing from the sequence numbers
  std::uint64_t corrupt = 0;   // frames the device flagged as damaged (delivered, flagged)
  std::uint64_t restarts = 0;  // sequence numbers that stepped back (the device restarted)
  // Frames whose device timestamp was not CLOCK_MONOTONIC: stamped when dequeued instead.
  std::uint64_t stamped_at_dequeue = 0;
};

// Frames in timestamp order. poll() does not block: kOk with a view valid until the next poll,
// kNotReady if no frame is waiting.
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  virtual SourceStatus poll(FrameView& frame) = 0;
  virtual const char* error() const { return ""; }
  virtual FrameCounters counters() const { return {}; }
};

// Where the markers' reflections should be in the image at the filter's estimate propagated to
// a frame's time: the predicted pixel and its 2x2 covariance (px^2) from the filter's uncertainty.
template <int M>
struct MarkerPrediction {
  std::array<bool, M> valid{};
  std::array<Eigen::Vector2d, M> uv{};
  std::array<Eigen::Matrix2d, M> covariance{};
};

// A marker source that can label its frames better once it knows where the filter expects the
// markers. The loop (set_identifier) calls relabel() on the frame the source delivered last, after
// propagating the filter to that frame's time and before the update; a source polled early (as the
// loop does, frames are held until the IMU reaches them) would otherwise have only a stale
// prediction.
template <int M>
class MarkerRelabeler {
 public:
  virtual ~MarkerRelabeler() = default;
  virtual void relabel(const MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) = 0;
};

}  // namespace mirrorcal::hal
