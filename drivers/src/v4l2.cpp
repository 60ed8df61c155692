#include "mirrorcal/drivers/v4l2.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "mirrorcal/drivers/monotonic_clock.hpp"

namespace mirrorcal::drivers {

namespace {

// ioctl, retried when a signal interrupts it.
int xioctl(int fd, unsigned long request, void* arg) {
  int r;
  do {
    r = ::ioctl(fd, request, arg);
  } while (r < 0 && errno == EINTR);
  return r;
}

std::uint32_t fourcc_of(hal::PixelFormat f) {
  return f == hal::PixelFormat::kGrey ? V4L2_PIX_FMT_GREY : V4L2_PIX_FMT_YUYV;
}

// "GREY", "YUYV", ... for messages.
struct FourccText {
  char s[5];
};
FourccText fourcc_text(std::uint32_t f) {
  FourccText t{};
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((f >> (8 * i)) & 0xff);
    t.s[i] = (c >= 32 && c < 127) ? c : '?';
  }
  return t;
}

}  // namespace

bool V4l2Stream::fail(Fault fault, const char* fmt, ...) {
  fault_ = fault;
  va_list ap;
  va_start(ap, fmt);
  std::vsnprintf(error_, sizeof error_, fmt, ap);
  va_end(ap);
  return false;
}

void V4l2Stream::close() {
  if (fd_ < 0) return;
  if (streaming_) {
    v4l2_buf_type type = output_ ? V4L2_BUF_TYPE_VIDEO_OUTPUT : V4L2_BUF_TYPE_VIDEO_CAPTURE;
    xioctl(fd_, VIDIOC_STREAMOFF, &type);
    streaming_ = false;
  }
  for (int i = 0; i < count_; ++i) {
    Buffer& b = buffers_[static_cast<std::size_t>(i)];
    if (b.start != nullptr) ::munmap(b.start, b.length);
    b = Buffer{};
  }
  if (count_ > 0) {  // give the buffers back so another program can stream
    v4l2_requestbuffers req{};
    req.count = 0;
    req.type = output_ ? V4L2_BUF_TYPE_VIDEO_OUTPUT : V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    xioctl(fd_, VIDIOC_REQBUFS, &req);
  }
  count_ = 0;
  ::close(fd_);
  fd_ = -1;
}

bool V4l2Stream::open_stream(const std::string& path, const V4l2Config& config) {
  close();
  path_ = path;
  error_[0] = '\0';
  if (!open_device() || !set_format(config)) return false;
  read_frame_period();
  return map_buffers(config);
}

// Opens path_ and checks that it is a single-planar video device of the stream's direction that
// streams.
bool V4l2Stream::open_device() {
  const char* p = path_.c_str();
  const char* what = output_ ? "output" : "capture";

  fd_ = ::open(p, O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) {
    const int e = errno;
    if (e == ENOENT || e == ENODEV || e == ENXIO)
      return fail(Fault::kMissing, "%s: no such device", p);
    if (e == EACCES)
      return fail(Fault::kIo, "%s: permission denied (add the user to group 'video')", p);
    return fail(Fault::kIo, "%s: cannot open: %s", p, std::strerror(e));
  }

  v4l2_capability cap{};
  if (xioctl(fd_, VIDIOC_QUERYCAP, &cap) < 0) {
    const int e = errno;
    close();
    if (e == ENOTTY || e == EINVAL) return fail(Fault::kWrongKind, "%s is not a V4L2 device", p);
    return fail(Fault::kIo, "%s: VIDIOC_QUERYCAP failed: %s", p, std::strerror(e));
  }
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  const std::uint32_t want = output_ ? V4L2_CAP_VIDEO_OUTPUT : V4L2_CAP_VIDEO_CAPTURE;
  const std::uint32_t mplane =
      output_ ? V4L2_CAP_VIDEO_OUTPUT_MPLANE : V4L2_CAP_VIDEO_CAPTURE_MPLANE;
  if ((caps & want) == 0) {
    close();
    if ((caps & mplane) != 0)
      return fail(Fault::kWrongKind,
                  "%s (%s) is a multi-planar video %s device; only single-planar is supported", p,
                  reinterpret_cast<const char*>(cap.card), what);
    return fail(Fault::kWrongKind, "%s (%s) is not a video %s device (device capabilities 0x%08x)",
                p, reinterpret_cast<const char*>(cap.card), what, caps);
  }
  if ((caps & V4L2_CAP_STREAMING) == 0) {
    close();
    return fail(Fault::kWrongKind, "%s (%s) does not support streaming I/O", p,
                reinterpret_cast<const char*>(cap.card));
  }
  return true;
}

// Sets the format config asks for (or the device's own, format_from_device) and keeps what the
// driver granted: the size, stride and image size.
bool V4l2Stream::set_format(const V4l2Config& config) {
  const char* p = path_.c_str();
  const auto buf_type = output_ ? V4L2_BUF_TYPE_VIDEO_OUTPUT : V4L2_BUF_TYPE_VIDEO_CAPTURE;
  hal::PixelFormat format = config.format;
  v4l2_format fmt{};
  fmt.type = buf_type;
  if (config.format_from_device && xioctl(fd_, VIDIOC_G_FMT, &fmt) == 0) {
    if (fmt.fmt.pix.pixelformat == V4L2_PIX_FMT_GREY) format = hal::PixelFormat::kGrey;
    if (fmt.fmt.pix.pixelformat == V4L2_PIX_FMT_YUYV) format = hal::PixelFormat::kYuyv;
  }
  fmt = v4l2_format{};
  fmt.type = buf_type;
  fmt.fmt.pix.width = static_cast<std::uint32_t>(config.width);
  fmt.fmt.pix.height = static_cast<std::uint32_t>(config.height);
  fmt.fmt.pix.pixelformat = fourcc_of(format);
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (xioctl(fd_, VIDIOC_S_FMT, &fmt) < 0) {
    const int e = errno;
    close();
    if (e == EBUSY)
      return fail(Fault::kBusy, "%s is busy (another program is streaming from it)", p);
    return fail(Fault::kIo, "%s: VIDIOC_S_FMT failed: %s", p, std::strerror(e));
  }
  const v4l2_pix_format& got = fmt.fmt.pix;
  if (got.pixelformat != fourcc_of(format) || static_cast<int>(got.width) != config.width ||
      static_cast<int>(got.height) != config.height) {
    const FourccText want_t = fourcc_text(fourcc_of(format)), got_t = fourcc_text(got.pixelformat);
    close();
    return fail(Fault::kWrongKind, "%s does not support %s %dx%d (the driver offers %s %ux%u)", p,
                want_t.s, config.width, config.height, got_t.s, got.width, got.height);
  }
  if (got.field != V4L2_FIELD_NONE && got.field != V4L2_FIELD_ANY) {
    close();
    return fail(Fault::kWrongKind,
                "%s delivers interlaced frames (field %u); only progressive is supported", p,
                got.field);
  }
  format_ = format;
  width_ = config.width;
  height_ = config.height;
  // Honour the driver's stride and image size: rows may be padded.
  const int min_line = width_ * hal::bytes_per_pixel(format_);
  bytes_per_line_ =
      static_cast<int>(got.bytesperline) < min_line ? min_line : static_cast<int>(got.bytesperline);
  size_image_ = got.sizeimage;
  if (size_image_ < static_cast<std::size_t>(bytes_per_line_) * static_cast<std::size_t>(height_)) {
    const std::size_t need =
        static_cast<std::size_t>(bytes_per_line_) * static_cast<std::size_t>(height_);
    close();
    return fail(Fault::kWrongKind, "%s reports an image size of %u bytes, less than %zu for %dx%d",
                p, got.sizeimage, need, width_, height_);
  }
  return true;
}

void V4l2Stream::read_frame_period() {
  const auto buf_type = output_ ? V4L2_BUF_TYPE_VIDEO_OUTPUT : V4L2_BUF_TYPE_VIDEO_CAPTURE;
  // The frame interval, where the driver tells it (capture: timeperframe; output: timeperframe).
  frame_period_ns_ = 0;
  v4l2_streamparm parm{};
  parm.type = buf_type;
  if (xioctl(fd_, VIDIOC_G_PARM, &parm) == 0) {
    const v4l2_fract& tpf =
        output_ ? parm.parm.output.timeperframe : parm.parm.capture.timeperframe;
    if (tpf.numerator > 0 && tpf.denominator > 0)
      frame_period_ns_ =
          static_cast<std::int64_t>(1'000'000'000LL * tpf.numerator / tpf.denominator);
  }
}

// Requests config.buffers memory-mapped buffers (2..kMaxBuffers) and maps those granted.
bool V4l2Stream::map_buffers(const V4l2Config& config) {
  const char* p = path_.c_str();
  const auto buf_type = output_ ? V4L2_BUF_TYPE_VIDEO_OUTPUT : V4L2_BUF_TYPE_VIDEO_CAPTURE;
  v4l2_requestbuffers req{};
  req.count = static_cast<std::uint32_t>(config.buffers < 2 ? 2 : config.buffers);
  if (req.count > kMaxBuffers) req.count = kMaxBuffers;
  req.type = buf_type;
  req.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd_, VIDIOC_REQBUFS, &req) < 0) {
    const int e = errno;
    close();
    if (e == EBUSY)
      return fail(Fault::kBusy, "%s is busy (another program is streaming from it)", p);
    if (e == EINVAL)
      return fail(Fault::kWrongKind, "%s does not support memory-mapped streaming", p);
    return fail(Fault::kIo, "%s: VIDIOC_REQBUFS failed: %s", p, std::strerror(e));
  }
  if (req.count < 2) {
    close();
    return fail(Fault::kWrongKind, "%s granted %u buffers; at least 2 are needed", p, req.count);
  }
  const int granted = req.count > kMaxBuffers ? kMaxBuffers : static_cast<int>(req.count);
  for (int i = 0; i < granted; ++i) {
    v4l2_buffer b{};
    b.type = buf_type;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = static_cast<std::uint32_t>(i);
    if (xioctl(fd_, VIDIOC_QUERYBUF, &b) < 0) {
      const int e = errno;
      close();
      return fail(Fault::kIo, "%s: VIDIOC_QUERYBUF %d failed: %s", p, i, std::strerror(e));
    }
    const int prot = output_ ? PROT_READ | PROT_WRITE : PROT_READ;
    void* m = ::mmap(nullptr, b.length, prot, MAP_SHARED, fd_, b.m.offset);
    if (m == MAP_FAILED) {
      const int e = errno;
      close();
      return fail(Fault::kIo, "%s: mmap of buffer %d failed: %s", p, i, std::strerror(e));
    }
    buffers_[static_cast<std::size_t>(i)] = {m, b.length};
    count_ = i + 1;  // so close() unmaps what is mapped so far
  }
  return true;
}

bool V4l2Stream::stream_on() {
  if (fd_ < 0) return fail(Fault::kIo, "camera not open");
  v4l2_buf_type type = output_ ? V4L2_BUF_TYPE_VIDEO_OUTPUT : V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(fd_, VIDIOC_STREAMON, &type) < 0) {
    const int e = errno;
    if (e == EBUSY)
      return fail(Fault::kBusy, "%s is busy (another program is streaming from it)", path_.c_str());
    return fail(Fault::kIo, "%s: VIDIOC_STREAMON failed: %s", path_.c_str(), std::strerror(e));
  }
  streaming_ = true;
  return true;
}

int V4l2Stream::wait_ready(int timeout_ms) {
  pollfd pfd{fd_, static_cast<short>(output_ ? POLLOUT : POLLIN), 0};
  int r;
  do {
    r = ::poll(&pfd, 1, timeout_ms);
  } while (r < 0 && errno == EINTR);
  if (r < 0) {
    fail(Fault::kIo, "%s: poll failed: %s", path_.c_str(), std::strerror(errno));
    return -1;
  }
  if (r == 0) return 0;
  if ((pfd.revents & (POLLERR | POLLHUP | POLLNVAL)) != 0 &&
      (pfd.revents & (POLLIN | POLLOUT)) == 0) {
    fail(Fault::kNotAnswering, "%s: device error while streaming (disconnected or stream stopped)",
         path_.c_str());
    return -1;
  }
  return 1;
}

// ---- capture ----------------------------------------------------------------------------------

bool V4l2Capture::open(const std::string& path, const V4l2Config& config) {
  held_ = -1;
  have_sequence_ = false;
  counters_ = {};
  if (!open_stream(path, config)) return false;
  for (int i = 0; i < count_; ++i) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = static_cast<std::uint32_t>(i);
    if (xioctl(fd_, VIDIOC_QBUF, &b) < 0) {
      const int e = errno;
      close();
      return fail(Fault::kIo, "%s: VIDIOC_QBUF failed: %s", path.c_str(), std::strerror(e));
    }
  }
  return true;
}

bool V4l2Capture::requeue_held() {
  if (held_ < 0) return true;
  v4l2_buffer b{};
  b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  b.memory = V4L2_MEMORY_MMAP;
  b.index = static_cast<std::uint32_t>(held_);
  if (xioctl(fd_, VIDIOC_QBUF, &b) < 0)
    return fail(Fault::kIo, "%s: VIDIOC_QBUF failed: %s", path_.c_str(), std::strerror(errno));
  held_ = -1;
  return true;
}

hal::SourceStatus V4l2Capture::wait(int timeout_ms, hal::FrameView& frame) {
  if (fd_ < 0 || !streaming_) {
    if (error_[0] == '\0') fail(Fault::kIo, "camera not streaming");
    return hal::SourceStatus::kError;
  }
  if (!requeue_held()) return hal::SourceStatus::kError;
  const int ready = wait_ready(timeout_ms);
  if (ready < 0) return hal::SourceStatus::kError;
  if (ready == 0) return hal::SourceStatus::kNotReady;

  v4l2_buffer b{};
  b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  b.memory = V4L2_MEMORY_MMAP;
  if (xioctl(fd_, VIDIOC_DQBUF, &b) < 0) {
    const int e = errno;
    if (e == EAGAIN) return hal::SourceStatus::kNotReady;
    if (e == ENODEV)
      fail(Fault::kNotAnswering, "%s: device disconnected", path_.c_str());
    else
      fail(Fault::kIo, "%s: VIDIOC_DQBUF failed: %s", path_.c_str(), std::strerror(e));
    return hal::SourceStatus::kError;
  }
  held_ = static_cast<int>(b.index);

  // Gaps in the sequence numbers are frames the device dropped (the difference taken modulo 2^32,
  // so a wrap is no gap); a step back means the device restarted its count, not a loss.
  if (have_sequence_) {
    const auto step = static_cast<std::int32_t>(b.sequence - last_sequence_);
    if (step > 1) counters_.dropped += static_cast<std::uint64_t>(step - 1);
    if (step <= 0) ++counters_.restarts;
  }
  have_sequence_ = true;
  last_sequence_ = b.sequence;
  ++counters_.frames;

  frame.format = format_;
  frame.width = width_;
  frame.height = height_;
  frame.bytes_per_line = bytes_per_line_;
  frame.data = static_cast<const std::uint8_t*>(buffers_[static_cast<std::size_t>(b.index)].start);
  frame.bytes = b.bytesused != 0 ? b.bytesused : size_image_;
  frame.sequence = b.sequence;
  frame.flags = 0;
  monotonic_ = (b.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
  frame.t_ns = capture_time_ns(b.flags,
                               static_cast<std::int64_t>(b.timestamp.tv_sec) * 1'000'000'000 +
                                   static_cast<std::int64_t>(b.timestamp.tv_usec) * 1'000,
                               monotonic_ns());
  if (!monotonic_) ++counters_.stamped_at_dequeue;
  start_of_exposure_ = (b.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
  if (start_of_exposure_) frame.flags |= hal::kFrameStartOfExposure;
  const std::size_t need =
      static_cast<std::size_t>(bytes_per_line_) * static_cast<std::size_t>(height_);
  if ((b.flags & V4L2_BUF_FLAG_ERROR) != 0 || frame.bytes < need) {
    frame.flags |= hal::kFrameCorrupt;
    ++counters_.corrupt;
  }
  return hal::SourceStatus::kOk;
}

std::int64_t capture_time_ns(std::uint32_t buffer_flags, std::int64_t buffer_ns,
                             std::int64_t dequeued_ns) {
  const bool monotonic =
      (buffer_flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
  return monotonic ? buffer_ns : dequeued_ns;
}

// ---- output -----------------------------------------------------------------------------------

bool V4l2Output::open(const std::string& path, const V4l2Config& config) {
  written_ = 0;
  last_ = nullptr;
  if (!open_stream(path, config)) return false;
  free_.fill(false);
  for (int i = 0; i < count_; ++i) free_[static_cast<std::size_t>(i)] = true;
  return true;
}

bool V4l2Output::reclaim() {
  for (;;) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    b.memory = V4L2_MEMORY_MMAP;
    if (xioctl(fd_, VIDIOC_DQBUF, &b) < 0) {
      if (errno == EAGAIN) return true;
      return fail(Fault::kIo, "%s: VIDIOC_DQBUF failed: %s", path_.c_str(), std::strerror(errno));
    }
    free_[b.index] = true;
  }
}

int V4l2Output::free_buffers() {
  if (fd_ < 0) return -1;
  if (streaming_ && !reclaim()) return -1;
  int n = 0;
  for (int i = 0; i < count_; ++i) n += free_[static_cast<std::size_t>(i)] ? 1 : 0;
  return n;
}

bool V4l2Output::write(const std::uint8_t* image, int src_bytes_per_line, int timeout_ms) {
  if (fd_ < 0) return fail(Fault::kIo, "output not open");
  int index = -1;
  for (int attempt = 0; attempt < 2 && index < 0; ++attempt) {
    // Before the stream starts nothing comes back, so only the never-queued buffers are free.
    if (streaming_ && !reclaim()) return false;
    for (int i = 0; i < count_ && index < 0; ++i)
      if (free_[static_cast<std::size_t>(i)]) index = i;
    if (index >= 0 || attempt == 1 || !streaming_) break;
    const int ready = wait_ready(timeout_ms);
    if (ready < 0) return false;
    if (ready == 0)
      return fail(Fault::kIo, "%s: no free output buffer within %d ms", path_.c_str(), timeout_ms);
  }
  if (index < 0) return fail(Fault::kIo, "%s: no free output buffer", path_.c_str());

  auto* dst = static_cast<std::uint8_t*>(buffers_[static_cast<std::size_t>(index)].start);
  const auto row = static_cast<std::size_t>(width_ * hal::bytes_per_pixel(format_));
  for (int y = 0; y < height_; ++y)
    std::memcpy(dst + static_cast<std::size_t>(y) * static_cast<std::size_t>(bytes_per_line_),
                image + static_cast<std::size_t>(y) * static_cast<std::size_t>(src_bytes_per_line),
                row);
  v4l2_buffer b{};
  b.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
  b.memory = V4L2_MEMORY_MMAP;
  b.index = static_cast<std::uint32_t>(index);
  b.bytesused = static_cast<std::uint32_t>(size_image_);
  b.field = V4L2_FIELD_NONE;
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  b.timestamp.tv_sec = now.tv_sec;
  b.timestamp.tv_usec = now.tv_nsec / 1000;
  if (xioctl(fd_, VIDIOC_QBUF, &b) < 0)
    return fail(Fault::kIo, "%s: VIDIOC_QBUF failed: %s", path_.c_str(), std::strerror(errno));
  free_[static_cast<std::size_t>(index)] = false;
  last_ = dst;
  ++written_;
  return true;
}

}  // namespace mirrorcal::drivers
