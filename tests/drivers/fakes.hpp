// Fakes at the driver boundary for what no kernel here can provide: the parts themselves behind
// the register buses (an MPU-6050 register file, an ICM-42688-P answering SPI transfers) and a
// data-ready line with scripted edges. Their register maps and scales are written out from the
// data sheets here, independently of the drivers' tables.
#pragma once

#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include <poll.h>

#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/drivers/register_bus.hpp"
#include "mirrorcal/hal/lines.hpp"

namespace mirrorcal::drivers::test {

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9.80665;

// The time of the drivers under test and of the fake parts alike: it moves only when a driver
// sleeps or a bus transfer takes its time, so pacing, timeouts and late loops give the same
// results on any machine, however loaded (the drivers take it as their RegisterImuConfig's
// timebase).
class FakeTimebase final : public Timebase {
 public:
  std::int64_t now_ns() override { return now_ns_; }
  void sleep_until_ns(std::int64_t t_ns) override { now_ns_ = t_ns > now_ns_ ? t_ns : now_ns_; }
  void advance(std::int64_t ns) { now_ns_ += ns; }
  // A descriptor is waited on as it is now (poll(2) without waiting): data there arrives
  // data_after_ns later (the next wait's only: then it is 0 again) unless that is beyond the
  // timeout; without data, or with it later than that, the wait lasts the whole timeout.
  int wait_readable(int fd, std::int64_t timeout_ns) override {
    pollfd p{fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, 0);
    if (ready < 0) return -1;
    const bool in_time = ready > 0 && data_after_ns <= timeout_ns;
    advance(in_time ? data_after_ns : timeout_ns);
    if (in_time) data_after_ns = 0;
    return in_time ? 1 : 0;
  }
  std::int64_t data_after_ns = 0;

 private:
  std::int64_t now_ns_ = 1'000'000'000;
};
inline FakeTimebase& test_time() {
  static FakeTimebase time;
  return time;
}
// What one register transfer lasts on the fake buses: a few bytes at 400 kHz I2C, or SPI with
// its chip-select set-up.
constexpr std::int64_t kTransferNs = 50'000;

inline void put_be16(std::uint8_t* p, double counts) {
  const long v = std::lround(std::fmax(-32768.0, std::fmin(32767.0, counts)));
  const auto u = static_cast<std::uint16_t>(static_cast<std::int16_t>(v));
  p[0] = static_cast<std::uint8_t>(u >> 8);
  p[1] = static_cast<std::uint8_t>(u & 0xff);
}

// An MPU-6050 as its register file behind I2C: 256 byte registers, WHO_AM_I 0x68, data registers
// computed from the physical motion at the configured full scale (RM-MPU-6000A 4.4, 4.5).
class FakeMpu6050 final : public RegisterBus {
 public:
  FakeMpu6050() {
    regs_[0x75] = 0x68;
    regs_[0x6B] = 0x40; /* reset value: asleep */
  }
  // The part's sample clock: a new sample every (1 + SMPLRT_DIV) ms of its own oscillator, which
  // runs clock_scale times the nominal rate. INT_STATUS's DATA_RDY_INT says a sample came since
  // the last read (INT_RD_CLEAR: any read clears it); last_data_sample is the sample the last
  // read of the data registers got, so tests can tell samples apart.
  double clock_scale = 1.0;
  std::int64_t start_ns = test_time().now_ns();
  std::int64_t last_data_sample = -1;
  std::int64_t frozen_sample = -1;  // >= 0: the part stopped sampling at this sample
  double gyro_dps[3] = {0, 0, 0};
  double accel_g[3] = {0, 0, 1};  // at rest, z up
  bool dead = false;              // the part stops answering: every transfer fails with dead_errno
  int dead_errno = EREMOTEIO;
  std::size_t reads = 0, writes = 0, largest_read = 0;
  std::array<std::uint8_t, 256> regs_{};

  bool write(std::uint8_t reg, std::uint8_t value) override {
    if (dead) return fail();
    ++writes;
    if (reg != 0x75) regs_[reg] = value;
    return true;
  }
  bool read(std::uint8_t first, std::uint8_t* out, std::size_t n) override {
    if (dead) return fail();
    test_time().advance(kTransferNs);
    ++reads;
    largest_read = n > largest_read ? n : largest_read;
    refresh();
    const std::int64_t sample = sample_number();
    regs_[0x3A] = sample != read_sample_ ? 0x01 : 0x00;
    for (std::size_t i = 0; i < n; ++i) out[i] = regs_[(first + i) & 0xff];
    if (first <= 0x3B && first + n > 0x3B) last_data_sample = sample;
    read_sample_ = sample;
    return true;
  }
  // The sample in the data registers now.
  std::int64_t sample_number() const {
    if (frozen_sample >= 0) return frozen_sample;
    const double period_ns = 1e6 * (1 + regs_[0x19]) / clock_scale;
    return static_cast<std::int64_t>(static_cast<double>(test_time().now_ns() - start_ns) /
                                     period_ns);
  }
  const std::string& device() const override { return name_; }

 private:
  bool fail() {
    errno = dead_errno;
    return false;
  }
  void refresh() {
    static const double gyro_lsb[4] = {131.0, 65.5, 32.8, 16.4};
    static const double accel_lsb[4] = {16384, 8192, 4096, 2048};
    const bool asleep = (regs_[0x6B] & 0x40) != 0;
    const double gl = gyro_lsb[(regs_[0x1B] >> 3) & 3], al = accel_lsb[(regs_[0x1C] >> 3) & 3];
    for (int i = 0; i < 3; ++i) {
      put_be16(&regs_[0x3B + 2 * i], asleep ? 0 : accel_g[i] * al);
      put_be16(&regs_[0x43 + 2 * i], asleep ? 0 : gyro_dps[i] * gl);
    }
  }
  std::int64_t read_sample_ = -1;
  std::string name_ = "fake-mpu6050";
};

// An ICM-42688-P answering SPI transfers as the data sheet (DS-000347) describes: first byte the
// address with bit 7 for reads, auto-increment, burst writes; soft reset; bank select; sensors
// off (data reads -32768) until PWR_MGMT0 turns them on; scales per GYRO_CONFIG0/ACCEL_CONFIG0.
class FakeIcm42688 final : public SpiTransport {
 public:
  FakeIcm42688() { reset(); }
  double gyro_dps[3] = {0, 0, 0};
  double accel_g[3] = {0, 0, 1};  // at rest, z up
  bool unplugged = false;         // MISO floats high: every byte reads 0xff
  bool miso_low = false;          // MISO held low: every byte reads 0x00
  std::size_t transfers = 0, resets = 0;
  std::vector<std::uint8_t> first_bytes;  // of every transfer, to check the framing
  std::array<std::uint8_t, 256> bank0{};
  std::uint8_t bank = 0;

  bool transfer(const std::uint8_t* tx, std::uint8_t* rx, std::size_t n) override {
    test_time().advance(kTransferNs);
    ++transfers;
    first_bytes.push_back(tx[0]);
    rx[0] = 0xff;
    if (unplugged || miso_low) {
      for (std::size_t i = 0; i < n; ++i) rx[i] = unplugged ? 0xff : 0x00;
      return true;
    }
    const std::uint8_t addr = tx[0] & 0x7f;
    if (tx[0] & 0x80) {
      refresh();
      for (std::size_t i = 1; i < n; ++i) {
        const int a = (addr + static_cast<int>(i) - 1) & 0x7f;
        rx[i] = reg(a);
        if (a == 0x2D && bank == 0) read_sample_ = sample_number();  // INT_STATUS clears on read
      }
    } else {
      for (std::size_t i = 1; i < n; ++i) write((addr + i - 1) & 0x7f, tx[i]);
    }
    return true;
  }
  const std::string& device() const override { return name_; }

 private:
  // The part's sample clock: a new sample every period of the configured ODR (the gyro's,
  // GYRO_CONFIG0's low bits); INT_STATUS's DATA_RDY_INT says one came since INT_STATUS was read.
  std::int64_t sample_number() const {
    double hz = 1000;
    switch (bank0[0x4F] & 0x0F) {
      case 3:
        hz = 8000;
        break;
      case 4:
        hz = 4000;
        break;
      case 5:
        hz = 2000;
        break;
      case 15:
        hz = 500;
        break;
      case 7:
        hz = 200;
        break;
      case 8:
        hz = 100;
        break;
      case 9:
        hz = 50;
        break;
      case 10:
        hz = 25;
        break;
      case 11:
        hz = 12.5;
        break;
      default:
        break;
    }
    return static_cast<std::int64_t>(static_cast<double>(test_time().now_ns() - start_ns_) * hz *
                                     1e-9);
  }
  std::uint8_t reg(int a) const {
    if (a == 0x2D && bank == 0) return sample_number() != read_sample_ ? 0x08 : 0x00;
    if (a == 0x76) return bank;
    return bank == 0 ? bank0[static_cast<std::size_t>(a)] : 0x00;
  }
  void write(int a, std::uint8_t v) {
    if (a == 0x76) {
      bank = v & 7;
      return;
    }
    if (bank != 0) return;
    if (a == 0x11 && (v & 1)) {
      reset();
      return;
    }
    if (a == 0x75 || (a >= 0x1D && a <= 0x2A)) return;  // read-only
    bank0[static_cast<std::size_t>(a)] = v;
  }
  void reset() {
    ++resets;
    bank0.fill(0);
    bank = 0;
    bank0[0x75] = 0x47;
    bank0[0x4F] = 0x06;  // GYRO_CONFIG0: +-2000 dps, 1 kHz
    bank0[0x50] = 0x06;  // ACCEL_CONFIG0: +-16 g, 1 kHz
    bank0[0x64] = 0x10;  // INT_CONFIG1
  }
  void refresh() {
    // Sensitivity per FS_SEL code (data sheet tables 1 and 2).
    static const double gyro_lsb[8] = {16.4, 32.8, 65.5, 131, 262, 524.3, 1048.6, 2097.2};
    static const double accel_lsb[4] = {2048, 4096, 8192, 16384};
    const bool gyro_on = ((bank0[0x4E] >> 2) & 3) == 3, accel_on = (bank0[0x4E] & 3) >= 2;
    const double gl = gyro_lsb[bank0[0x4F] >> 5], al = accel_lsb[(bank0[0x50] >> 5) & 3];
    for (int i = 0; i < 3; ++i) {
      put_be16(&bank0[static_cast<std::size_t>(0x1F + 2 * i)], accel_on ? accel_g[i] * al : -32768);
      put_be16(&bank0[static_cast<std::size_t>(0x25 + 2 * i)], gyro_on ? gyro_dps[i] * gl : -32768);
    }
  }
  std::int64_t start_ns_ = test_time().now_ns(), read_sample_ = -1;
  std::string name_ = "fake-icm42688";
};

// A data-ready line whose rising edges are scripted: times popped in order; none left -> timeout;
// broken -> the line itself fails (its chip went away). Each wait lasts delay_ns first, as for a
// part whose next sample is that far away.
class FakeDataReady final : public hal::DataReadyLine {
 public:
  std::deque<std::int64_t> edges;
  std::int64_t last_timeout_ns = 0;
  std::int64_t delay_ns = 0;
  bool broken = false;
  const char* error() const override { return broken ? "gpiochip0:17: read failed: ENODEV" : ""; }
  hal::SourceStatus wait_rising(std::int64_t timeout_ns, std::int64_t& t_ns) override {
    last_timeout_ns = timeout_ns;
    if (broken) return hal::SourceStatus::kError;
    test_time().advance(delay_ns);
    if (edges.empty()) return hal::SourceStatus::kNotReady;
    t_ns = edges.front();
    edges.pop_front();
    return hal::SourceStatus::kOk;
  }
};

}  // namespace mirrorcal::drivers::test
