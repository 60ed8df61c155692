#include "mirrorcal/drivers/register_bus.hpp"

#include <fcntl.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>
#include <linux/spi/spidev.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "mirrorcal/drivers/driver_error.hpp"

namespace mirrorcal::drivers {
namespace {

std::string hex(int value) {
  char buf[8];
  std::snprintf(buf, sizeof(buf), "0x%02x", value);
  return buf;
}

int open_device(const std::string& device) {
  const int fd = ::open(device.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) throw os_error(device, "cannot open", errno);
  return fd;
}

bool smbus(int fd, std::uint8_t read_write, std::uint8_t command, std::uint32_t size,
           i2c_smbus_data* data) {
  i2c_smbus_ioctl_data args{};
  args.read_write = read_write;
  args.command = command;
  args.size = size;
  args.data = data;
  return ::ioctl(fd, I2C_SMBUS, &args) == 0;
}

}  // namespace

I2cBus::I2cBus(const std::string& device, int address) : device_(device + ":" + hex(address)) {
  fd_ = open_device(device);
  unsigned long funcs = 0;
  if (::ioctl(fd_, I2C_FUNCS, &funcs) != 0) {
    const int err = errno;
    ::close(fd_);
    throw DriverError(Fault::kWrongKind,
                      device + ": not an I2C adapter (I2C_FUNCS: " + std::strerror(err) + ")");
  }
  const unsigned long needed = I2C_FUNC_SMBUS_WRITE_BYTE_DATA | I2C_FUNC_SMBUS_READ_I2C_BLOCK;
  if ((funcs & needed) != needed) {
    ::close(fd_);
    throw DriverError(Fault::kWrongKind,
                      device + ": the adapter offers no SMBus byte-data writes or I2C-block reads");
  }
  // I2C_SLAVE fails with EBUSY when a kernel driver has bound the address.
  if (::ioctl(fd_, I2C_SLAVE, static_cast<unsigned long>(address)) != 0) {
    const int err = errno;
    ::close(fd_);
    if (err == EBUSY)
      throw DriverError(Fault::kBusy, device + ": address " + hex(address) +
                                          " is claimed by a kernel driver (busy)");
    throw os_error(device, "cannot address " + hex(address), err);
  }
}

I2cBus::~I2cBus() {
  if (fd_ >= 0) ::close(fd_);
}

bool I2cBus::write(std::uint8_t reg, std::uint8_t value) {
  i2c_smbus_data data{};
  data.byte = value;
  return smbus(fd_, I2C_SMBUS_WRITE, reg, I2C_SMBUS_BYTE_DATA, &data);
}

bool I2cBus::read(std::uint8_t first, std::uint8_t* out, std::size_t n) {
  while (n > 0) {
    const std::size_t chunk = n < I2C_SMBUS_BLOCK_MAX ? n : I2C_SMBUS_BLOCK_MAX;
    i2c_smbus_data data{};
    data.block[0] = static_cast<std::uint8_t>(chunk);
    if (!smbus(fd_, I2C_SMBUS_READ, first, I2C_SMBUS_I2C_BLOCK_DATA, &data)) return false;
    if (data.block[0] != chunk) {
      errno = EIO;
      return false;
    }
    std::memcpy(out, &data.block[1], chunk);
    out += chunk;
    first = static_cast<std::uint8_t>(first + chunk);
    n -= chunk;
  }
  return true;
}

SpidevTransport::SpidevTransport(const std::string& device, std::uint32_t speed_hz,
                                 std::uint8_t mode)
    : device_(device), speed_hz_(speed_hz) {
  fd_ = open_device(device);
  std::uint8_t bits = 8;
  if (::ioctl(fd_, SPI_IOC_WR_MODE, &mode) != 0 || ::ioctl(fd_, SPI_IOC_WR_BITS_PER_WORD, &bits) ||
      ::ioctl(fd_, SPI_IOC_WR_MAX_SPEED_HZ, &speed_hz) != 0) {
    const int err = errno;
    ::close(fd_);
    if (err == ENOTTY)
      throw DriverError(Fault::kWrongKind, device + ": not a spidev node (SPI ioctls refused)");
    throw os_error(device, "cannot set SPI mode and clock", err);
  }
}

SpidevTransport::~SpidevTransport() {
  if (fd_ >= 0) ::close(fd_);
}

bool SpidevTransport::transfer(const std::uint8_t* tx, std::uint8_t* rx, std::size_t n) {
  spi_ioc_transfer t{};
  t.tx_buf = reinterpret_cast<std::uintptr_t>(tx);
  t.rx_buf = reinterpret_cast<std::uintptr_t>(rx);
  t.len = static_cast<std::uint32_t>(n);
  t.speed_hz = speed_hz_;
  t.bits_per_word = 8;
  return ::ioctl(fd_, SPI_IOC_MESSAGE(1), &t) >= 0;
}

bool SpiRegisterBus::write(std::uint8_t reg, std::uint8_t value) {
  const std::uint8_t tx[2] = {static_cast<std::uint8_t>(reg & 0x7f), value};
  std::uint8_t rx[2];
  return transport_->transfer(tx, rx, 2);
}

bool SpiRegisterBus::read(std::uint8_t first, std::uint8_t* out, std::size_t n) {
  if (n > kMaxRead) {
    errno = EINVAL;
    return false;
  }
  std::uint8_t tx[kMaxRead + 1] = {};
  std::uint8_t rx[kMaxRead + 1] = {};
  tx[0] = static_cast<std::uint8_t>(first | 0x80);
  if (!transport_->transfer(tx, rx, n + 1)) return false;
  std::memcpy(out, rx + 1, n);
  return true;
}

}  // namespace mirrorcal::drivers
