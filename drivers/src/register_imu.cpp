#include "mirrorcal/drivers/register_imu.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>

#include "mirrorcal/drivers/monotonic_clock.hpp"

namespace mirrorcal::drivers {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string hex(int value) {
  char buf[8];
  std::snprintf(buf, sizeof(buf), "0x%02x", value);
  return buf;
}

std::int16_t big_endian(const std::uint8_t* p) {
  return static_cast<std::int16_t>(static_cast<std::uint16_t>((p[0] << 8) | p[1]));
}

// A full-scale setting: the range it covers and the data sheet's sensitivity.
struct Scale {
  std::uint8_t code;
  double range;
  double lsb_per_unit;
};

// The smallest listed range covering `wanted`; throws when none does.
template <std::size_t N>
const Scale& covering(const Scale (&scales)[N], double wanted, const std::string& device,
                      const char* what, const char* unit) {
  const Scale* best = nullptr;
  for (const Scale& s : scales)
    if (s.range >= wanted && (best == nullptr || s.range < best->range)) best = &s;
  if (best == nullptr || !(wanted > 0))
    throw DriverError(Fault::kBadSpec, device + ": no " + what + " full scale covers " +
                                           std::to_string(wanted) + " " + unit);
  return *best;
}

}  // namespace

RegisterImu::RegisterImu(std::unique_ptr<RegisterBus> bus, hal::DataReadyLine* drdy,
                         const RegisterImuConfig& config)
    : time_(config.timebase != nullptr ? *config.timebase : monotonic_timebase()),
      bus_(std::move(bus)),
      drdy_(drdy),
      pace_(config.pace) {}

void RegisterImu::expect_who_am_i(std::uint8_t reg, std::uint8_t expected, const char* part) {
  std::uint8_t id = 0;
  if (!bus_->read(reg, &id, 1))
    throw DriverError(Fault::kNotAnswering, bus_->device() + ": nothing answers (reading the " +
                                                part + "'s WHO_AM_I: " + std::strerror(errno) +
                                                ")");
  if (id == expected) {
    who_am_i_register_ = reg;
    who_am_i_ = expected;
    return;
  }
  if (id == 0x00 || id == 0xff)
    throw DriverError(Fault::kNotAnswering, bus_->device() + ": WHO_AM_I reads " + hex(id) +
                                                ", nothing answers (no " + part +
                                                " there, or not powered?)");
  throw DriverError(Fault::kWrongKind, bus_->device() + ": WHO_AM_I reads " + hex(id) +
                                           ", not the " + part + "'s " + hex(expected));
}

void RegisterImu::write_checked(std::uint8_t reg, std::uint8_t value) {
  if (!bus_->write(reg, value))
    throw os_error(bus_->device(), "cannot write register " + hex(reg), errno);
}

void RegisterImu::write_verified(std::uint8_t reg, std::uint8_t value) {
  write_checked(reg, value);
  std::uint8_t back = 0;
  if (!bus_->read(reg, &back, 1))
    throw os_error(bus_->device(), "cannot read register " + hex(reg), errno);
  if (back != value)
    throw DriverError(Fault::kWrongKind, bus_->device() + ": register " + hex(reg) + " reads " +
                                             hex(back) + " after writing " + hex(value) +
                                             " (not the expected part?)");
}

bool RegisterImu::read_with_retry(std::uint8_t first, std::uint8_t* out, std::size_t n) {
  if (bus_->read(first, out, n)) return true;
  if (!bus_->read(first, out, n)) return false;
  ++counters_.read_retries;
  return true;
}

const char* RegisterImu::no_data(const std::uint8_t* raw) const {
  const std::size_t fields[2] = {accel_offset_, gyro_offset_};
  bool zeros = true, ones = true, no_data_value = no_data_value_valid_;
  for (const std::size_t f : fields)
    for (std::size_t i = 0; i < 6; ++i) {
      zeros = zeros && raw[f + i] == 0x00;
      ones = ones && raw[f + i] == 0xff;
      if (i % 2 == 0) no_data_value = no_data_value && big_endian(raw + f + i) == no_data_value_;
    }
  if (ones) return "0xff throughout (nothing drives the bus: part unplugged or unpowered?)";
  if (zeros) return "0x00 throughout (nothing answers, or the part reset and sleeps)";
  if (no_data_value)
    return "the part's no-data value on every axis (its sensors are off: did it reset?)";
  return nullptr;
}

hal::SourceStatus RegisterImu::next(ImuSample& sample) {
  std::int64_t t_ns = 0;
  wait_ns_ = 0;
  if (drdy_ != nullptr) {
    if (!wait_data_ready_line(t_ns)) return hal::SourceStatus::kError;
  } else if (pace_) {
    if (!poll_data_ready_status(t_ns)) return hal::SourceStatus::kError;
  } else {
    t_ns = time_.now_ns();
  }
  count_missed_samples(t_ns);

  std::uint8_t raw[32];
  if (!read_data(raw)) return hal::SourceStatus::kError;

  const double rad_per_lsb = kPi / 180.0 / gyro_lsb_per_dps_;
  const double ms2_per_lsb = kStandardGravity / accel_lsb_per_g_;
  sample.t_ns = t_ns;
  for (int i = 0; i < 3; ++i) {
    sample.accel[i] =
        big_endian(raw + accel_offset_ + 2 * static_cast<std::size_t>(i)) * ms2_per_lsb;
    sample.gyro[i] = big_endian(raw + gyro_offset_ + 2 * static_cast<std::size_t>(i)) * rad_per_lsb;
  }
  ++counters_.samples;
  return hal::SourceStatus::kOk;
}

// The data-ready line's next rising edge, timed by the line (t_ns); false after 20 periods (at
// least 200 ms) without one, or when the line fails.
bool RegisterImu::wait_data_ready_line(std::int64_t& t_ns) {
  const std::int64_t timeout_ns = std::max<std::int64_t>(20 * period_ns_, 200'000'000);
  const std::int64_t wait_start = time_.now_ns();
  const hal::SourceStatus s = drdy_->wait_rising(timeout_ns, t_ns);
  wait_ns_ = time_.now_ns() - wait_start;
  if (s == hal::SourceStatus::kNotReady) {
    error_.set("%s: stops answering: no data-ready edge for %lld ms", bus_->device().c_str(),
               static_cast<long long>(timeout_ns / 1'000'000));
    return false;
  }
  if (s != hal::SourceStatus::kOk) {
    error_.set("%s: data-ready line failed: %s", bus_->device().c_str(), drdy_->error());
    return false;
  }
  return true;
}

bool RegisterImu::poll_data_ready_status(std::int64_t& t_ns) {
  // Without a data-ready line the part's own data-ready status tells when a new sample is in
  // its registers: polled every eighth of a period from shortly before the next one is due.
  // No sample is read twice (a part whose clock runs slower than the host's), and each is timed
  // within an eighth of a period of its arrival.
  const std::int64_t poll_ns = std::max<std::int64_t>(period_ns_ / 8, 50'000);
  const std::int64_t start = time_.now_ns();
  if (next_due_ns_ < start - period_ns_) next_due_ns_ = start;  // the first, or fell behind
  time_.sleep_until_ns(next_due_ns_);
  const std::int64_t timeout_ns = std::max<std::int64_t>(20 * period_ns_, 200'000'000);
  for (;;) {
    std::uint8_t status = 0;
    if (!read_with_retry(status_register_, &status, 1)) {
      error_.set("%s: stops answering: reading the status at 0x%02x failed: %s",
                 bus_->device().c_str(), status_register_, std::strerror(errno));
      return false;
    }
    t_ns = time_.now_ns();
    if ((status & status_ready_mask_) != 0) break;
    if (t_ns - start > timeout_ns) {
      error_.set("%s: stops answering: no new sample for %lld ms (status 0x%02x at 0x%02x)",
                 bus_->device().c_str(), static_cast<long long>(timeout_ns / 1'000'000), status,
                 status_register_);
      return false;
    }
    time_.sleep_until_ns(t_ns + poll_ns);
  }
  wait_ns_ = t_ns - start;
  next_due_ns_ = t_ns + period_ns_ - 2 * poll_ns;
  return true;
}

void RegisterImu::count_missed_samples(std::int64_t t_ns) {
  // The part counts on: samples further apart than a period are samples nobody read.
  if (drdy_ != nullptr || pace_) {
    if (last_sample_ns_ >= 0) {
      const long long periods = std::llround(static_cast<double>(t_ns - last_sample_ns_) /
                                             static_cast<double>(period_ns_));
      if (periods > 1) counters_.missed_samples += static_cast<std::uint64_t>(periods - 1);
    }
    last_sample_ns_ = t_ns;
  }
}

// The sample's bytes into raw; false when the bus fails, the registers hold no data, or (once a
// second) the part no longer answers as the one configured.
bool RegisterImu::read_data(std::uint8_t* raw) {
  if (!read_with_retry(data_register_, raw, data_length_)) {
    error_.set("%s: stops answering: reading %zu bytes at 0x%02x failed: %s",
               bus_->device().c_str(), data_length_, data_register_, std::strerror(errno));
    return false;
  }
  // A bus with nobody answering reads one byte value throughout (0xff where the data line floats
  // high or is pulled up, 0x00 where it is held low), and a part that reset itself reads its
  // no-data value: neither may reach the filter as a sample. A working part never reads all six
  // axes exactly zero (gravity and noise see to that).
  if (const char* why = no_data(raw)) {
    error_.set("%s: stops answering: the data registers read %s", bus_->device().c_str(), why);
    return false;
  }
  // Once a second, make sure the part is still the one we configured (a part replaced or reset
  // to another configuration would otherwise pass unnoticed).
  const std::uint64_t per_second =
      static_cast<std::uint64_t>(1'000'000'000 / (period_ns_ > 0 ? period_ns_ : 1));
  if (per_second > 0 && counters_.samples % per_second == per_second - 1) {
    std::uint8_t id = 0;
    if (!read_with_retry(who_am_i_register_, &id, 1) || id != who_am_i_) {
      error_.set("%s: stops answering: WHO_AM_I reads 0x%02x instead of 0x%02x",
                 bus_->device().c_str(), id, who_am_i_);
      return false;
    }
  }
  return true;
}

Mpu6050::Mpu6050(std::unique_ptr<RegisterBus> bus, const RegisterImuConfig& config,
                 hal::DataReadyLine* drdy)
    : RegisterImu(std::move(bus), drdy, config) {
  using namespace mpu6050;
  const std::string& device = this->bus().device();
  // Register map sections 4.4 and 4.5: FS_SEL / AFS_SEL codes and sensitivities.
  static const Scale gyro[] = {{0, 250, 131.0}, {1, 500, 65.5}, {2, 1000, 32.8}, {3, 2000, 16.4}};
  static const Scale accel[] = {{0, 2, 16384}, {1, 4, 8192}, {2, 8, 4096}, {3, 16, 2048}};
  const Scale& g = covering(gyro, config.gyro_range_dps, device, "gyro", "deg/s");
  const Scale& a = covering(accel, config.accel_range_g, device, "accelerometer", "g");
  if (!(config.rate_hz >= 1000.0 / 256 && config.rate_hz <= 1000))
    throw DriverError(Fault::kBadSpec, device + ": the MPU-6050 runs at 3.9 to 1000 Hz, not " +
                                           std::to_string(config.rate_hz));
  const long divider = std::lround(1000.0 / config.rate_hz) - 1;

  expect_who_am_i(kWhoAmI, kWhoAmIValue, "MPU-6050");
  write_checked(kPwrMgmt1, 0x01);  // awake, clocked from the X gyro's PLL
  write_verified(kSmplrtDiv, static_cast<std::uint8_t>(divider));
  write_verified(kConfig, 0x02);  // DLPF 94 Hz (gyro 98 Hz): 1 kHz gyro output rate
  write_verified(kGyroConfig, static_cast<std::uint8_t>(g.code << 3));
  write_verified(kAccelConfig, static_cast<std::uint8_t>(a.code << 3));
  write_checked(kIntPinCfg, 0x10);  // INT active high, push-pull, cleared by any read
  write_checked(kIntEnable, 0x01);  // DATA_RDY_EN

  data_register_ = kAccelXoutH;
  status_register_ = kIntStatus;  // any read clears it (INT_PIN_CFG's INT_RD_CLEAR above)
  status_ready_mask_ = kDataRdyInt;
  data_length_ = 14;  // accel (6), temperature (2), gyro (6)
  accel_offset_ = 0;
  gyro_offset_ = 8;
  period_ns_ = (divider + 1) * 1'000'000;
  gyro_lsb_per_dps_ = g.lsb_per_unit;
  accel_lsb_per_g_ = a.lsb_per_unit;
}

Icm42688::Icm42688(std::unique_ptr<RegisterBus> bus, const RegisterImuConfig& config,
                   hal::DataReadyLine* drdy)
    : RegisterImu(std::move(bus), drdy, config) {
  using namespace icm42688;
  const std::string& device = this->bus().device();
  // Data sheet sections 3.1, 3.2 and 14 (GYRO_CONFIG0, ACCEL_CONFIG0).
  static const Scale gyro[] = {{0, 2000, 16.4},    {1, 1000, 32.8},    {2, 500, 65.5},
                               {3, 250, 131},      {4, 125, 262},      {5, 62.5, 524.3},
                               {6, 31.25, 1048.6}, {7, 15.625, 2097.2}};
  static const Scale accel[] = {{0, 16, 2048}, {1, 8, 4096}, {2, 4, 8192}, {3, 2, 16384}};
  struct Odr {
    std::uint8_t code;
    double hz;
  };
  static const Odr rates[] = {{3, 8000}, {4, 4000}, {5, 2000}, {6, 1000}, {15, 500},
                              {7, 200},  {8, 100},  {9, 50},   {10, 25},  {11, 12.5}};
  const Scale& g = covering(gyro, config.gyro_range_dps, device, "gyro", "deg/s");
  const Scale& a = covering(accel, config.accel_range_g, device, "accelerometer", "g");
  const Odr* odr = nullptr;
  for (const Odr& r : rates)
    if (std::fabs(r.hz - config.rate_hz) < 1e-9) odr = &r;
  if (odr == nullptr)
    throw DriverError(Fault::kBadSpec,
                      device + ": the ICM-42688-P has no output rate of " +
                          std::to_string(config.rate_hz) +
                          " Hz (12.5, 25, 50, 100, 200, 500, 1000, 2000, 4000, 8000)");

  write_checked(kBankSel, 0);  // the part may have been left in another bank
  expect_who_am_i(kWhoAmI, kWhoAmIValue, "ICM-42688-P");
  write_checked(kDeviceConfig, 0x01);  // soft reset; registers usable after 1 ms
  time_.sleep_until_ns(time_.now_ns() + 1'000'000);
  write_verified(kGyroConfig0, static_cast<std::uint8_t>(g.code << 5 | odr->code));
  write_verified(kAccelConfig0, static_cast<std::uint8_t>(a.code << 5 | odr->code));
  write_checked(kIntConfig, 0x03);   // INT1 push-pull, active high, pulsed
  write_checked(kIntConfig1, 0x00);  // INT_ASYNC_RESET cleared, as the data sheet asks
  write_checked(kIntSource0, 0x08);  // UI_DRDY_INT1_EN
  write_checked(kPwrMgmt0, 0x0F);    // gyro and accelerometer in low-noise mode
  time_.sleep_until_ns(time_.now_ns() + 45'000'000);  // gyro start-up (no access for 200 us either)
  std::uint8_t power = 0;
  if (!read_register(kPwrMgmt0, power) || power != 0x0F)
    throw DriverError(Fault::kWrongKind, device + ": PWR_MGMT0 reads " + hex(power) +
                                             " after writing 0x0f (not an ICM-42688-P?)");

  data_register_ = kAccelDataX1;
  status_register_ = kIntStatus;
  status_ready_mask_ = kDataRdyInt;
  data_length_ = 12;
  no_data_value_valid_ = true;  // its data registers read -32768 while a sensor is off
  no_data_value_ = -32768;
  accel_offset_ = 0;
  gyro_offset_ = 6;
  period_ns_ = std::llround(1e9 / odr->hz);
  gyro_lsb_per_dps_ = g.lsb_per_unit;
  accel_lsb_per_g_ = a.lsb_per_unit;
}

}  // namespace mirrorcal::drivers
