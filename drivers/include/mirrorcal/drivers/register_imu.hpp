// IMUs read through byte registers (register_bus.hpp): the MPU-6050 family over I2C and the
// ICM-42688-P over SPI. Opening checks WHO_AM_I, configures rate and full scale and throws
// DriverError when the part is missing, of another kind or does not take its configuration.
// next() waits for the sample (the data-ready line's rising edge if there is one, else the part's
// data-ready status bit, polled from shortly before the next period on CLOCK_MONOTONIC; wait_ns()
// says how long), reads the data registers in one burst and converts with the data sheet's
// scales. Nothing is allocated after opening. A part that stops answering ends the stream with
// kError and error() saying how: a failed transfer (after one retry), no data-ready edge or status
// for 20 periods (at least 200 ms), a data block no working part gives
// (all 0x00 or 0xff bytes, the ICM-42688-P's -32768 of sensors off) at once, a changed WHO_AM_I
// within a second.
#pragma once

#include <cstdint>
#include <memory>

#include "mirrorcal/drivers/driver_error.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/drivers/register_bus.hpp"
#include "mirrorcal/hal/lines.hpp"
#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::drivers {

constexpr double kStandardGravity = 9.80665;  // m/s^2 per g, as the data sheets count

struct RegisterImuConfig {
  double rate_hz = 200.0;       // output data rate; the part's nearest supported rate is used
  double gyro_range_dps = 500;  // the smallest full scale covering this is chosen
  double accel_range_g = 4;     // likewise
  bool pace = true;  // without a data-ready line: poll the part's data-ready status each period
  Timebase* timebase = nullptr;  // what it paces and times out by; nullptr: CLOCK_MONOTONIC
};

struct RegisterImuCounters {
  std::uint64_t samples = 0;
  std::uint64_t missed_samples = 0;  // samples (edges, or statuses) further apart than one period
  std::uint64_t read_retries = 0;    // bus transfers that failed once and then worked
};

class RegisterImu : public hal::ImuSource {
 public:
  hal::SourceStatus next(ImuSample& sample) override;
  const char* error() const override { return error_.c_str(); }
  // The wait on the data-ready edge, or for the part's data-ready status.
  std::int64_t wait_ns() const override { return wait_ns_; }

  const RegisterImuCounters& counters() const { return counters_; }
  std::int64_t period_ns() const { return period_ns_; }
  double gyro_lsb_per_dps() const { return gyro_lsb_per_dps_; }
  double accel_lsb_per_g() const { return accel_lsb_per_g_; }
  const RegisterBus& bus() const { return *bus_; }

 protected:
  RegisterImu(std::unique_ptr<RegisterBus> bus, hal::DataReadyLine* drdy,
              const RegisterImuConfig& config);

  // Reads WHO_AM_I; throws kNotAnswering for a silent bus, kWrongKind for another part.
  void expect_who_am_i(std::uint8_t reg, std::uint8_t expected, const char* part);
  void write_checked(std::uint8_t reg, std::uint8_t value);  // throws on failure
  // Writes and reads back; throws kWrongKind when the part does not keep the value.
  void write_verified(std::uint8_t reg, std::uint8_t value);
  bool read_register(std::uint8_t reg, std::uint8_t& value) { return bus_->read(reg, &value, 1); }

  // Set by the part's constructor: where the data is, how to read it, the scales.
  std::uint8_t data_register_ = 0;
  std::size_t data_length_ = 12;
  // The part's data-ready status bit, polled when paced without a data-ready line (read clears it).
  std::uint8_t status_register_ = 0, status_ready_mask_ = 0;
  std::uint8_t who_am_i_register_ = 0;
  std::uint8_t who_am_i_ = 0;
  std::int64_t period_ns_ = 5'000'000;
  double gyro_lsb_per_dps_ = 1.0, accel_lsb_per_g_ = 1.0;
  // Offsets of the big-endian accelerometer and gyro triples in the data block.
  std::size_t accel_offset_ = 0, gyro_offset_ = 6;
  // The value a part reads on every axis when it has no data (sensors off), if it has one.
  bool no_data_value_valid_ = false;
  std::int16_t no_data_value_ = 0;
  Timebase& time_;  // what it paces and times out by

 private:
  bool read_with_retry(std::uint8_t first, std::uint8_t* out, std::size_t n);
  // The steps of next(), in order; one that returns false has set error().
  bool wait_data_ready_line(std::int64_t& t_ns);
  bool poll_data_ready_status(std::int64_t& t_ns);
  void count_missed_samples(std::int64_t t_ns);
  bool read_data(std::uint8_t* raw);
  // Why a data block cannot be a sample of a working part (a bus nobody drives, a part that
  // reset), or nullptr when it can.
  const char* no_data(const std::uint8_t* raw) const;

  std::unique_ptr<RegisterBus> bus_;
  hal::DataReadyLine* drdy_;
  bool pace_;
  std::int64_t next_due_ns_ = 0;
  std::int64_t last_sample_ns_ = -1;
  std::int64_t wait_ns_ = 0;
  RegisterImuCounters counters_{};
  ErrorText error_;
};

// InvenSense MPU-6050 / MPU-6000 (register map RM-MPU-6000A-00 rev 4.2): WHO_AM_I 0x75 = 0x68,
// gyro output 1 kHz with the DLPF on, divided by SMPLRT_DIV; data ACCEL_XOUT_H (0x3B) to
// GYRO_ZOUT_L (0x48), big-endian, temperature in between.
class Mpu6050 final : public RegisterImu {
 public:
  Mpu6050(std::unique_ptr<RegisterBus> bus, const RegisterImuConfig& config,
          hal::DataReadyLine* drdy = nullptr);
};

// TDK InvenSense ICM-42688-P (data sheet DS-000347 rev 1.7): WHO_AM_I 0x75 = 0x47, bank 0
// registers; gyro and accelerometer in low-noise mode at a common ODR; data ACCEL_DATA_X1 (0x1F)
// to GYRO_DATA_Z0 (0x2A), big-endian (INTF_CONFIG0's default).
class Icm42688 final : public RegisterImu {
 public:
  Icm42688(std::unique_ptr<RegisterBus> bus, const RegisterImuConfig& config,
           hal::DataReadyLine* drdy = nullptr);
};

// Register addresses and values both the drivers and the tests' fakes use (from the data sheets).
namespace mpu6050 {
constexpr std::uint8_t kSmplrtDiv = 0x19, kConfig = 0x1A, kGyroConfig = 0x1B, kAccelConfig = 0x1C;
constexpr std::uint8_t kIntPinCfg = 0x37, kIntEnable = 0x38, kIntStatus = 0x3A, kAccelXoutH = 0x3B;
constexpr std::uint8_t kDataRdyInt = 0x01;  // INT_STATUS
constexpr std::uint8_t kPwrMgmt1 = 0x6B, kWhoAmI = 0x75, kWhoAmIValue = 0x68;
}  // namespace mpu6050

namespace icm42688 {
constexpr std::uint8_t kDeviceConfig = 0x11, kIntConfig = 0x14, kAccelDataX1 = 0x1F;
constexpr std::uint8_t kIntStatus = 0x2D, kDataRdyInt = 0x08;  // INT_STATUS, cleared on read
constexpr std::uint8_t kPwrMgmt0 = 0x4E, kGyroConfig0 = 0x4F, kAccelConfig0 = 0x50;
constexpr std::uint8_t kIntConfig1 = 0x64, kIntSource0 = 0x65, kWhoAmI = 0x75, kBankSel = 0x76;
constexpr std::uint8_t kWhoAmIValue = 0x47;
}  // namespace icm42688

}  // namespace mirrorcal::drivers
