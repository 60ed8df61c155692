// Byte registers of a sensor behind a bus: i2c-dev (SMBus byte-data writes, I2C-block reads) or
// spidev (one full-duplex transfer per access, bit 7 of the first byte set for reads). The
// sensors' drivers (register_imu.hpp) see only this interface; tests put fakes behind it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace mirrorcal::drivers {

class RegisterBus {
 public:
  virtual ~RegisterBus() = default;
  // false on failure, with errno telling why.
  virtual bool write(std::uint8_t reg, std::uint8_t value) = 0;
  virtual bool read(std::uint8_t first, std::uint8_t* out, std::size_t n) = 0;
  // The device, for messages (for I2C: the node and the address, /dev/i2c-1:0x68).
  virtual const std::string& device() const = 0;
};

// An I2C client through /dev/i2c-N. Opening checks that the node is an I2C adapter offering the
// SMBus transfers used and claims the address; throws DriverError otherwise.
class I2cBus final : public RegisterBus {
 public:
  I2cBus(const std::string& device, int address);
  ~I2cBus() override;
  I2cBus(const I2cBus&) = delete;
  I2cBus& operator=(const I2cBus&) = delete;

  bool write(std::uint8_t reg, std::uint8_t value) override;
  // In I2C-block reads of at most 32 bytes (the SMBus block limit).
  bool read(std::uint8_t first, std::uint8_t* out, std::size_t n) override;
  const std::string& device() const override { return device_; }

 private:
  std::string device_;
  int fd_ = -1;
};

// One full-duplex SPI transfer of n bytes: tx out, rx in (the same length).
class SpiTransport {
 public:
  virtual ~SpiTransport() = default;
  virtual bool transfer(const std::uint8_t* tx, std::uint8_t* rx, std::size_t n) = 0;
  virtual const std::string& device() const = 0;
};

// /dev/spidevB.C through SPI_IOC_MESSAGE; opening sets mode and clock, throws DriverError.
class SpidevTransport final : public SpiTransport {
 public:
  SpidevTransport(const std::string& device, std::uint32_t speed_hz, std::uint8_t mode);
  ~SpidevTransport() override;
  SpidevTransport(const SpidevTransport&) = delete;
  SpidevTransport& operator=(const SpidevTransport&) = delete;

  bool transfer(const std::uint8_t* tx, std::uint8_t* rx, std::size_t n) override;
  const std::string& device() const override { return device_; }

 private:
  std::string device_;
  int fd_ = -1;
  std::uint32_t speed_hz_;
};

// Register access framed for SPI sensors (InvenSense, Bosch): the first byte is the register
// address with bit 7 set for a read; reads continue at increasing addresses.
class SpiRegisterBus final : public RegisterBus {
 public:
  static constexpr std::size_t kMaxRead = 63;
  explicit SpiRegisterBus(std::unique_ptr<SpiTransport> transport)
      : transport_(std::move(transport)) {}
  bool write(std::uint8_t reg, std::uint8_t value) override;
  bool read(std::uint8_t first, std::uint8_t* out, std::size_t n) override;
  const std::string& device() const override { return transport_->device(); }

 private:
  std::unique_ptr<SpiTransport> transport_;
};

}  // namespace mirrorcal::drivers
