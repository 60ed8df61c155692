// Kalibr's imu.yaml as text: the one writer of it, for recordings (record), imu-noise and the
// noise a calibration estimated. Apart from recording_yaml.cpp so that the calibration, which has
// no YAML reader, writes it too.
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/io/version.hpp"
#include "text_io.hpp"

namespace mirrorcal::io {

namespace {

std::string number(double v) {
  std::string s;
  text::append(s, v);
  return s;
}

}  // namespace

std::string imu_yaml_text(const SensorInfo& s) {
  std::string imu = "# Kalibr IMU description (continuous-time noise densities)\n# written by " +
                    written_by() + "\nrostopic: " + s.imu_rostopic + "\n";
  imu +=
      "accelerometer_noise_density: " + number(s.imu.accel_noise_density) + "  # m/s^2/sqrt(Hz)\n";
  imu += "accelerometer_random_walk: " + number(s.imu.accel_random_walk) + "  # m/s^3/sqrt(Hz)\n";
  imu += "gyroscope_noise_density: " + number(s.imu.gyro_noise_density) + "  # rad/s/sqrt(Hz)\n";
  imu += "gyroscope_random_walk: " + number(s.imu.gyro_random_walk) + "  # rad/s^2/sqrt(Hz)\n";
  imu += "update_rate: " + number(s.imu_rate_hz) + "  # Hz\n";
  if (s.imu_model)
    imu += std::string("# mirrorcal's: the IMU model to estimate\nimu_model: ") +
           to_string(*s.imu_model) + "\n";
  if (s.imu_model || !s.imu_tolerances_defaulted) {
    const ImuIntrinsicsSigma& t = s.imu_tolerances;
    imu +=
        "# mirrorcal's: the datasheet's tolerances (1-sigma; relative, g-sensitivity in "
        "(rad/s)/(m/s^2))\n";
    imu += "accelerometer_scale_tolerance: " + number(t.accel_scale) + "\n";
    imu += "accelerometer_cross_axis_tolerance: " + number(t.accel_misalignment) + "\n";
    imu += "gyroscope_scale_tolerance: " + number(t.gyro_scale) + "\n";
    imu += "gyroscope_cross_axis_tolerance: " + number(t.gyro_misalignment) + "\n";
    imu += "gyroscope_g_sensitivity: " + number(t.g_sensitivity) + "\n";
  }
  return imu;
}

}  // namespace mirrorcal::io
