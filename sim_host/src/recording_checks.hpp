// A recording's data checked against what its files say they are: mistakes the parsers cannot
// see, as each line is well formed (timestamps in another unit than ns, deg/s given for rad/s, g
// for m/s^2, noise densities that are not the data's).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mirrorcal/sim_host/recording.hpp"

namespace mirrorcal::sim {

// The file names the messages give.
struct RecordingFiles {
  std::string imu_csv, frames_csv, imu_yaml;
};

// A median over a stream of any length in bounded memory: exact over up to kKept values; beyond,
// over every 2^k-th value (k the smallest that keeps at most kKept).
class StreamMedian {
 public:
  static constexpr std::size_t kKept = 1 << 16;
  void add(double v);
  double median() const;  // 0 without values

 private:
  std::vector<double> kept_;
  std::uint64_t seen_ = 0, stride_ = 1;
};

// RecordingStats from the IMU samples, then the frames, fed in timestamp order.
class StatsGatherer {
 public:
  explicit StatsGatherer(int markers);
  void add(const ImuSample& s);
  // After the last IMU sample: the frames are judged against the IMU data's span.
  void add(const ObservedFrame& f);
  RecordingStats finish();

 private:
  RecordingStats stats_;
  StreamMedian steps_, gyro_, accel_;
  ImuSample previous_[2];             // the last two samples, newest first
  double noise_sum_[2] = {0.0, 0.0};  // gyro, accelerometer
  std::uint64_t noise_n_ = 0;
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
