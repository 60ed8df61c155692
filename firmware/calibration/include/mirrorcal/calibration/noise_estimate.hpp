// The noise levels a calibration assumes, estimated from its own data instead of taken from
// imu.yaml and mirrorcal.yaml: the gyro's and accelerometer's white-noise densities from the IMU
// samples, and the pixel noise from the refinement's linearised pass (issue 35).
//
// Why these estimators. The filter's process noise over a frame interval holds the gyro's white
// noise as an attitude random walk of sigma_g sqrt(dt): 4e-5 to 2e-4 rad over 50 ms for the
// random family's IMUs, where a frame's markers pin the attitude to a few 1e-4 rad. An
// expectation-maximisation of the process noise along the smoothed trajectory (Shumway-Stoffer)
// would see it only below about 0.5 Hz, some 30 independent samples an axis in 60 s, and would
// converge slowly from a wrong start, since the data hardly move it. The IMU's own samples hold
// the same white noise at every sample, 12000 a minute: a smooth signal sampled fast enough
// vanishes from its fourth differences (the family's 2 Hz sweeps keep 1e-4 of their amplitude
// there, far below the noise), the bias and its random walk cancel, and what is left is the white
// noise with a variance 70 times the sample's (1 + 16 + 36 + 16 + 1). The density is that
// sample sigma times sqrt(dt) (the simulator's and Kalibr's convention). A part whose own
// low-pass filter cuts below the Nyquist rate, or whose quantization step is comparable to its
// noise, shows less noise from sample to sample than its density at low frequency
// (docs/usage.md, imu-noise): the estimate would read low and the calibration over-confident.
// Such noise shows more over every other sample than from one to the next, where white noise
// shows the same: a sensor whose two readings differ by more than 5 % keeps its stated density,
// and a still recording through `mirrorcal imu-noise` is the better source.
//
// The pixel noise is Foerstner's variance-component estimate over the last linearised pass of the
// refinement (the Kalman filter of the problem linearised along the smoothed trajectory): with
// innovations nu, their covariance S and the noise R = sigma^2 I, the residuals e = R S^-1 nu
// have E[e^T e] = sigma^2 tr(R S^-1) when sigma is right, so sigma^2 e^T e / (sigma^2 tr(R S^-1))
// is the estimate, and the calibration is refined again with it until it no longer moves (the
// estimate's fixed point is the REML estimate; a step takes an error to its share in S, which
// the markers' own noise dominates: two or three steps suffice from 5x off). Its sigma is that
// of a variance from r = tr(R S^-1) degrees of freedom: sigma / sqrt(2 r).
//
// The bias random walks are left as stated: 60 s hardly see them (a walk shows in the Allan
// deviation beyond tens of seconds, which only a long still recording resolves).
#pragma once

#include <cstdint>
#include <string>

#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/hal/sources.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::calibration {

// What a calibration estimated of the noise it assumed, and what it was told.
struct NoiseEstimate {
  bool estimated = false;  // false: the levels stated were used as they are
  // The densities and the pixel noise stated (imu.yaml, mirrorcal.yaml).
  ImuNoise told{};
  double told_pixel_sigma = 0.0;
  // The estimates (the random walks are told's) and their 1-sigma.
  ImuNoise imu{};
  double gyro_density_sigma = 0.0, accel_density_sigma = 0.0;
  double pixel_sigma = 0.0, pixel_sigma_sigma = 0.0;
  double imu_rate_hz = 0.0;  // the IMU's nominal rate (imu.yaml's update_rate)
  // imu.yaml's own keys the calibration used (the IMU model, the tolerances), which the imu.yaml
  // written with the estimates keeps, so that calibrating from it changes only the noise.
  ImuModel imu_model = ImuModel::kCalibrated;
  ImuIntrinsicsSigma imu_tolerances{};
  std::uint64_t imu_differences = 0;  // the fourth differences the densities rest on
  // Whether each density was estimated: false where the samples' noise was not white from sample
  // to sample (ImuWhiteNoise::white; a part's own low-pass filter), and the stated one was kept.
  bool gyro_estimated = false, accel_estimated = false;
  double gyro_stride2_ratio = 0.0, accel_stride2_ratio = 0.0;  // that test's figures (1: white)
  double pixel_redundancy = 0.0;  // tr(R S^-1) over the last linearised pass
  int refinements = 0;            // the calibration refined again with the estimates
  bool converged = false;         // the pixel noise's last refinement moved it < 2 %
};

// The white-noise densities of the IMU's samples (their fourth differences over runs of five
// samples nominal_period_ns apart, within 10 %), with their 1-sigma from the spread of 20 batches.
// False if fewer than 200 differences could be formed.
struct ImuWhiteNoise {
  double gyro_density = 0.0, accel_density = 0.0;
  double gyro_sigma = 0.0, accel_sigma = 0.0;
  // The density read the same way from every other sample over the one above: 1 for white noise
  // (motion stays far below the noise at either stride). A part's own low-pass filter makes the
  // noise show less from sample to sample than over two (a first-order filter at 70 Hz in a
  // 200 Hz part: the density reads 0.81 of the truth); beyond kWhiteTolerance, the density is
  // not taken (white() false) and the stated one stays.
  double gyro_stride2_ratio = 0.0, accel_stride2_ratio = 0.0;
  std::uint64_t differences = 0;
  static constexpr double kWhiteTolerance = 0.05;
  static bool white(double stride2_ratio);
};
bool imu_white_noise(hal::ImuSource& imu, std::int64_t nominal_period_ns, ImuWhiteNoise& out);

// Foerstner's estimate of the pixel noise from a pass's sums (FilterCounters' pixel_noise_*),
// told the one the pass assumed; its 1-sigma into sigma. False if the pass had no redundancy.
bool pixel_noise_estimate(double quadratic, double redundancy, double told_pixel_sigma,
                          double& estimate, double& sigma);

// Kalibr's imu.yaml with the estimated densities (and the random walks stated), the IMU model
// and tolerances used, as the shared writer writes it (io::imu_yaml_text), with a comment saying
// where they come from.
std::string estimated_imu_yaml(const NoiseEstimate& n);
// The same as imu.yaml at path, added to out (written with the run's other outputs, or none).
bool add_estimated_imu_yaml(io::OutputSet& out, const std::string& path, const NoiseEstimate& n,
                            std::string& error);

}  // namespace mirrorcal::calibration
