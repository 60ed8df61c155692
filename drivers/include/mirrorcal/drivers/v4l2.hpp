// Video4Linux2 camera driver: MMAP streaming capture as a hal::FrameSource, and an output writer
// (used to feed frames into a loop-back device such as vivid's output node in the kernel tests).
//
// Single-planar V4L2 only (V4L2_CAP_VIDEO_CAPTURE / _OUTPUT), progressive frames (field NONE),
// GREY or YUYV. Buffers are requested and mapped once at open(); nothing allocates per frame.
// Errors are kept as a message naming the device (error()); a dropped or damaged frame is counted,
// never fatal.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "mirrorcal/drivers/driver_error.hpp"
#include "mirrorcal/hal/frames.hpp"

namespace mirrorcal::drivers {

struct V4l2Config {
  hal::PixelFormat format = hal::PixelFormat::kGrey;
  int width = 640, height = 480;
  int buffers = 4;  // requested; the driver may grant more (at most kMaxBuffers are used)
  // Take the device's current pixel format when it is GREY or YUYV (else `format`): a camera
  // given without a format keeps what it was set up with.
  bool format_from_device = false;
};

// One V4L2 node streaming memory-mapped buffers in one direction; the shared part of capture and
// output.
class V4l2Stream {
 public:
  static constexpr int kMaxBuffers = 16;

  V4l2Stream(const V4l2Stream&) = delete;
  V4l2Stream& operator=(const V4l2Stream&) = delete;

  bool is_open() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  const char* error() const { return error_; }
  // What kind of failure error() describes (missing, busy, wrong kind, not answering, other).
  Fault fault() const { return fault_; }
  int width() const { return width_; }
  int height() const { return height_; }
  int bytes_per_line() const { return bytes_per_line_; }
  std::size_t size_image() const { return size_image_; }
  int buffer_count() const { return count_; }
  hal::PixelFormat format() const { return format_; }
  // The frame period the driver reports (VIDIOC_G_PARM's timeperframe), 0 if it reports none.
  std::int64_t frame_period_ns() const { return frame_period_ns_; }
  // Stops streaming, unmaps and closes; safe to call twice.
  void close();

 protected:
  explicit V4l2Stream(bool output) : output_(output) {}
  ~V4l2Stream() { close(); }
  bool open_stream(const std::string& path, const V4l2Config& config);
  // The steps of open_stream, in order; one that returns false has closed the device and set
  // error().
  bool open_device();
  bool set_format(const V4l2Config& config);
  void read_frame_period();
  bool map_buffers(const V4l2Config& config);
  bool stream_on();
  bool fail(Fault fault, const char* fmt, ...) __attribute__((format(printf, 3, 4)));
  // Waits up to timeout_ms for the device to be ready (POLLIN for capture, POLLOUT for output):
  // 1 ready, 0 timed out, -1 error (message set).
  int wait_ready(int timeout_ms);

  struct Buffer {
    void* start = nullptr;
    std::size_t length = 0;
  };
  bool output_;
  int fd_ = -1;
  bool streaming_ = false;
  std::string path_;
  char error_[256] = "";
  Fault fault_ = Fault::kIo;
  int width_ = 0, height_ = 0, bytes_per_line_ = 0;
  std::size_t size_image_ = 0;
  hal::PixelFormat format_ = hal::PixelFormat::kGrey;
  std::int64_t frame_period_ns_ = 0;
  std::array<Buffer, kMaxBuffers> buffers_{};
  int count_ = 0;
};

// A captured frame's time on the loop's clock (CLOCK_MONOTONIC): the buffer's own timestamp when
// the driver says it is on that clock (V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, as most drivers), else
// the time it was dequeued (a driver that copies timestamps or leaves them unknown: its times
// are on no clock the IMU's can be compared with, the dequeue is late by the readout and the
// loop's latency, but on the right clock).
std::int64_t capture_time_ns(std::uint32_t buffer_flags, std::int64_t buffer_ns,
                             std::int64_t dequeued_ns);

// Capture: frames in the order the device fills them. The buffer of the frame last delivered
// goes back to the device at the next poll, so the view stays valid until then.
class V4l2Capture final : public V4l2Stream, public hal::FrameSource {
 public:
  V4l2Capture() : V4l2Stream(false) {}
  ~V4l2Capture() override = default;

  // Opens the node, sets the format, maps the buffers and queues them. False with error() set:
  // missing device, not a V4L2 capture device, busy, format not supported.
  bool open(const std::string& path, const V4l2Config& config);
  bool start() { return stream_on(); }

  // Waits up to timeout_ms (0: do not wait, -1: forever) for the next frame.
  hal::SourceStatus wait(int timeout_ms, hal::FrameView& frame);
  hal::SourceStatus poll(hal::FrameView& frame) override { return wait(0, frame); }
  const char* error() const override { return V4l2Stream::error(); }
  hal::FrameCounters counters() const override { return counters_; }

  // Whether the driver's timestamps are CLOCK_MONOTONIC (known after the first frame), and
  // whether they mark the start of exposure rather than the end of the frame.
  bool timestamps_monotonic() const { return monotonic_; }
  bool start_of_exposure() const { return start_of_exposure_; }

 private:
  bool requeue_held();

  int held_ = -1;  // index of the buffer whose frame was delivered last
  bool have_sequence_ = false;
  std::uint32_t last_sequence_ = 0;
  bool monotonic_ = true;
  bool start_of_exposure_ = false;
  hal::FrameCounters counters_{};
};

// Output: frames written are queued to the device, which consumes them at its frame rate.
class V4l2Output final : public V4l2Stream {
 public:
  V4l2Output() : V4l2Stream(true) {}

  bool open(const std::string& path, const V4l2Config& config);
  bool start() { return stream_on(); }

  // Copies one image (rows of src_bytes_per_line bytes, in the configured format and size) into
  // a free buffer and queues it, waiting up to timeout_ms for the device to free one.
  bool write(const std::uint8_t* image, int src_bytes_per_line, int timeout_ms);

  // Buffers free for write() now (the device's finished ones taken back); -1 on error.
  int free_buffers();

  std::uint64_t frames_written() const { return written_; }

  // The mapped memory of the buffer queued last (nullptr before any write). Changing it while the
  // device holds it is outside V4L2's contract, but a loop-back device that copies the output at
  // capture time (vivid) shows the change: a test can keep one frame queued and move what it
  // shows with the clock.
  std::uint8_t* last_written_data() const { return last_; }

 private:
  bool reclaim();  // takes back every buffer the device has finished with

  std::array<bool, kMaxBuffers> free_{};
  std::uint64_t written_ = 0;
  std::uint8_t* last_ = nullptr;
};

}  // namespace mirrorcal::drivers
