// A recording's data checked against what its files say they are: mistakes the parsers cannot
// see, as each line is well formed (timestamps in another unit than ns, deg/s given for rad/s, g
// for m/s^2, noise densities that are not the data's).
#pragma once

#include <string>
#include <vector>

#include "mirrorcal/sim_host/recording.hpp"

namespace mirrorcal::sim {

// The file names the messages give.
struct RecordingFiles {
  std::string imu_csv, frames_csv, imu_yaml;
};

// The IMU's sample rate in its timestamps against imu.yaml's update_rate (false: beyond
// kImuRateTolerance, most likely timestamps in us or ms).
bool check_imu_rate(const Recording& r, const RecordingFiles& files, std::string& error);
// The frames (at least one) lie within the IMU data and span about as long (false: most outside
// it, or a span orders of magnitude shorter, most likely the camera's timestamps in another unit).
bool check_frames_against_imu(const Recording& r, const RecordingFiles& files, std::string& error);
// Gyro and accelerometer magnitudes in rad/s and m/s^2 (false: deg/s, or g).
bool check_imu_units(const Recording& r, const RecordingFiles& files, std::string& error);
// imu.yaml's noise against the range of real parts and against the data's own high-frequency
// noise; what disagrees goes into warnings (it may be right, the calibration goes on).
void check_noise_densities(const Recording& r, const RecordingFiles& files,
                           std::vector<std::string>& warnings);

}  // namespace mirrorcal::sim
