#include "mirrorcal/drivers/can_imu.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>

#include "mirrorcal/drivers/monotonic_clock.hpp"

namespace mirrorcal::drivers {
namespace mm710 {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kGravity = 9.80665;  // m/s^2 per g

std::uint16_t quantise(double value, double per_bit, bool& clamped) {
  const double raw = std::round(value / per_bit) + kZero;
  const double limited = std::min(65535.0, std::max(0.0, raw));
  if (limited != raw || !std::isfinite(value)) clamped = true;
  return static_cast<std::uint16_t>(std::isfinite(value) ? limited : kZero);
}

void put16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v & 0xff);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}

int get16(const std::uint8_t* p) {
  return p[0] | (p[1] << 8);
}

}  // namespace

bool encode(const ImuSample& sample, std::uint8_t counter, Frame frames[3]) {
  bool clamped = false;
  const double to_dps = 180.0 / kPi;
  // Message order TX1 (yaw z, AY), TX2 (roll x, sent left-handed, AX), TX3 (pitch y, AZ).
  const double rates[3] = {sample.gyro.z() * to_dps, -sample.gyro.x() * to_dps,
                           sample.gyro.y() * to_dps};
  const double accels[3] = {sample.accel.y(), sample.accel.x(), sample.accel.z()};
  const std::uint32_t ids[3] = {kTx1, kTx2, kTx3};
  for (int m = 0; m < 3; ++m) {
    Frame& f = frames[m];
    f = Frame{};
    f.id = ids[m];
    f.len = 8;
    put16(f.data + 0, quantise(rates[m], kRateDpsPerBit, clamped));
    if (m == 0) f.data[3] = 25 + 50;  // TEMP_RATE_Z: 25 degC (offset -50)
    put16(f.data + 4, quantise(accels[m] / kGravity, kAccelGPerBit, clamped));
    f.data[6] = static_cast<std::uint8_t>(counter & 0x0f);  // counter; accel status 0 (ok)
  }
  return !clamped;
}

bool decode(const Frame& frame, Part& part) {
  if (frame.len != 8) return false;
  switch (frame.id) {
    case kTx1:
      part.message = 0;
      break;
    case kTx2:
      part.message = 1;
      break;
    case kTx3:
      part.message = 2;
      break;
    default:
      return false;
  }
  const double dps = (get16(frame.data + 0) - kZero) * kRateDpsPerBit;
  part.rate = (part.message == 1 ? -dps : dps) * kPi / 180.0;
  part.accel = (get16(frame.data + 4) - kZero) * kAccelGPerBit * kGravity;
  part.counter = frame.data[6] & 0x0f;
  part.status_ok = (frame.data[2] >> 4) == 0 && (frame.data[6] >> 4) == 0;
  return true;
}

bool Assembler::add(const Part& part, std::int64_t t_ns, ImuSample& sample) {
  const int m = part.message;
  if (seen_[m]) counters_.lost_frames[m] += (part.counter - last_counter_[m] - 1) & 0x0f;
  seen_[m] = true;
  last_counter_[m] = part.counter;

  // Counts a sample of counter c as incomplete, once however many of its frames arrive. Before the
  // first whole sample nothing is a loss: the kernel registers a socket's filters one message at a
  // time, so a receiver that joins a live bus may get a TX1 without the TX2 and TX3 behind it.
  const auto drop = [this](std::uint8_t c) {
    have_ = 0;
    if (!joined_) return;
    if (!(dropped_valid_ && dropped_counter_ == c)) ++counters_.incomplete_samples;
    dropped_valid_ = true;
    dropped_counter_ = c;
  };
  // A stream joined between a sample's first and last frame: its rest is not a loss.
  if (!synced_ && m != 0) return false;
  synced_ = true;
  if (m == 0) {
    if (have_ > 0) drop(pending_counter_);
    have_ = 1;
    pending_counter_ = part.counter;
    pending_ok_ = part.status_ok;
    pending_.gyro.z() = part.rate;
    pending_.accel.y() = part.accel;
    return false;
  }
  if (have_ != m || part.counter != pending_counter_) {
    if (have_ > 0) drop(pending_counter_);
    drop(part.counter);
    return false;
  }
  pending_ok_ = pending_ok_ && part.status_ok;
  if (m == 1) {
    pending_.gyro.x() = part.rate;
    pending_.accel.x() = part.accel;
    have_ = 2;
    return false;
  }
  pending_.gyro.y() = part.rate;
  pending_.accel.z() = part.accel;
  have_ = 0;
  joined_ = true;
  if (!pending_ok_) {
    ++counters_.flagged_samples;
    return false;
  }
  sample = pending_;
  sample.t_ns = t_ns;
  return true;
}

void Assembler::reset() {
  if (have_ > 0) ++counters_.incomplete_samples;
  have_ = 0;
}

}  // namespace mm710

namespace {

// CLOCK_MONOTONIC - CLOCK_REALTIME now: the realtime reading bracketed by two monotonic ones, the
// tightest of three tries (a preemption between the reads would otherwise bias the offset).
std::int64_t monotonic_minus_realtime_ns() {
  std::int64_t best_offset = 0, best_width = INT64_MAX;
  for (int i = 0; i < 3; ++i) {
    const std::int64_t m1 = monotonic_ns(), r = realtime_ns(), m2 = monotonic_ns();
    if (m2 - m1 < best_width) {
      best_width = m2 - m1;
      best_offset = m1 + (m2 - m1) / 2 - r;
    }
  }
  return best_offset;
}

// The time a frame was received: the kernel's receive time (SO_TIMESTAMPNS, CLOCK_REALTIME) moved
// onto CLOCK_MONOTONIC, or now_ns where the message carries none.
std::int64_t receive_time_ns(msghdr& msg, std::int64_t now_ns) {
  std::int64_t t_ns = now_ns;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_TIMESTAMPNS) {
      timespec ts{};
      std::memcpy(&ts, CMSG_DATA(c), sizeof(ts));
      const std::int64_t rx_real =
          static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
      t_ns = rx_real + monotonic_minus_realtime_ns();
    }
  }
  return t_ns;
}

}  // namespace

int open_mm710_socket(const std::string& ifname) {
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0)
    throw DriverError(Fault::kMissing, ifname + ": this kernel offers no raw CAN sockets (" +
                                           std::strerror(errno) + "; modules can, can-raw)");
  const auto fail = [fd](Fault fault, const std::string& message) {
    ::close(fd);
    throw DriverError(fault, message);
  };
  const unsigned index = if_nametoindex(ifname.c_str());
  if (index == 0) fail(Fault::kMissing, ifname + ": no such network interface (missing)");
  std::ifstream type_file("/sys/class/net/" + ifname + "/type");
  int type = -1;
  if (type_file >> type && type != 280)  // ARPHRD_CAN
    fail(Fault::kWrongKind,
         ifname + ": not a CAN interface (link type " + std::to_string(type) + ")");
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, ifname.c_str(), IFNAMSIZ - 1);
  if (::ioctl(fd, SIOCGIFFLAGS, &ifr) == 0 && (ifr.ifr_flags & IFF_UP) == 0)
    fail(Fault::kNotAnswering, ifname + ": the interface is down (ip link set " + ifname +
                                   " up type can bitrate 1000000)");

  // Only the sensor's three standard data frames, and every class of error frame.
  const canid_t mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
  const can_filter filters[3] = {{mm710::kTx1, mask}, {mm710::kTx2, mask}, {mm710::kTx3, mask}};
  const can_err_mask_t errors = CAN_ERR_MASK;
  const int on = 1;
  if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, filters, sizeof(filters)) != 0 ||
      ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &errors, sizeof(errors)) != 0 ||
      ::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on)) != 0)
    fail(Fault::kIo, ifname + ": cannot set the socket's filters: " + std::strerror(errno));
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = static_cast<int>(index);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    const int err = errno;
    ::close(fd);
    throw os_error(ifname, "cannot bind a CAN socket", err);
  }
  return fd;
}

CanImu::CanImu(int fd, const std::string& device, std::int64_t timeout_ns, Timebase* time)
    : fd_(fd),
      device_(device),
      timeout_ns_(timeout_ns),
      time_(time != nullptr ? *time : monotonic_timebase()) {
  const int on = 1;
  ::setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));  // best effort (socketpairs)
}

CanImu::~CanImu() {
  if (fd_ >= 0) ::close(fd_);
}

const CanImuCounters& CanImu::counters() const {
  counters_.assembly = assembler_.counters();
  return counters_;
}

void CanImu::on_error_frame(std::uint32_t can_id, const std::uint8_t* data) {
  ++counters_.error_frames;
  static const struct {
    std::uint32_t bit;
    const char* name;
  } classes[] = {{CAN_ERR_TX_TIMEOUT, "tx timeout"},
                 {CAN_ERR_LOSTARB, "lost arbitration"},
                 {CAN_ERR_CRTL, "controller problem"},
                 {CAN_ERR_PROT, "protocol violation"},
                 {CAN_ERR_TRX, "transceiver problem"},
                 {CAN_ERR_ACK, "no acknowledgement"},
                 {CAN_ERR_BUSOFF, "bus-off"},
                 {CAN_ERR_BUSERROR, "bus error"},
                 {CAN_ERR_RESTARTED, "controller restarted"}};
  char text[160] = "";
  std::size_t used = 0;
  for (const auto& c : classes) {
    if ((can_id & c.bit) == 0) continue;
    const int n = std::snprintf(text + used, sizeof(text) - used, "%s%s", used ? ", " : "", c.name);
    if (n > 0) used = std::min(sizeof(text) - 1, used + static_cast<std::size_t>(n));
  }
  if ((can_id & CAN_ERR_CRTL) != 0 &&
      (data[1] & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)))
    std::snprintf(text + used, sizeof(text) - used, " (error passive)");
  bus_error_.set("%s", text);
  if ((can_id & CAN_ERR_BUSOFF) != 0) {
    ++counters_.bus_off;
    bus_off_ = true;
    assembler_.reset();  // whatever was half received is gone
  }
  if ((can_id & CAN_ERR_RESTARTED) != 0 && bus_off_) {
    bus_off_ = false;
    ++counters_.recoveries;
  }
}

hal::SourceStatus CanImu::next(ImuSample& sample) {
  const std::int64_t deadline = time_.now_ns() + timeout_ns_;
  wait_ns_ = 0;
  std::uint64_t frames_meanwhile = 0;  // of any kind but error frames, none completing a sample
  for (;;) {
    const std::int64_t poll_start = time_.now_ns();
    const std::int64_t left = deadline - poll_start;
    if (left <= 0) {
      set_silence_error(frames_meanwhile);
      return hal::SourceStatus::kError;
    }
    const int ready = time_.wait_readable(fd_, left);
    wait_ns_ += time_.now_ns() - poll_start;
    if (ready < 0 && errno != EINTR) {
      error_.set("%s: poll failed: %s", device_.c_str(), std::strerror(errno));
      return hal::SourceStatus::kError;
    }
    if (ready <= 0) continue;

    can_frame frame{};
    iovec iov{&frame, sizeof(frame)};
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) * 2];
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control;
    msg.msg_controllen = sizeof(control);
    const ssize_t n = ::recvmsg(fd_, &msg, 0);
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      error_.set("%s: stops answering: %s", device_.c_str(), std::strerror(errno));
      return hal::SourceStatus::kError;
    }
    if (n == 0) {
      error_.set("%s: the CAN socket was closed", device_.c_str());
      return hal::SourceStatus::kError;
    }
    if (static_cast<std::size_t>(n) != sizeof(frame)) {
      ++counters_.rejected_frames;
      continue;
    }
    // The kernel's receive time is CLOCK_REALTIME; move it onto CLOCK_MONOTONIC.
    const std::int64_t t_ns = receive_time_ns(msg, time_.now_ns());
    if ((frame.can_id & CAN_ERR_FLAG) != 0) {
      on_error_frame(frame.can_id, frame.data);
      continue;
    }
    ++frames_meanwhile;
    mm710::Part part;
    if (!take_data_frame(frame.can_id, frame.len, frame.data, part)) continue;
    if (assembler_.add(part, t_ns, sample)) {
      ++counters_.samples;
      return hal::SourceStatus::kOk;
    }
  }
}

// Why no sample came within the timeout: frames that never completed one, a bus-off, or silence.
void CanImu::set_silence_error(std::uint64_t frames_meanwhile) {
  if (frames_meanwhile > 0 && !bus_off_)
    error_.set(
        "%s: stops answering: %llu frames in %lld ms but no complete MM7.10 sample (wrong "
        "length, out of order or missing messages)",
        device_.c_str(), static_cast<unsigned long long>(frames_meanwhile),
        static_cast<long long>(timeout_ns_ / 1'000'000));
  else if (bus_off_)
    error_.set(
        "%s: stops answering: bus-off and no frame since for %lld ms (automatic "
        "recovery: ip link set %s type can restart-ms 100)",
        device_.c_str(), static_cast<long long>(timeout_ns_ / 1'000'000), device_.c_str());
  else
    error_.set("%s: stops answering: no frame of the MM7.10 for %lld ms", device_.c_str(),
               static_cast<long long>(timeout_ns_ / 1'000'000));
}

// A data frame decoded into part and counted; one that is not a standard data frame of the
// MM7.10's messages is counted as rejected (false). Frames that flow again end a bus-off.
bool CanImu::take_data_frame(std::uint32_t can_id, std::uint8_t len, const std::uint8_t* data,
                             mm710::Part& part) {
  mm710::Frame f;
  f.id = can_id & CAN_SFF_MASK;
  f.len = len;
  std::memcpy(f.data, data, 8);
  if ((can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG)) != 0 || !mm710::decode(f, part)) {
    ++counters_.rejected_frames;
    return false;
  }
  ++counters_.frames;
  if (bus_off_) {  // frames flow again: the controller recovered without telling us
    bus_off_ = false;
    ++counters_.recoveries;
  }
  return true;
}

bool CanImuSender::send_frame(const mm710::Frame& f) {
  can_frame frame{};
  frame.can_id = f.id;
  frame.len = f.len;
  std::memcpy(frame.data, f.data, 8);
  return ::write(fd_, &frame, sizeof(frame)) == static_cast<ssize_t>(sizeof(frame));
}

bool CanImuSender::send(const ImuSample& sample) {
  mm710::Frame frames[3];
  if (!mm710::encode(sample, counter_, frames)) ++clamped_;
  counter_ = static_cast<std::uint8_t>((counter_ + 1) & 0x0f);
  for (const mm710::Frame& f : frames)
    if (!send_frame(f)) return false;
  return true;
}

}  // namespace mirrorcal::drivers
