// An IMU's noise from a still recording (`mirrorcal imu-noise`): the overlapping Allan deviation of
// each axis, and the figures Kalibr's imu.yaml holds read from it. IEEE Std 952-1997, Annex C:
//   white noise N         sigma(tau) = N / sqrt(tau)        (slope -1/2, read at tau = 1 s)
//   bias instability B    sigma = 0.664 B at the flat floor  (slope 0)
//   bias random walk K    sigma(tau) = K sqrt(tau / 3)      (slope +1/2)
// N and K are in Kalibr's continuous-time units: rad/s/sqrt(Hz) and rad/s^2/sqrt(Hz) for the
// gyroscope, m/s^2/sqrt(Hz) and m/s^3/sqrt(Hz) for the accelerometer. Plain arithmetic on
// vectors: the board's program runs it too.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::calibration {

// Cluster sizes m (samples) spaced about per_decade to a decade from 1 up to n / 9: beyond a
// ninth of the data the Allan deviation rests on fewer than 16 independent clusters.
std::vector<std::size_t> allan_cluster_sizes(std::size_t n, int per_decade = 10);

// The overlapping Allan deviation of y (evenly spaced samples) at each cluster size in m (each
// within 1..n/2; 0 where it is not). Cumulative sums make each cluster size O(n).
std::vector<double> overlapping_allan_deviation(const std::vector<double>& y,
                                                const std::vector<std::size_t>& m);

// The Allan deviation's relative 1-sigma error at cluster size m over n samples: about
// 1 / sqrt(2 (n/m - 1)), from the number of independent clusters (IEEE 952, Annex C).
double allan_relative_error(std::size_t n, std::size_t m);

// One figure read from an Allan deviation curve.
struct NoiseFigure {
  // The figure; an upper bound when it is not resolved (the curve never showed its slope).
  double value = 0.0;
  bool resolved = false;
  double rel_sigma = 0.0;  // its relative 1-sigma (statistical) when resolved
  // Where it was read (s): the cluster times of the fitted region, or of the bound.
  double tau_lo_s = 0.0, tau_hi_s = 0.0;
  // When not resolved: the recording length (s) it would take at least to resolve it.
  double needed_s = 0.0;
};

// The three figures of one axis (or of a sensor, its three axes combined).
struct AxisNoise {
  NoiseFigure white;        // N
  NoiseFigure instability;  // B
  NoiseFigure random_walk;  // K
};

// Reads N, B and K from one Allan deviation curve (cluster sizes m of samples dt_s apart, n
// samples). N: a -1/2 line fitted where the curve's slope is within 0.1 of -1/2 (the first such
// run of three points or more); B: the curve's minimum / 0.664, resolved if the curve rises for
// three points after it; K: a +1/2 line fitted after the minimum where the slope exceeds 1/4, if
// the rise is beyond the statistical error, else an upper bound. Each fit takes out the other
// line's share of the variance. A figure without its region is not resolved (white.value 0: no
// white noise seen at all).
AxisNoise fit_allan_curve(const std::vector<std::size_t>& m, const std::vector<double>& adev,
                          std::size_t n, double dt_s);

// The three axes of a sensor as one figure each, as imu.yaml has: the root mean square of the
// axes' figures, resolved only if every axis's is (else an upper bound: the resolved axes at
// three of their sigmas above their figure).
AxisNoise combine_axes(const std::array<AxisNoise, 3>& axes);

// The six signals: gyroscope x, y, z then accelerometer x, y, z.
constexpr int kImuAxes = 6;
const char* imu_axis_name(int axis);  // "gyro x", ..., "accel z"

// What a still recording tells of its IMU's noise.
struct ImuNoiseAnalysis {
  std::string file;  // the data it came from (messages, the summary)
  std::size_t samples = 0;
  double rate_hz = 0.0, duration_s = 0.0;
  std::vector<std::size_t> m;
  std::vector<double> tau_s;
  std::array<std::vector<double>, kImuAxes> adev;
  std::array<AxisNoise, kImuAxes> axes;
  AxisNoise gyro, accel;           // the sensors' figures (combine_axes)
  double motion_ratio = 0.0;       // the stillness test's largest ratio (below kMotionRatio)
  std::vector<std::string> notes;  // what the user should know (dropped samples)
  ImuNoise noise() const;          // the figures imu.yaml gets (bounds where not resolved)
};

// Shorter recordings say nothing worth writing down (s).
constexpr double kMinStillDurationS = 60.0;
// A still axis's Allan deviation at tau = 1 s lies near its white-noise line; motion puts it this
// many times above.
constexpr double kMotionRatio = 3.0;
// A still accelerometer's norm (10-s means) stays this close to its median (m/s^2): bias drift
// is hundredths of that, a carried board or a vehicle's motion is more.
constexpr double kMaxNormDrift = 0.5;

// Analyses the samples of a still IMU (file names them in messages). False, with a message naming
// file and saying why, if they are too few or too short, their timestamps irregular, their units
// not rad/s and m/s^2, or the IMU moved.
bool analyse_imu_noise(const std::vector<ImuSample>& samples, const std::string& file,
                       ImuNoiseAnalysis& out, std::string& error);

// What a user reads: the figures with their uncertainties, and what it takes to resolve those
// that are not.
std::string imu_noise_summary(const ImuNoiseAnalysis& a);
// allan.csv: tau and the six Allan deviations.
std::string allan_csv(const ImuNoiseAnalysis& a);

}  // namespace mirrorcal::calibration
