// What `mirrorcal run` runs on: the devices and settings from a config file and the command line.
#pragma once

#include <string>
#include <string_view>

namespace mirrorcal::app {

struct RunSettings {
  std::string imu;      // device spec: spi:/dev/spidev0.0, i2c:/dev/i2c-1:0x68, can:can0
  std::string drdy;     // the IMU's data-ready line, CHIP:LINE (optional)
  std::string trigger;  // the camera's trigger input, driven as a GPIO output, CHIP:LINE (optional)
  int trigger_every =
      0;                // IMU samples per trigger pulse (>= 2); 0: from the camera's frame interval
  std::string camera;   // /dev/videoN (optional)
  std::string sensors;  // directory with imu.yaml, camchain.yaml, mirrorcal.yaml
  std::string out = "out/run";
  double duration_s = 0.0;  // 0: until the IMU stream ends or fails
  double rate_hz = 200.0;   // IMU output rate (SPI and I2C parts)
  double gyro_range_dps = 500.0;
  double accel_range_g = 4.0;
};

// The settings' keys, which are also the command line's option names (--imu, --duration, ...).
extern const char* const kRunKeys[11];

// Sets one setting from its key and text; false with a message naming the key and the value.
bool set_run_setting(RunSettings& s, const std::string& key, const std::string& value,
                     std::string& error);

// A config file: `key: value` lines (a flat YAML map; `#` starts a comment; values may be quoted).
// False with "FILE:LINE: what is wrong" for unknown or repeated keys and bad values.
bool parse_run_config(std::string_view text, const std::string& file, RunSettings& s,
                      std::string& error);

}  // namespace mirrorcal::app
