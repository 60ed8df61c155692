// Device specifications: the forms the README documents parse to their parts; malformed ones
// fail with kBadSpec and a message quoting the specification.
#include <gtest/gtest.h>

#include "mirrorcal/drivers/device_spec.hpp"
#include "mirrorcal/drivers/driver_error.hpp"

namespace mirrorcal::drivers {
namespace {

TEST(DeviceSpec, ImuForms) {
  const ImuSpec spi = parse_imu_spec("spi:/dev/spidev0.0");
  EXPECT_EQ(spi.bus, ImuBus::kSpi);
  EXPECT_EQ(spi.device, "/dev/spidev0.0");

  const ImuSpec i2c = parse_imu_spec("i2c:/dev/i2c-1:0x69");
  EXPECT_EQ(i2c.bus, ImuBus::kI2c);
  EXPECT_EQ(i2c.device, "/dev/i2c-1");
  EXPECT_EQ(i2c.i2c_address, 0x69);
  EXPECT_EQ(parse_imu_spec("i2c:/dev/i2c-1").i2c_address, 0x68);
  EXPECT_EQ(parse_imu_spec("i2c:/dev/i2c-1:104").i2c_address, 104);

  const ImuSpec can = parse_imu_spec("can:can0");
  EXPECT_EQ(can.bus, ImuBus::kCan);
  EXPECT_EQ(can.device, "can0");
  EXPECT_EQ(can.text, "can:can0");
}

TEST(DeviceSpec, LineForms) {
  const LineSpec a = parse_line_spec("gpiochip0:17");
  EXPECT_EQ(a.chip, "gpiochip0");
  EXPECT_EQ(a.line, 17u);
  const LineSpec b = parse_line_spec("/dev/gpiochip2:0");
  EXPECT_EQ(b.chip, "/dev/gpiochip2");
  EXPECT_EQ(b.line, 0u);
}

TEST(DeviceSpec, CameraForms) {
  const CameraSpec plain = parse_camera_spec("/dev/video0");
  EXPECT_EQ(plain.device, "/dev/video0");
  EXPECT_FALSE(plain.format_given);
  const CameraSpec grey = parse_camera_spec("/dev/video2:grey");
  EXPECT_EQ(grey.device, "/dev/video2");
  EXPECT_TRUE(grey.format_given);
  EXPECT_EQ(grey.format, hal::PixelFormat::kGrey);
  const CameraSpec yuyv = parse_camera_spec("/dev/v4l/by-id/cam:yuyv");
  EXPECT_EQ(yuyv.device, "/dev/v4l/by-id/cam");
  EXPECT_EQ(yuyv.format, hal::PixelFormat::kYuyv);
  EXPECT_EQ(yuyv.text, "/dev/v4l/by-id/cam:yuyv");
}

TEST(DeviceSpec, BadCameraSpecsAreRefusedWithAReason) {
  for (const auto& [spec, fragment] :
       {std::pair<std::string, std::string>{"/dev/video0:rgb24", "unknown pixel format 'rgb24'"},
        {"video0", "device path"},
        {":grey", "device path"}}) {
    try {
      parse_camera_spec(spec);
      ADD_FAILURE() << "accepted '" << spec << "'";
    } catch (const DriverError& e) {
      EXPECT_EQ(e.fault(), Fault::kBadSpec);
      const std::string what = e.what();
      EXPECT_NE(what.find("'" + spec + "'"), std::string::npos) << what;
      EXPECT_NE(what.find(fragment), std::string::npos) << what;
    }
  }
}

void expect_bad(const std::string& spec, bool imu, const std::string& fragment) {
  try {
    if (imu)
      parse_imu_spec(spec);
    else
      parse_line_spec(spec);
    ADD_FAILURE() << "accepted '" << spec << "'";
  } catch (const DriverError& e) {
    EXPECT_EQ(e.fault(), Fault::kBadSpec);
    const std::string what = e.what();
    EXPECT_NE(what.find("'" + spec + "'"), std::string::npos) << what;
    EXPECT_NE(what.find(fragment), std::string::npos) << what;
  }
}

TEST(DeviceSpec, BadSpecsAreRefusedWithAReason) {
  expect_bad("/dev/spidev0.0", true, "BUS:DEVICE");
  expect_bad("usb:/dev/ttyUSB0", true, "unknown bus 'usb'");
  expect_bad("spi:spidev0.0", true, "device path");
  expect_bad("i2c:/dev/i2c-1:0x80", true, "7-bit I2C address");
  expect_bad("i2c:/dev/i2c-1:68h", true, "7-bit I2C address");
  expect_bad("i2c:/dev/i2c-1:", true, "7-bit I2C address");
  expect_bad("can:", true, "network interface");
  expect_bad("can:can0/x", true, "network interface");
  expect_bad("gpiochip0", false, "CHIP:LINE");
  expect_bad("gpiochip0:-1", false, "GPIO line number");
  expect_bad("gpiochip0:x", false, "GPIO line number");
  expect_bad(":3", false, "CHIP:LINE");
}

}  // namespace
}  // namespace mirrorcal::drivers
