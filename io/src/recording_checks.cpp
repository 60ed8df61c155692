#include "recording_checks.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace mirrorcal::io {

namespace {

// How far the IMU's rate may lie from update_rate: a real part's clock is off by a few percent,
// dropped samples lower the mean but not the median step.
constexpr double kImuRateTolerance = 1.5;
// A camera that spans this many times less than the IMU (or less than half its frames within the
// IMU data) is on another clock or in another unit.
constexpr double kFrameSpanFactor = 100.0;
// No gyro measures beyond 35 rad/s (2000 deg/s, the widest MEMS range): above, deg/s.
constexpr double kMaxGyroNorm = 35.0;
// An accelerometer in g reads about 1 at rest; in m/s^2 about 9.81.
constexpr double kMinAccelNormG = 0.5, kMaxAccelNormG = 2.0;
// The noise stated and the data's may differ by this factor before a warning: the sqrt(rate)
// mix-up of discrete and continuous noise is 14x at 200 Hz, 4.5x at 20 Hz.
constexpr double kNoiseFactor = 4.0;

std::string number(double v) {
  char s[32];
  std::snprintf(s, sizeof s, "%.3g", v);
  return s;
}

// What timestamps factor times too small (or the ratio of two rates) most likely are.
std::string unit_hint(double factor) {
  const auto near = [&](double f) { return factor > f / 3.0 && factor < f * 3.0; };
  if (near(1e3)) return "timestamps in microseconds instead of nanoseconds?";
  if (near(1e6)) return "timestamps in milliseconds instead of nanoseconds?";
  if (near(1e9)) return "timestamps in seconds instead of nanoseconds?";
  return "timestamps in another unit than nanoseconds, or another clock?";
}

// The densities and random walks of real MEMS parts, generously (units of imu.yaml's keys).
struct NoiseRange {
  const char* key;
  double ImuNoise::*value;
  double lo, hi;
  const char* unit;
};
constexpr NoiseRange kNoiseRanges[] = {
    {"gyroscope_noise_density", &ImuNoise::gyro_noise_density, 1e-6, 1e-2, "rad/s/sqrt(Hz)"},
    {"gyroscope_random_walk", &ImuNoise::gyro_random_walk, 1e-7, 1e-2, "rad/s^2/sqrt(Hz)"},
    {"accelerometer_noise_density", &ImuNoise::accel_noise_density, 1e-5, 1e-1, "m/s^2/sqrt(Hz)"},
    {"accelerometer_random_walk", &ImuNoise::accel_random_walk, 1e-6, 1e-1, "m/s^3/sqrt(Hz)"},
};

// The warning, if any, for one sensor's stated density against its data's noise.
void compare_density(const Recording& r, const RecordingFiles& files, bool gyro,
                     std::vector<std::string>& warnings) {
  const double density =
      gyro ? r.sensors.imu.gyro_noise_density : r.sensors.imu.accel_noise_density;
  const double stated = density * std::sqrt(r.sensors.imu_rate_hz);
  const double seen = gyro ? r.stats.gyro_noise_seen : r.stats.accel_noise_seen;
  if (seen <= 0.0) return;
  const double factor = stated / seen;
  if (factor <= kNoiseFactor && factor >= 1.0 / kNoiseFactor) return;
  const char* key = gyro ? "gyroscope_noise_density" : "accelerometer_noise_density";
  const char* unit = gyro ? "rad/s" : "m/s^2";
  std::string w = files.imu_yaml + ": " + key + " " + number(density) + " " + unit +
                  "/sqrt(Hz) implies a noise of " + number(stated) + " " + unit +
                  " per sample at " + number(r.sensors.imu_rate_hz) + " Hz, " +
                  number(factor > 1.0 ? factor : 1.0 / factor) + " times " +
                  (factor > 1.0 ? "more" : "less") + " than " + files.imu_csv +
                  " shows in its high-frequency noise (" + number(seen) + " " + unit + "): ";
  w += factor > 1.0 ? "a per-sample sigma given for the density (divide by sqrt(update_rate))?"
                    : "the density of another part, or in another unit?";
  warnings.push_back(w + " The calibration's sigmas rest on it.");
}

}  // namespace

void StreamMedian::add(double v) {
  if (seen_++ % stride_ != 0) return;
  if (kept_.size() == kKept) {  // keep every other value, and every other from now on
    for (std::size_t i = 0; i < kKept / 2; ++i) kept_[i] = kept_[2 * i];
    kept_.resize(kKept / 2);
    stride_ *= 2;
    if ((seen_ - 1) % stride_ != 0) return;
  }
  kept_.push_back(v);
}

double StreamMedian::median() const {
  if (kept_.empty()) return 0.0;
  std::vector<double> v = kept_;
  std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
  return v[v.size() / 2];
}

StatsGatherer::StatsGatherer(int markers) {
  stats_.marker_seen.assign(static_cast<std::size_t>(std::max(markers, 0)), false);
}

// The white noise's discrete sigma from the second differences of the samples, whose variance is
// 6 sigma^2; smooth motion adds little at IMU rates. Steps of unequal length (gaps) are left out.
void StatsGatherer::add(const ImuSample& s) {
  RecordingStats& st = stats_;
  if (st.imu_samples == 0) st.imu_first_ns = s.t_ns;
  if (st.imu_samples >= 1) steps_.add(double(s.t_ns - previous_[0].t_ns));
  if (st.imu_samples >= 2) {
    const double a = double(previous_[0].t_ns - previous_[1].t_ns);
    const double b = double(s.t_ns - previous_[0].t_ns);
    if (std::abs(a - b) <= 0.1 * std::max(a, b)) {
      noise_sum_[0] += (s.gyro - 2.0 * previous_[0].gyro + previous_[1].gyro).squaredNorm();
      noise_sum_[1] += (s.accel - 2.0 * previous_[0].accel + previous_[1].accel).squaredNorm();
      noise_n_ += 3;
    }
  }
  gyro_.add(s.gyro.norm());
  accel_.add(s.accel.norm());
  previous_[1] = previous_[0];
  previous_[0] = s;
  st.imu_last_ns = s.t_ns;
  ++st.imu_samples;
}

void StatsGatherer::add(const ObservedFrame& f) {
  RecordingStats& st = stats_;
  if (st.frames_listed++ == 0) st.frames_first_ns = f.t_ns;
  st.frames_last_ns = f.t_ns;
  if (st.imu_samples == 0 || f.t_ns < st.imu_first_ns || f.t_ns > st.imu_last_ns) return;
  if (st.frames++ == 0) st.frames_inside_first_ns = f.t_ns;
  st.frames_inside_last_ns = f.t_ns;
  st.markers += f.markers.size();
  for (const ObservedMarker& m : f.markers)
    if (m.id >= 0 && std::size_t(m.id) < st.marker_seen.size())
      st.marker_seen[std::size_t(m.id)] = true;
}

RecordingStats StatsGatherer::finish() {
  stats_.imu_step_median_ns = steps_.median();
  stats_.gyro_norm_median = gyro_.median();
  stats_.accel_norm_median = accel_.median();
  const auto sigma = [&](double sum) {
    return noise_n_ == 0 ? 0.0 : std::sqrt(sum / (6.0 * double(noise_n_)));
  };
  stats_.gyro_noise_seen = sigma(noise_sum_[0]);
  stats_.accel_noise_seen = sigma(noise_sum_[1]);
  return stats_;
}

bool check_imu_rate(const Recording& r, const RecordingFiles& files, std::string& error) {
  const double rate = 1e9 / r.stats.imu_step_median_ns;
  const double factor = rate / r.sensors.imu_rate_hz;
  if (factor <= kImuRateTolerance && factor >= 1.0 / kImuRateTolerance) return true;
  error = files.imu_csv + ": its timestamps step by " + number(r.stats.imu_step_median_ns) +
          " ns (median), " + number(rate) + " Hz, but " + files.imu_yaml + "'s update_rate is " +
          number(r.sensors.imu_rate_hz) + " Hz: " + unit_hint(factor);
  return false;
}

bool check_frames_against_imu(const Recording& r, const RecordingFiles& files, std::string& error) {
  const RecordingStats& st = r.stats;
  const std::int64_t t0 = st.imu_first_ns, t1 = st.imu_last_ns;
  const std::string imu_span = std::to_string(t0) + ".." + std::to_string(t1) + " ns";
  if (st.frames == 0 || 2 * st.frames < st.frames_listed) {
    const double cam_mid = 0.5 * (double(st.frames_first_ns) + double(st.frames_last_ns));
    const double imu_mid = 0.5 * (double(t0) + double(t1));
    error =
        files.frames_csv + ": " +
        (st.frames == 0 ? std::string("no frame within the IMU data")
                        : std::to_string(st.frames_listed - st.frames) + " of " +
                              std::to_string(st.frames_listed) + " frames outside the IMU data") +
        " (" + imu_span + " in " + files.imu_csv + "; the frames " +
        std::to_string(st.frames_first_ns) + ".." + std::to_string(st.frames_last_ns) +
        " ns); the filter needs them within: " +
        unit_hint(cam_mid > 0.0 && imu_mid > 0.0 ? imu_mid / cam_mid : 0.0);
    return false;
  }
  if (st.frames < 2) return true;
  const double imu_ns = double(t1 - t0);
  const double cam_ns = double(st.frames_inside_last_ns - st.frames_inside_first_ns);
  if (cam_ns * kFrameSpanFactor >= imu_ns) return true;
  error = files.frames_csv + ": the frames within the IMU data span " + number(cam_ns) +
          " ns, the IMU data " + number(imu_ns) + " ns (" + files.imu_csv + "), " +
          number(imu_ns / cam_ns) + " times longer: " + unit_hint(imu_ns / cam_ns);
  return false;
}

bool check_imu_units(const Recording& r, const RecordingFiles& files, std::string& error) {
  const double g = r.stats.gyro_norm_median, a = r.stats.accel_norm_median;
  if (g > kMaxGyroNorm) {
    error = files.imu_csv + ": the gyro's median rate is " + number(g) +
            " rad/s, beyond any part's range (" + number(kMaxGyroNorm) +
            " rad/s): deg/s given for rad/s?";
    return false;
  }
  if (a > kMinAccelNormG && a < kMaxAccelNormG) {
    error = files.imu_csv + ": the accelerometer's median magnitude is " + number(a) +
            " m/s^2, where gravity alone gives 9.81: g given for m/s^2?";
    return false;
  }
  return true;
}

void check_noise_densities(const Recording& r, const RecordingFiles& files,
                           std::vector<std::string>& warnings) {
  for (const NoiseRange& n : kNoiseRanges) {
    const double v = r.sensors.imu.*n.value;
    if (v >= n.lo && v <= n.hi) continue;
    warnings.push_back(files.imu_yaml + ": " + n.key + " " + number(v) + " " + n.unit +
                       " lies outside what real MEMS parts have (" + number(n.lo) + ".." +
                       number(n.hi) + "), " + number(v > n.hi ? v / n.hi : n.lo / v) +
                       " times: another unit, or a typo? The calibration's sigmas rest on it.");
  }
  compare_density(r, files, true, warnings);
  compare_density(r, files, false, warnings);
}

}  // namespace mirrorcal::io
