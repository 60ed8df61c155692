// A Bosch MM7.10 inertial sensor on SocketCAN.
//
// Frame layout, as Bosch publishes it for the MM7.10 (Bosch Motorsport data sheet of the MM7.10,
// "CAN Message" table, and Bosch Engineering's ROS driver off_highway_sensor_drivers,
// off_highway_mm7p10/src/receiver.cpp, which names every signal). Three classic 8-byte frames
// per sample, 11-bit identifiers, signals little-endian (Intel) at these bit positions:
//   TX1 0x174  yaw rate (about z)   bits 0-15, status 20-23, temperature 24-31, AY 32-47,
//              message counter 48-51, AY status 52-55, CRC 56-63
//   TX2 0x178  roll rate (about x)  bits 0-15, status 20-23, AX 32-47, counter 48-51, ...
//   TX3 0x17C  pitch rate (about y) bits 0-15, HW index 16-19, status 20-23, AZ 32-47, counter...
// Rates: unsigned, 0.005 deg/s per bit, offset -163.84 deg/s (raw 0x8000 is zero); accelerations:
// 0.000127465 g per bit, raw 0x8000 is zero (Bosch rounds the offset to -4.1768 g). The roll
// rate comes negative with respect to the right-hand rule about x (Bosch's driver inverts it); we
// invert it too, so the sample is right-handed in the sensor's x, y, z. A status nibble other
// than 0 flags a signal the sensor itself does not trust.
//
// The CRC byte (bits 56-63) is carried but NOT verified, and CanImuSender writes 0 there. No
// public source says how the MM7.10 computes it: the data sheet's table names the signal only,
// and Bosch's own driver declares the three messages without a CRC position (crc_index =
// std::nullopt in off_highway_mm7p10/src/receiver.cpp), although its CAN library checks an SAE
// J1850 CRC-8 (polynomial 0x1D, initial value and final XOR 0xFF) on the messages of Bosch's
// off-highway radar. An AUTOSAR E2E-style CRC over these bytes would also need a per-message data
// ID that nobody publishes, so guessing would reject every frame of a real sensor or accept
// garbage anyway. Lost and damaged frames are caught otherwise: the CAN bus's own 15-bit CRC
// drops corrupted frames in the controller, the identifier filter and the length check reject
// foreign frames, each message's counter reveals lost frames, the three frames of a sample must
// carry the same counter in order, and the status nibbles drop samples the sensor distrusts.
//
// The three frames of one sample carry the same 4-bit message counter; each message's counter
// steps by one per sample, so a gap counts lost frames of that message. A sample is delivered
// when TX1, TX2 and TX3 with the same counter arrived in that order; anything else is counted and
// dropped. Its time is the kernel's receive timestamp of TX3 (SO_TIMESTAMPNS, CLOCK_REALTIME)
// mapped onto CLOCK_MONOTONIC, the loop's clock.
#pragma once

#include <cstdint>
#include <string>

#include "mirrorcal/drivers/driver_error.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::drivers {

namespace mm710 {

constexpr std::uint32_t kTx1 = 0x174, kTx2 = 0x178, kTx3 = 0x17C;
constexpr double kRateDpsPerBit = 0.005;
constexpr double kAccelGPerBit = 0.000127465;
constexpr std::uint16_t kZero = 0x8000;

// One classic CAN frame, independent of the Linux headers.
struct Frame {
  std::uint32_t id = 0;
  std::uint8_t len = 8;
  std::uint8_t data[8] = {};
};

// The three frames of a sample with counter (0-15). Values beyond the sensor's range are clamped;
// returns false when any was.
bool encode(const ImuSample& sample, std::uint8_t counter, Frame frames[3]);

// One decoded frame: which message (0 = TX1, 1 = TX2, 2 = TX3), its counter, rate (rad/s,
// right-handed) and acceleration (m/s^2), and whether the sensor flagged either as bad.
struct Part {
  int message = 0;
  std::uint8_t counter = 0;
  double rate = 0.0, accel = 0.0;
  bool status_ok = true;
};
// False when the frame is not one of the three messages or not 8 bytes long.
bool decode(const Frame& frame, Part& part);

// Puts frames back together into samples and counts what went missing.
class Assembler {
 public:
  struct Counters {
    std::uint64_t lost_frames[3] = {0, 0, 0};  // from each message's counter gaps
    std::uint64_t incomplete_samples = 0;      // started, never completed: dropped
    std::uint64_t flagged_samples = 0;         // the sensor flagged a signal: dropped
  };
  // Adds a decoded frame received at t_ns; true when it completed a sample.
  bool add(const Part& part, std::int64_t t_ns, ImuSample& sample);
  // Drops a partial sample (after a bus error).
  void reset();
  const Counters& counters() const { return counters_; }

 private:
  Counters counters_{};
  bool synced_ = false;  // a sample's first frame (TX1) has arrived
  bool joined_ = false;  // a whole sample has arrived: from here on a missing frame is a loss
  bool seen_[3] = {false, false, false};
  std::uint8_t last_counter_[3] = {0, 0, 0};
  int have_ = 0;  // how many parts of the pending sample arrived (in order)
  bool dropped_valid_ = false;
  std::uint8_t dropped_counter_ = 0;  // the last sample counted as incomplete
  std::uint8_t pending_counter_ = 0;
  bool pending_ok_ = true;
  ImuSample pending_{};
};

}  // namespace mm710

struct CanImuCounters {
  std::uint64_t frames = 0;           // data frames of the three messages
  std::uint64_t rejected_frames = 0;  // wrong length, remote or extended frames, unknown ids
  std::uint64_t error_frames = 0;     // error frames of any class
  std::uint64_t bus_off = 0;          // bus-off events
  std::uint64_t recoveries = 0;       // returns to normal after a bus-off
  std::uint64_t samples = 0;
  mm710::Assembler::Counters assembly{};
  std::uint64_t lost_frames() const {
    return assembly.lost_frames[0] + assembly.lost_frames[1] + assembly.lost_frames[2];
  }
};

// A raw CAN socket on interface ifname, bound, filtered to the MM7.10's three messages (standard
// data frames only) plus error frames, with receive timestamps on. Throws DriverError: no CAN in
// the kernel, no such interface, not a CAN interface, interface down.
int open_mm710_socket(const std::string& ifname);

class CanImu final : public hal::ImuSource {
 public:
  // Adopts fd (a socket from open_mm710_socket, or any socket delivering struct can_frame records,
  // e.g. a socketpair in tests); device names it in messages. next() fails when no frame of the
  // sensor arrives for timeout_ns. time is what it waits on the socket and times out by
  // (nullptr: CLOCK_MONOTONIC; tests give a fake one, as to the register IMUs); a sample's time
  // is the kernel's receive stamp where the socket gives one, else time's when it was read.
  CanImu(int fd, const std::string& device, std::int64_t timeout_ns = 500'000'000,
         Timebase* time = nullptr);
  ~CanImu() override;
  CanImu(const CanImu&) = delete;
  CanImu& operator=(const CanImu&) = delete;

  hal::SourceStatus next(ImuSample& sample) override;
  const char* error() const override { return error_.c_str(); }
  // The time next() spent in poll, waiting for the sample's three frames.
  std::int64_t wait_ns() const override { return wait_ns_; }
  const CanImuCounters& counters() const;
  bool bus_off() const { return bus_off_; }
  // The last error frame's classes in words (e.g. "bus-off"), for logs; empty if none came.
  const char* last_bus_error() const { return bus_error_.c_str(); }

 private:
  void on_error_frame(std::uint32_t can_id, const std::uint8_t* data);
  // Parts of next().
  void set_silence_error(std::uint64_t frames_meanwhile);
  bool take_data_frame(std::uint32_t can_id, std::uint8_t len, const std::uint8_t* data,
                       mm710::Part& part);

  int fd_;
  std::string device_;
  std::int64_t timeout_ns_;
  Timebase& time_;  // what it waits and times out by
  std::int64_t wait_ns_ = 0;
  mm710::Assembler assembler_;
  mutable CanImuCounters counters_{};
  bool bus_off_ = false;
  ErrorText error_, bus_error_;
};

// Sends an IMU stream as MM7.10 frames (a simulated sensor, or a bridge from another IMU).
class CanImuSender {
 public:
  explicit CanImuSender(int fd) : fd_(fd) {}
  // Writes the sample's three frames; false (errno set) when the socket refused one.
  bool send(const ImuSample& sample);
  bool send_frame(const mm710::Frame& frame);
  std::uint8_t counter() const { return counter_; }
  std::uint64_t clamped() const { return clamped_; }

 private:
  int fd_;
  std::uint8_t counter_ = 0;
  std::uint64_t clamped_ = 0;
};

}  // namespace mirrorcal::drivers
