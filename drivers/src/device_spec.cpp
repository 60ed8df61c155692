#include "mirrorcal/drivers/device_spec.hpp"

#include <cstdlib>

#include "mirrorcal/drivers/driver_error.hpp"

namespace mirrorcal::drivers {
namespace {

[[noreturn]] void bad(const std::string& spec, const std::string& why) {
  throw DriverError(Fault::kBadSpec, "bad device specification '" + spec + "': " + why);
}

// A whole-string unsigned number (decimal, or hex with 0x); false if anything else.
bool parse_unsigned(const std::string& s, unsigned long& value) {
  if (s.empty() || s[0] == '-' || s[0] == '+' || s[0] == ' ') return false;
  char* end = nullptr;
  value = std::strtoul(s.c_str(), &end, 0);
  return end != nullptr && *end == '\0';
}

}  // namespace

const char* bus_name(ImuBus bus) {
  switch (bus) {
    case ImuBus::kSpi:
      return "spi";
    case ImuBus::kI2c:
      return "i2c";
    case ImuBus::kCan:
      return "can";
  }
  return "?";
}

ImuSpec parse_imu_spec(const std::string& spec) {
  const std::size_t colon = spec.find(':');
  if (colon == std::string::npos)
    bad(spec, "expected BUS:DEVICE, e.g. spi:/dev/spidev0.0, i2c:/dev/i2c-1:0x68 or can:can0");
  const std::string bus = spec.substr(0, colon);
  std::string rest = spec.substr(colon + 1);
  ImuSpec out;
  out.text = spec;
  if (bus == "spi") {
    out.bus = ImuBus::kSpi;
    if (rest.empty() || rest[0] != '/')
      bad(spec, "expected a device path, e.g. spi:/dev/spidev0.0");
    out.device = rest;
  } else if (bus == "i2c") {
    out.bus = ImuBus::kI2c;
    const std::size_t c2 = rest.find(':');
    if (c2 != std::string::npos) {
      unsigned long address = 0;
      const std::string a = rest.substr(c2 + 1);
      if (!parse_unsigned(a, address) || address < 0x03 || address > 0x77)
        bad(spec, "'" + a + "' is no 7-bit I2C address (0x03 to 0x77)");
      out.i2c_address = static_cast<int>(address);
      rest = rest.substr(0, c2);
    }
    if (rest.empty() || rest[0] != '/')
      bad(spec, "expected a device path, e.g. i2c:/dev/i2c-1:0x68");
    out.device = rest;
  } else if (bus == "can") {
    out.bus = ImuBus::kCan;
    if (rest.empty() || rest.size() > 15 || rest.find_first_of("/: ") != std::string::npos)
      bad(spec, "expected a network interface name, e.g. can:can0");
    out.device = rest;
  } else {
    bad(spec, "unknown bus '" + bus + "' (spi, i2c or can)");
  }
  return out;
}

LineSpec parse_line_spec(const std::string& spec) {
  const std::size_t colon = spec.rfind(':');
  if (colon == std::string::npos || colon == 0) bad(spec, "expected CHIP:LINE, e.g. gpiochip0:17");
  unsigned long line = 0;
  const std::string l = spec.substr(colon + 1);
  if (!parse_unsigned(l, line) || line > 1023) bad(spec, "'" + l + "' is no GPIO line number");
  LineSpec out;
  out.chip = spec.substr(0, colon);
  out.line = static_cast<unsigned>(line);
  out.text = spec;
  return out;
}

CameraSpec parse_camera_spec(const std::string& spec) {
  CameraSpec out;
  out.text = spec;
  out.device = spec;
  const std::size_t colon = spec.rfind(':');
  if (colon != std::string::npos) {
    const std::string format = spec.substr(colon + 1);
    if (format == "grey")
      out.format = hal::PixelFormat::kGrey;
    else if (format == "yuyv")
      out.format = hal::PixelFormat::kYuyv;
    else
      bad(spec, "unknown pixel format '" + format + "' (grey or yuyv)");
    out.format_given = true;
    out.device = spec.substr(0, colon);
  }
  if (out.device.empty() || out.device[0] != '/')
    bad(spec, "expected a device path, e.g. /dev/video0 or /dev/video0:yuyv");
  return out;
}

}  // namespace mirrorcal::drivers
