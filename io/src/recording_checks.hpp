// A recording's data checked against what its files say they are: mistakes the parsers cannot
// see, as each line is well formed (timestamps in another unit than ns, deg/s given for rad/s, g
// for m/s^2, noise densities that are not the data's).
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::io {

// The file names the messages give (a bag's: the bag and the topic).
struct RecordingFiles {
  std::string imu_csv, frames_csv, imu_yaml, features_csv;
};

// FNV-1a over the bytes of each file in turn: the same data give the same fingerprint, wherever
// the recording lies.
class Fingerprint {
 public:
  void add(std::string_view bytes) {
    for (const char c : bytes) {
      hash_ ^= static_cast<unsigned char>(c);
      hash_ *= 0x100000001b3ULL;
    }
  }
  std::string hex() const {
    char s[17];
    std::snprintf(s, sizeof s, "%016llx", static_cast<unsigned long long>(hash_));
    return s;
  }

 private:
  std::uint64_t hash_ = 0xcbf29ce484222325ULL;
};

// A recording's descriptions in dir: imu.yaml, camchain.yaml, mirrorcal.yaml and truth.yaml if
// there (into out's sensors, priors and truth; defaults used into its notes).
bool read_descriptions(const std::string& dir, Recording& out, std::string& error);
// The checks of a recording whose stats are gathered: enough data, the IMU's rate and units, the
// frames within the IMU data, every marker seen (unless out.from_images); the notes and
// warnings they leave go into out.
bool check_recording(Recording& out, const RecordingFiles& named, int markers, std::string& error);

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

}  // namespace mirrorcal::io
