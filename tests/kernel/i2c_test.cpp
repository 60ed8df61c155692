// I2C on a real kernel (i2c-stub at 0x68, i2c-dev): an MPU-6050 register file written in with
// busybox's i2cset is read back by the project's driver through SMBus I2C-block reads, value for
// value, paced by its INT_STATUS (a status that stays clear ends the stream); the configuration
// the driver writes is read back with i2cget; a missing adapter, a non-I2C node, an address
// nobody answers and an address a kernel client holds give their messages.
#include <dirent.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <string>

#include "expect_driver_error.hpp"
#include "guest_check.hpp"
#include "mirrorcal/drivers/register_imu.hpp"

namespace {

using namespace mirrorcal;
using namespace mirrorcal::drivers;

constexpr double kPi = 3.14159265358979323846;

// The i2c-dev node of the adapter named `name` ("SMBus stub driver"), or "" if none.
std::string find_adapter(const char* name, int& number) {
  DIR* dir = opendir("/sys/class/i2c-dev");
  if (dir == nullptr) return "";
  std::string found;
  while (dirent* e = readdir(dir)) {
    std::string n;
    std::getline(std::ifstream(std::string("/sys/class/i2c-dev/") + e->d_name + "/name"), n);
    if (n == name) {
      found = std::string("/dev/") + e->d_name;
      number = std::atoi(e->d_name + 4);
    }
  }
  closedir(dir);
  return found;
}

int run(const char* format, int bus, int reg, int value = -1) {
  char cmd[120];
  std::snprintf(cmd, sizeof(cmd), format, bus, reg, value);
  return std::system(cmd);
}

// i2cget's answer ("0x08") as a number, or -1.
int i2cget(int bus, int reg) {
  char cmd[80];
  std::snprintf(cmd, sizeof(cmd), "i2cget -y %d 0x68 0x%02x b", bus, reg);
  FILE* p = popen(cmd, "r");
  if (p == nullptr) return -1;
  char out[32] = "";
  const bool got = std::fgets(out, sizeof(out), p) != nullptr;
  pclose(p);
  return got ? static_cast<int>(std::strtol(out, nullptr, 16)) : -1;
}

}  // namespace

int main() {
  int bus = -1;
  const std::string node = find_adapter("SMBus stub driver", bus);
  if (!GUEST_CHECK(!node.empty())) return mirrorcal::guest::finish("kernel I2C");
  std::printf("i2c-stub is %s\n", node.c_str());

  // The register file: WHO_AM_I, asleep as after power-on, and a sample in 0x3B-0x48.
  const int raw[7] = {0x1234, -292 /* 0xFEDC */, 0x4000, 0x0102 /* temperature */,
                      0x0083, -131 /* 0xFF7D */, 0x7FFF};
  GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x75, 0x68) == 0);
  GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x6B, 0x40) == 0);
  // INT_STATUS's DATA_RDY_INT, which paces the reads without a data-ready line: set for good
  // (i2c-stub's registers do not clear when read), a new sample at every poll.
  GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x3A, 0x01) == 0);
  for (int i = 0; i < 7; ++i) {
    const unsigned u = static_cast<std::uint16_t>(raw[i]);
    GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x3B + 2 * i, u >> 8) == 0);
    GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x3C + 2 * i, u & 0xff) == 0);
  }

  RegisterImuConfig config;
  config.rate_hz = 200;
  config.gyro_range_dps = 500;  // FS_SEL 1: 65.5 LSB/(deg/s)
  config.accel_range_g = 4;     // AFS_SEL 1: 8192 LSB/g
  config.pace = true;

  // A kernel client at the address makes it busy for user space.
  char path[96];
  std::snprintf(path, sizeof(path), "/sys/bus/i2c/devices/i2c-%d/new_device", bus);
  GUEST_CHECK(static_cast<bool>(std::ofstream(path) << "dummy 0x68\n"));
  guest::expect_driver_error("busy", Fault::kBusy,
                             [&] { Mpu6050 imu(std::make_unique<I2cBus>(node, 0x68), config); });
  std::snprintf(path, sizeof(path), "/sys/bus/i2c/devices/i2c-%d/delete_device", bus);
  GUEST_CHECK(static_cast<bool>(std::ofstream(path) << "0x68\n"));

  try {
    Mpu6050 imu(std::make_unique<I2cBus>(node, 0x68), config);
    // What the driver configured, read back by another program.
    GUEST_CHECK(i2cget(bus, 0x1B) == 0x08);
    GUEST_CHECK(i2cget(bus, 0x1C) == 0x08);
    GUEST_CHECK(i2cget(bus, 0x19) == 4);
    GUEST_CHECK(i2cget(bus, 0x6B) == 0x01);
    for (int k = 0; k < 5; ++k) {
      ImuSample s;
      if (!GUEST_CHECK(imu.next(s) == hal::SourceStatus::kOk)) {
        std::printf("  %s\n", imu.error());
        break;
      }
      for (int i = 0; i < 3; ++i) {
        const double accel = raw[i] / 8192.0 * 9.80665;
        const double gyro = raw[4 + i] / 65.5 * kPi / 180;
        GUEST_CHECK(std::fabs(s.accel[i] - accel) <= 1e-12 * std::fabs(accel));
        GUEST_CHECK(std::fabs(s.gyro[i] - gyro) <= 1e-12 * std::fabs(gyro));
      }
      if (k == 0)
        std::printf("read: accel %.9f %.9f %.9f m/s^2, gyro %.9f %.9f %.9f rad/s\n", s.accel[0],
                    s.accel[1], s.accel[2], s.gyro[0], s.gyro[1], s.gyro[2]);
    }
    // The part stops sampling: DATA_RDY_INT stays clear, and after 20 periods (at least 200 ms)
    // the stream ends with a message.
    GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x3A, 0x00) == 0);
    {
      ImuSample s;
      GUEST_CHECK(imu.next(s) == hal::SourceStatus::kError);
      std::printf("no new sample: %s\n", imu.error());
      GUEST_CHECK(std::strstr(imu.error(), "stops answering: no new sample for 200 ms") != nullptr);
    }
    GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x3A, 0x01) == 0);
    // Mid-run the part resets (a brown-out): its data registers read 0x00. The next read ends the
    // stream with a message instead of handing the filter a sample of zeros.
    for (int i = 0; i < 14; ++i)
      GUEST_CHECK(run("i2cset -y %d 0x68 0x%02x 0x%02x b", bus, 0x3B + i, 0) == 0);
    ImuSample s;
    GUEST_CHECK(imu.next(s) == hal::SourceStatus::kError);
    std::printf("after a reset: %s\n", imu.error());
    GUEST_CHECK(std::strstr(imu.error(), "stops answering: the data registers read 0x00") !=
                nullptr);
  } catch (const DriverError& e) {
    std::printf("FAILED: %s\n", e.what());
    GUEST_CHECK(false);
  }

  guest::expect_driver_error("missing", Fault::kMissing, [&] {
    Mpu6050 imu(std::make_unique<I2cBus>("/dev/i2c-9", 0x68), config);
  });
  guest::expect_driver_error("wrong kind", Fault::kWrongKind, [&] {
    Mpu6050 imu(std::make_unique<I2cBus>("/dev/null", 0x68), config);
  });
  guest::expect_driver_error("no answer", Fault::kNotAnswering,
                             [&] { Mpu6050 imu(std::make_unique<I2cBus>(node, 0x69), config); });
  return mirrorcal::guest::finish("kernel I2C");
}
