// Device specifications as users write them on the command line or in a config file:
//   spi:/dev/spidev0.0       an ICM-42688-P on a spidev node
//   i2c:/dev/i2c-1[:0x68]    an MPU-6050 (family) on an i2c-dev node, 7-bit address (default 0x68)
//   can:can0                 a Bosch MM7.10 on a SocketCAN interface
//   gpiochip0:17             line 17 of a GPIO chip (also /dev/gpiochip0:17), e.g. for --drdy
//   /dev/video0[:grey|:yuyv] a V4L2 camera; without a format, the device's current one if it is
//                            GREY or YUYV, else GREY
#pragma once

#include <string>

#include "mirrorcal/hal/frames.hpp"

namespace mirrorcal::drivers {

enum class ImuBus { kSpi, kI2c, kCan };

struct ImuSpec {
  ImuBus bus = ImuBus::kSpi;
  std::string device;  // /dev/spidev0.0, /dev/i2c-1, or the network interface (can0)
  int i2c_address = 0x68;
  std::string text;  // the specification as written, for messages
};

struct LineSpec {
  std::string chip;  // as libgpiod looks it up: gpiochip0, /dev/gpiochip0, or a label
  unsigned line = 0;
  std::string text;
};

struct CameraSpec {
  std::string device;  // /dev/video0
  bool format_given = false;
  hal::PixelFormat format = hal::PixelFormat::kGrey;
  std::string text;
};

// All throw DriverError (Fault::kBadSpec) naming the specification and what is wrong with it.
ImuSpec parse_imu_spec(const std::string& spec);
LineSpec parse_line_spec(const std::string& spec);
CameraSpec parse_camera_spec(const std::string& spec);

const char* bus_name(ImuBus bus);

}  // namespace mirrorcal::drivers
