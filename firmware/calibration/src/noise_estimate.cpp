#include "mirrorcal/calibration/noise_estimate.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::calibration {

namespace {

// The fourth difference's weights (1 -4 6 -4 1): the squares sum to 70.
constexpr std::array<double, 5> kWeights = {1.0, -4.0, 6.0, -4.0, 1.0};
constexpr double kWeightSquares = 70.0;
constexpr int kBatches = 20;

// The mean of values and its 1-sigma from the spread of kBatches consecutive batches' means
// (neighbouring differences share samples: the batches, each hundreds long, are nearly
// independent where single differences are not).
void mean_and_sigma(const std::vector<double>& values, double& mean, double& sigma) {
  const std::size_t n = values.size();
  double sum = 0.0;
  for (const double v : values) sum += v;
  mean = sum / static_cast<double>(n);
  const std::size_t per = n / kBatches;
  double ss = 0.0;
  for (int b = 0; b < kBatches; ++b) {
    double s = 0.0;
    for (std::size_t i = per * std::size_t(b); i < per * std::size_t(b + 1); ++i) s += values[i];
    const double d = s / static_cast<double>(per) - mean;
    ss += d * d;
  }
  sigma = std::sqrt(ss / (kBatches - 1) / kBatches);
}

}  // namespace

bool imu_white_noise(hal::ImuSource& imu, std::int64_t nominal_period_ns, ImuWhiteNoise& out) {
  // The last nine samples of a run of equally spaced ones: the fourth difference of the last five,
  // and of every other one of the nine (stride 2).
  std::array<ImuSample, 9> window{};
  int filled = 0;
  // Each difference's squared norm over 3 axes and the weights, per sample: the sample's
  // variance (per axis) on average.
  std::vector<double> gyro, accel;
  double stride2_g = 0.0, stride2_a = 0.0;
  std::uint64_t stride2_n = 0;
  ImuSample s;
  const std::int64_t slack = nominal_period_ns / 10;
  const auto difference = [&](int last, int stride, Eigen::Vector3d& g, Eigen::Vector3d& a) {
    g.setZero();
    a.setZero();
    for (int i = 0; i < 5; ++i) {
      const ImuSample& x = window[std::size_t(last - stride * (4 - i))];
      g += kWeights[std::size_t(i)] * x.gyro;
      a += kWeights[std::size_t(i)] * x.accel;
    }
  };
  while (imu.next(s) == hal::SourceStatus::kOk) {
    if (filled > 0 &&
        std::llabs(s.t_ns - window[std::size_t(filled - 1)].t_ns - nominal_period_ns) > slack)
      filled = 0;  // a gap or a jitter: start a new run
    if (filled == 9) {
      for (std::size_t i = 0; i + 1 < 9; ++i) window[i] = window[i + 1];
      filled = 8;
    }
    window[std::size_t(filled++)] = s;
    if (filled < 5) continue;
    Eigen::Vector3d g, a;
    difference(filled - 1, 1, g, a);
    gyro.push_back(g.squaredNorm() / (3.0 * kWeightSquares));
    accel.push_back(a.squaredNorm() / (3.0 * kWeightSquares));
    if (filled < 9) continue;
    difference(8, 2, g, a);
    stride2_g += g.squaredNorm() / (3.0 * kWeightSquares);
    stride2_a += a.squaredNorm() / (3.0 * kWeightSquares);
    ++stride2_n;
  }
  if (gyro.size() < 200 || stride2_n == 0) return false;
  const double dt = static_cast<double>(nominal_period_ns) * 1e-9;
  const auto density = [dt](const std::vector<double>& v, double& d, double& sigma) {
    double var = 0.0, var_sigma = 0.0;
    mean_and_sigma(v, var, var_sigma);
    d = std::sqrt(var * dt);                              // sigma_sample sqrt(dt)
    sigma = var > 0.0 ? 0.5 * d * var_sigma / var : 0.0;  // d(sqrt x) = dx / (2 sqrt x)
  };
  density(gyro, out.gyro_density, out.gyro_sigma);
  density(accel, out.accel_density, out.accel_sigma);
  const auto ratio = [&](double sum, double d) {
    return d > 0.0 ? std::sqrt(sum / double(stride2_n) * dt) / d : 0.0;
  };
  out.gyro_stride2_ratio = ratio(stride2_g, out.gyro_density);
  out.accel_stride2_ratio = ratio(stride2_a, out.accel_density);
  out.differences = gyro.size();
  return true;
}

bool ImuWhiteNoise::white(double stride2_ratio) {
  return std::abs(stride2_ratio - 1.0) <= kWhiteTolerance;
}

bool pixel_noise_estimate(double quadratic, double redundancy, double told_pixel_sigma,
                          double& estimate, double& sigma) {
  if (!(redundancy > 0.0) || !(quadratic >= 0.0) || !(told_pixel_sigma > 0.0)) return false;
  estimate = told_pixel_sigma * std::sqrt(quadratic / redundancy);
  sigma = estimate / std::sqrt(2.0 * redundancy);
  return true;
}

std::string estimated_imu_yaml(const NoiseEstimate& n) {
  io::SensorInfo sensors;
  sensors.imu = n.imu;
  sensors.imu_rate_hz = n.imu_rate_hz;
  sensors.imu_model = n.imu_model;  // the one it was estimated with, the ideal IMU's included
  sensors.imu_tolerances = n.imu_tolerances;
  sensors.imu_tolerances_defaulted = false;  // written out, the defaults included
  std::string y = io::imu_yaml_text(sensors);
  char note[512];
  std::snprintf(note, sizeof note,
                "# The noise densities estimated by mirrorcal's calibration from its own data "
                "(1-sigma: gyroscope %.3g, accelerometer %.3g; stated %.6g and %.6g); the random "
                "walks as stated, which a minute cannot measure.\n",
                n.gyro_density_sigma, n.accel_density_sigma, n.told.gyro_noise_density,
                n.told.accel_noise_density);
  return y + note;
}

bool add_estimated_imu_yaml(io::OutputSet& out, const std::string& path, const NoiseEstimate& n,
                            std::string& error) {
  std::FILE* f = out.add(path, error);
  if (f == nullptr) return false;
  const std::string text = estimated_imu_yaml(n);
  std::fwrite(text.data(), 1, text.size(), f);
  return true;
}

}  // namespace mirrorcal::calibration
