#include "mirrorcal/calibration/imu_noise.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "mirrorcal/io/recording.hpp"
#include "text_format.hpp"

namespace mirrorcal::calibration {

namespace {

// IEEE 952's ratio of the flat floor of the Allan deviation to the bias instability (flicker).
constexpr double kFlickerFloor = 0.664;
// A slope counts as the white noise's -1/2 within this.
constexpr double kWhiteSlopeTolerance = 0.1;
// After the floor, a slope above this is the random walk's +1/2 (nearer it than the floor's 0).
constexpr double kRandomWalkSlope = 0.2;
// The fewest points of a curve a line is fitted to: three at ten a decade span 0.2 decade.
constexpr std::size_t kMinRegionPoints = 3;
// A rise counts when it exceeds this many times its relative error.
constexpr double kRiseSigmas = 2.0;
// An upper bound holds at this many of each point's sigmas (the least of the curve's bounds is
// taken, so each must hold with room).
constexpr double kBoundSigmas = 3.0;
// How far the curve must reach past the lines' crossing tau_x for each figure to show: the
// random walk's slope above 1/4 needs tau > 3 tau_x, and three points with a rise past their
// error about 5 tau_x; the floor needs about 3 tau_x. The curve ends at a ninth of the recording.
constexpr double kRandomWalkSpan = 9.0 * 5.0;
constexpr double kFloorSpan = 9.0 * 3.0;
// The accelerometer norm's drift is judged on means over this long (s).
constexpr double kDriftWindowS = 10.0;
// Steps farther than this fraction from the median step are irregular (a dropped sample doubles
// one); up to kMaxIrregular of them (and of the time) are let through with a note.
constexpr double kStepTolerance = 0.5;
constexpr double kMaxIrregular = 0.01;

// A duration in the unit a person would say it in.
std::string duration(double s) {
  if (s < 120.0) return format("%.0f s", s);
  if (s < 2.0 * 3600.0) return format("%.0f min", s / 60.0);
  return format("%.1f h", s / 3600.0);
}

// The least-squares slope of log adev against log tau over points i-3..i+3 of the curve (0.6
// decade at ten a decade): narrower windows let the long cluster times' scatter decide.
double local_slope(const std::vector<double>& lt, const std::vector<double>& ls, std::size_t i) {
  const std::size_t lo = i >= 3 ? i - 3 : 0, hi = std::min(i + 4, lt.size());
  double mt = 0.0, ms = 0.0;
  for (std::size_t j = lo; j < hi; ++j) {
    mt += lt[j];
    ms += ls[j];
  }
  mt /= double(hi - lo);
  ms /= double(hi - lo);
  double sts = 0.0, stt = 0.0;
  for (std::size_t j = lo; j < hi; ++j) {
    sts += (lt[j] - mt) * (ls[j] - ms);
    stt += (lt[j] - mt) * (lt[j] - mt);
  }
  return stt > 0.0 ? sts / stt : 0.0;
}

// A line of fixed slope through the points of region: the weighted mean (weights 1/e^2) of
// log(value), where value(i) is the figure point i gives (<= 0: the point says nothing).
template <class Value>
double fit_line(const std::vector<std::size_t>& region, const std::vector<double>& e, Value value) {
  double sw = 0.0, sx = 0.0;
  for (std::size_t i : region) {
    const double v = value(i);
    if (!(v > 0.0)) continue;
    const double w = 1.0 / (e[i] * e[i]);
    sw += w;
    sx += w * std::log(v);
  }
  return sw > 0.0 ? std::exp(sx / sw) : 0.0;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
  return v[v.size() / 2];
}

}  // namespace

std::vector<std::size_t> allan_cluster_sizes(std::size_t n, int per_decade) {
  std::vector<std::size_t> m;
  const std::size_t last = std::max<std::size_t>(n / 9, 1);
  for (int k = 0;; ++k) {
    const auto size =
        static_cast<std::size_t>(std::llround(std::pow(10.0, k / double(per_decade))));
    if (size > last) break;
    if (m.empty() || size != m.back()) m.push_back(size);
  }
  return m;
}

std::vector<double> overlapping_allan_deviation(const std::vector<double>& y,
                                                const std::vector<std::size_t>& m) {
  const std::size_t n = y.size();
  std::vector<double> adev(m.size(), 0.0);
  if (n < 2) return adev;
  // Sums of the samples less their mean: they stay near zero, so that a cluster's mean, the
  // difference of two sums, keeps its digits however long the recording.
  double mean = 0.0;
  for (double v : y) mean += v;
  mean /= double(n);
  std::vector<double> sum(n + 1, 0.0);
  for (std::size_t i = 0; i < n; ++i) sum[i + 1] = sum[i] + (y[i] - mean);
  for (std::size_t k = 0; k < m.size(); ++k) {
    const std::size_t c = m[k];
    if (c < 1 || 2 * c > n) continue;
    // sigma^2(m) = 1 / (2 m^2 (n - 2m + 1)) sum_i (S[i+2m] - 2 S[i+m] + S[i])^2
    double s = 0.0;
    for (std::size_t i = 0; i + 2 * c <= n; ++i) {
      const double d = sum[i + 2 * c] - 2.0 * sum[i + c] + sum[i];
      s += d * d;
    }
    adev[k] = std::sqrt(s / (2.0 * double(c) * double(c) * double(n - 2 * c + 1)));
  }
  return adev;
}

double allan_relative_error(std::size_t n, std::size_t m) {
  const double clusters = double(n) / double(std::max<std::size_t>(m, 1));
  return clusters > 1.5 ? 1.0 / std::sqrt(2.0 * (clusters - 1.0)) : 1.0;
}

AxisNoise fit_allan_curve(const std::vector<std::size_t>& m, const std::vector<double>& adev,
                          std::size_t n, double dt_s) {
  AxisNoise a;
  const std::size_t k = std::min(m.size(), adev.size());
  if (k < kMinRegionPoints) return a;
  std::vector<double> tau(k), e(k), lt(k), ls(k), slope(k);
  for (std::size_t i = 0; i < k; ++i) {
    if (!(adev[i] > 0.0)) return a;  // a constant signal: no noise to read
    tau[i] = double(m[i]) * dt_s;
    e[i] = allan_relative_error(n, m[i]);
    lt[i] = std::log(tau[i]);
    ls[i] = std::log(adev[i]);
  }
  for (std::size_t i = 0; i < k; ++i) slope[i] = local_slope(lt, ls, i);
  const double duration_s = double(n) * dt_s;

  // White noise: the first run of points whose slope is -1/2.
  std::vector<std::size_t> white;
  for (std::size_t i = 0; i < k; ++i) {
    if (std::abs(slope[i] + 0.5) <= kWhiteSlopeTolerance) {
      white.push_back(i);
    } else if (white.size() >= kMinRegionPoints) {
      break;
    } else {
      white.clear();
    }
  }
  if (white.size() < kMinRegionPoints) white.clear();

  // The floor: the curve's minimum, resolved if the curve rises after it beyond its error.
  const std::size_t i_min =
      std::size_t(std::min_element(adev.begin(), adev.begin() + long(k)) - adev.begin());
  const double floor = adev[i_min];
  bool rises = false;
  for (std::size_t j = i_min + 1; j < k; ++j) rises |= adev[j] > floor * (1.0 + kRiseSigmas * e[j]);
  a.instability.value = floor / kFlickerFloor;
  a.instability.resolved = rises;
  a.instability.rel_sigma = e[i_min];
  a.instability.tau_lo_s = a.instability.tau_hi_s = tau[i_min];

  // The random walk: past the floor, where the slope approaches +1/2.
  std::vector<std::size_t> walk;
  bool walk_rises = false;
  for (std::size_t j = i_min + 1; j < k; ++j)
    if (slope[j] >= kRandomWalkSlope) {
      walk.push_back(j);
      walk_rises |= adev[j] > floor * (1.0 + kRiseSigmas * e[j]);
    }
  const bool walk_resolved = walk.size() >= kMinRegionPoints && walk_rises;

  // N, then K with N's share of the variance taken out, then N again with K's taken out.
  double N = 0.0, K = 0.0;
  const auto white_of = [&](double k_rw) {
    return fit_line(white, e, [&](std::size_t i) {
      return std::sqrt(std::max(adev[i] * adev[i] - k_rw * k_rw * tau[i] / 3.0, 0.0) * tau[i]);
    });
  };
  const auto walk_of = [&](double n_white) {
    return fit_line(walk, e, [&](std::size_t i) {
      return std::sqrt(std::max(adev[i] * adev[i] - n_white * n_white / tau[i], 0.0) * 3.0 /
                       tau[i]);
    });
  };
  if (!white.empty()) N = white_of(0.0);
  if (walk_resolved) {
    K = walk_of(N);
    // A walk line above the white region's points would leave no white noise: keep the first N.
    if (!white.empty() && white_of(K) > 0.0) N = white_of(K);
    K = walk_of(N);
  }
  if (!white.empty()) {
    a.white.value = N;
    a.white.resolved = true;
    a.white.rel_sigma = e[white.front()];  // its best point's: the points share their data
    a.white.tau_lo_s = tau[white.front()];
    a.white.tau_hi_s = tau[white.back()];
  }
  if (walk_resolved && K > 0.0) {
    a.random_walk.value = K;
    a.random_walk.resolved = true;
    // The error of the region's middle point: its first point's alone proved optimistic on
    // simulated walks (the region is chosen by its noisy slope, and the walk dominates late).
    a.random_walk.rel_sigma = e[walk[walk.size() / 2]];
    a.random_walk.tau_lo_s = tau[walk.front()];
    a.random_walk.tau_hi_s = tau[walk.back()];
  } else {
    // Every point bounds K: the random walk's share of its variance is at most all of it
    // (taken at three of its sigmas).
    double bound = std::numeric_limits<double>::infinity();
    std::size_t at = 0;
    for (std::size_t i = 0; i < k; ++i) {
      const double b = adev[i] * (1.0 + kBoundSigmas * e[i]) / std::sqrt(tau[i] / 3.0);
      if (b < bound) {
        bound = b;
        at = i;
      }
    }
    a.random_walk.value = bound;
    a.random_walk.tau_lo_s = a.random_walk.tau_hi_s = tau[at];
    // Where its line would cross the floor (or the white-noise line, if the curve still falls):
    // with K at most the bound, that is at the earliest.
    const double tau_x = rises ? 3.0 * (floor / bound) * (floor / bound)
                               : (N > 0.0 ? std::sqrt(3.0) * N / bound : 0.0);
    if (tau_x > 0.0) a.random_walk.needed_s = std::max(kRandomWalkSpan * tau_x, 2.0 * duration_s);
  }
  if (!rises) {
    // The curve still falls at its end: the floor lies below, after the white-noise line meets
    // the random walk's.
    const double k_line = a.random_walk.value;
    const double tau_x = N > 0.0 && k_line > 0.0 ? std::sqrt(3.0) * N / k_line : 0.0;
    if (tau_x > 0.0) a.instability.needed_s = std::max(kFloorSpan * tau_x, 2.0 * duration_s);
  }
  return a;
}

AxisNoise combine_axes(const std::array<AxisNoise, 3>& axes) {
  AxisNoise s;
  const auto combine = [&](NoiseFigure AxisNoise::*f) {
    NoiseFigure c;
    c.resolved = true;
    for (const AxisNoise& a : axes) c.resolved = c.resolved && (a.*f).resolved;
    c.tau_lo_s = std::numeric_limits<double>::infinity();
    double sum2 = 0.0, err2 = 0.0;
    for (const AxisNoise& a : axes) {
      const NoiseFigure& x = a.*f;
      // A bound of the root mean square takes every axis at its bound: the resolved ones at
      // three of their sigmas above.
      const double v =
          c.resolved || !x.resolved ? x.value : x.value * (1.0 + kBoundSigmas * x.rel_sigma);
      sum2 += v * v;
      err2 += (v * v * x.rel_sigma) * (v * v * x.rel_sigma);
      c.tau_lo_s = std::min(c.tau_lo_s, x.tau_lo_s);
      c.tau_hi_s = std::max(c.tau_hi_s, x.tau_hi_s);
      c.needed_s = std::max(c.needed_s, x.needed_s);
    }
    c.value = std::sqrt(sum2 / 3.0);
    // The root mean square's relative error: d sqrt(mean v^2) = sum v_i dv_i / (3 rms).
    c.rel_sigma = c.resolved && sum2 > 0.0 ? std::sqrt(err2) / sum2 : 0.0;
    return c;
  };
  s.white = combine(&AxisNoise::white);
  s.instability = combine(&AxisNoise::instability);
  s.random_walk = combine(&AxisNoise::random_walk);
  return s;
}

const char* imu_axis_name(int axis) {
  static const char* const names[kImuAxes] = {"gyro x",  "gyro y",  "gyro z",
                                              "accel x", "accel y", "accel z"};
  return axis >= 0 && axis < kImuAxes ? names[axis] : "?";
}

ImuNoise ImuNoiseAnalysis::noise() const {
  ImuNoise n;
  n.gyro_noise_density = gyro.white.value;
  n.gyro_random_walk = gyro.random_walk.value;
  n.accel_noise_density = accel.white.value;
  n.accel_random_walk = accel.random_walk.value;
  return n;
}

namespace {

// The timestamps: evenly spaced at an IMU's rate, with few gaps. The median step into step_ns.
bool check_timestamps(const std::vector<ImuSample>& s, const std::string& file, double& step_ns,
                      std::vector<std::string>& notes, std::string& error) {
  std::vector<double> steps(s.size() - 1);
  for (std::size_t i = 1; i < s.size(); ++i) steps[i - 1] = double(s[i].t_ns - s[i - 1].t_ns);
  step_ns = median(steps);
  const double rate = 1e9 / step_ns;
  if (!(rate >= io::kMinImuRateHz && rate <= io::kMaxImuRateHz)) {
    error = file + format(
                       ": the timestamps step by %.4g ns (median), %.4g Hz, which no IMU samples "
                       "at (%.0f..%.0f Hz): timestamps in another unit than nanoseconds?",
                       step_ns, rate, io::kMinImuRateHz, io::kMaxImuRateHz);
    return false;
  }
  std::size_t irregular = 0, first = 0;
  double missing_ns = 0.0;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    if (std::abs(steps[i] - step_ns) <= kStepTolerance * step_ns) continue;
    if (irregular++ == 0) first = i + 1;
    missing_ns += std::max(steps[i] - step_ns, 0.0);
  }
  if (irregular == 0) return true;
  const double span_ns = double(s.back().t_ns - s.front().t_ns);
  const std::string what = format(
      "%zu of %zu timestamp steps differ from the median step (%.0f ns) by more than half, the "
      "first at timestamp %lld (sample %zu); %.3g s are missing",
      irregular, steps.size(), step_ns, static_cast<long long>(s[first].t_ns), first + 1,
      missing_ns * 1e-9);
  if (double(irregular) > kMaxIrregular * double(steps.size()) ||
      missing_ns > kMaxIrregular * span_ns) {
    error = file + ": irregular timestamps: " + what +
            ". The Allan deviation needs evenly spaced samples: record again without dropping "
            "samples.";
    return false;
  }
  notes.push_back(file + ": " + what +
                  "; the Allan deviation takes the samples as evenly spaced, which so few "
                  "barely change.");
  return true;
}

// What the user is told when the data do not look like a still IMU.
std::string moves(const std::string& file, const std::string& why) {
  return file + ": the IMU moves: " + why +
         ". A noise recording must be still: the board on a steady table, untouched, for the "
         "whole recording.";
}

}  // namespace

bool analyse_imu_noise(const std::vector<ImuSample>& samples, const std::string& file,
                       ImuNoiseAnalysis& out, std::string& error) {
  out = ImuNoiseAnalysis{};
  out.file = file;
  out.samples = samples.size();
  if (samples.size() < 3) {
    error = file + format(
                       ": %zu IMU samples: far too short to say anything of the noise (record "
                       "at least %.0f s of a still IMU)",
                       samples.size(), kMinStillDurationS);
    return false;
  }
  double step_ns = 0.0;
  if (!check_timestamps(samples, file, step_ns, out.notes, error)) return false;
  const double dt = step_ns * 1e-9;
  const std::size_t n = samples.size();
  out.rate_hz = 1.0 / dt;
  out.duration_s = double(n) * dt;
  if (out.duration_s < kMinStillDurationS) {
    error = file + format(
                       ": only %.1f s of data (%zu samples at %.4g Hz): too short to say anything "
                       "of the noise. Record at least %.0f s of a still IMU (white noise), and "
                       "an hour or more for the bias random walk.",
                       out.duration_s, n, out.rate_hz, kMinStillDurationS);
    return false;
  }
  // Units, as calibrate checks them (a gyro in deg/s, an accelerometer in g).
  std::vector<double> norm(n);
  for (std::size_t i = 0; i < n; ++i) norm[i] = samples[i].gyro.norm();
  const double gyro_norm = median(norm);
  for (std::size_t i = 0; i < n; ++i) norm[i] = samples[i].accel.norm();
  const double accel_norm = median(norm);
  if (gyro_norm > 35.0) {
    error = file + format(
                       ": the gyro's median rate is %.3g rad/s, beyond any part's range "
                       "(35 rad/s): deg/s given for rad/s?",
                       gyro_norm);
    return false;
  }
  if (accel_norm > 0.5 && accel_norm < 2.0) {
    error = file + format(
                       ": the accelerometer's median magnitude is %.3g m/s^2, where gravity "
                       "alone gives 9.81: g given for m/s^2?",
                       accel_norm);
    return false;
  }
  if (!(accel_norm > 7.0 && accel_norm < 13.0)) {
    error = file + format(
                       ": the accelerometer's median magnitude is %.3g m/s^2; a still one reads "
                       "gravity, 9.81 m/s^2: not a still IMU, or not m/s^2",
                       accel_norm);
    return false;
  }

  out.m = allan_cluster_sizes(n);
  out.tau_s.resize(out.m.size());
  for (std::size_t k = 0; k < out.m.size(); ++k) out.tau_s[k] = double(out.m[k]) * dt;
  std::vector<double> y(n);
  for (int axis = 0; axis < kImuAxes; ++axis) {
    for (std::size_t i = 0; i < n; ++i)
      y[i] = axis < 3 ? samples[i].gyro(axis) : samples[i].accel(axis - 3);
    const auto [lo, hi] = std::minmax_element(y.begin(), y.end());
    if (*lo == *hi) {
      error = file + ": " + imu_axis_name(axis) +
              format(" reads %.6g throughout: no noise to measure (a sensor that does not sample?)",
                     *lo);
      return false;
    }
    out.adev[std::size_t(axis)] = overlapping_allan_deviation(y, out.m);
    out.axes[std::size_t(axis)] = fit_allan_curve(out.m, out.adev[std::size_t(axis)], n, dt);
  }

  // Still: a gyro axis and the specific force's norm are white noise about a slowly wandering
  // bias. At tau = 1 s that bias moves far less than the white noise for any MEMS part, while a
  // turn or a push puts the curve many times above its white-noise line.
  std::size_t at_1s = 0;
  for (std::size_t k = 1; k < out.tau_s.size(); ++k)
    if (std::abs(std::log(out.tau_s[k])) < std::abs(std::log(out.tau_s[at_1s]))) at_1s = k;
  const double tau_1s = out.tau_s[at_1s];
  const auto still = [&](const std::string& what, const AxisNoise& a, double adev_1s,
                         const char* unit) {
    if (!a.white.resolved) {
      error = moves(file, what +
                              " shows no white noise at any cluster time (its Allan deviation "
                              "never falls as 1/sqrt(tau)); or its data are filtered or coarsely "
                              "quantized, not raw samples");
      return false;
    }
    const double white = a.white.value / std::sqrt(tau_1s);
    const double ratio = adev_1s / white;
    out.motion_ratio = std::max(out.motion_ratio, ratio);
    if (ratio <= kMotionRatio) return true;
    error =
        moves(file, what + format(" varies %.3g %s over %.3g s, %.1f times what its white noise "
                                  "gives (%.3g %s; a still one stays within %.0f times)",
                                  adev_1s, unit, tau_1s, ratio, white, unit, kMotionRatio));
    return false;
  };
  for (int axis = 0; axis < 3; ++axis)
    if (!still(imu_axis_name(axis), out.axes[std::size_t(axis)], out.adev[std::size_t(axis)][at_1s],
               "rad/s"))
      return false;
  for (std::size_t i = 0; i < n; ++i) norm[i] = samples[i].accel.norm();
  const std::vector<double> norm_adev = overlapping_allan_deviation(norm, out.m);
  if (!still("the specific force's norm", fit_allan_curve(out.m, norm_adev, n, dt),
             norm_adev[at_1s], "m/s^2"))
    return false;
  // The norm's drift: its means over 10 s stay near their median, bias drift being small.
  const auto window = std::max<std::size_t>(std::size_t(std::llround(kDriftWindowS / dt)), 1);
  std::vector<double> means;
  for (std::size_t i = 0; i + window <= n; i += window) {
    double s = 0.0;
    for (std::size_t j = i; j < i + window; ++j) s += norm[j];
    means.push_back(s / double(window));
  }
  const double middle = median(means);
  for (std::size_t w = 0; w < means.size(); ++w)
    if (std::abs(means[w] - middle) > kMaxNormDrift) {
      error = moves(
          file, format("the specific force's norm, over the %.0f s from %.1f s on, is "
                       "%.3f m/s^2 against its median %.3f m/s^2 (a still IMU stays "
                       "within %.1f m/s^2): it was carried or accelerated",
                       kDriftWindowS, double(w * window) * dt, means[w], middle, kMaxNormDrift));
      return false;
    }

  out.gyro = combine_axes({out.axes[0], out.axes[1], out.axes[2]});
  out.accel = combine_axes({out.axes[3], out.axes[4], out.axes[5]});
  return true;
}

namespace {

std::string figure_cell(const NoiseFigure& f) {
  if (!f.resolved) return format("<%.3e", f.value);
  return format("%.3e +-%.2g %%", f.value, 100.0 * f.rel_sigma);
}

// What a figure's uncertainty means and what it takes to resolve it, in a sentence.
std::string advice(const char* sensor, const char* figure, const NoiseFigure& f, const char* unit,
                   double duration_s, const char* what_it_takes) {
  std::string s = format("  %s %s: ", sensor, figure);
  if (f.resolved) {
    s += format("%.3g %s +-%.2g %%", f.value, unit, 100.0 * f.rel_sigma);
    if (f.rel_sigma > 0.1)
      s += format("; recording %.0f times as long (%s) would bring it to +-10 %%",
                  std::ceil(f.rel_sigma * f.rel_sigma / 0.01),
                  duration(duration_s * std::ceil(f.rel_sigma * f.rel_sigma / 0.01)).c_str());
    else
      s += ": meaningful";
    return s + ".\n";
  }
  s += format("not resolved in %s; at most %.3g %s. ", duration(duration_s).c_str(), f.value, unit);
  s += what_it_takes;
  if (f.needed_s > 0.0)
    s += format(": record at least %s still (longer if the figure is smaller).",
                duration(f.needed_s).c_str());
  else
    s += ".";
  return s + "\n";
}

}  // namespace

std::string imu_noise_summary(const ImuNoiseAnalysis& a) {
  std::string s = format(
      "mirrorcal imu-noise: %s: %zu samples at %.5g Hz, %s of still data (Allan deviation from "
      "tau %.3g s to %.4g s, a ninth of it)\n\n",
      a.file.c_str(), a.samples, a.rate_hz, duration(a.duration_s).c_str(),
      a.tau_s.empty() ? 0.0 : a.tau_s.front(), a.tau_s.empty() ? 0.0 : a.tau_s.back());
  s += format("  %-14s %-21s %-21s %s\n", "", "noise density N", "bias instability B",
              "random walk K");
  const auto row = [&](const char* name, const AxisNoise& x) {
    s += format("  %-14s %-21s %-21s %s\n", name, figure_cell(x.white).c_str(),
                figure_cell(x.instability).c_str(), figure_cell(x.random_walk).c_str());
  };
  for (int axis = 0; axis < kImuAxes; ++axis) {
    row(imu_axis_name(axis), a.axes[std::size_t(axis)]);
    if (axis == 2) {
      row("gyroscope", a.gyro);
      s += "  (N rad/s/sqrt(Hz), B rad/s, K rad/s^2/sqrt(Hz))\n";
    }
  }
  row("accelerometer", a.accel);
  s += "  (N m/s^2/sqrt(Hz), B m/s^2, K m/s^3/sqrt(Hz))\n";
  s += "  +-: the statistical 1-sigma, from the number of independent clusters; <: an upper "
       "bound, the curve never showing that slope\n\n";
  s += "What the recording says, and how long it takes:\n";
  const char* rw_takes =
      "The curve has not turned upward (slope +1/2); with K below the bound it turns only later";
  const char* floor_takes =
      "The curve still falls at its end, so its floor lies at longer cluster times";
  for (int sensor = 0; sensor < 2; ++sensor) {
    const AxisNoise& x = sensor == 0 ? a.gyro : a.accel;
    const char* name = sensor == 0 ? "gyroscope" : "accelerometer";
    s += advice(name, "noise density", x.white, sensor == 0 ? "rad/s/sqrt(Hz)" : "m/s^2/sqrt(Hz)",
                a.duration_s, "");
    s += advice(name, "random walk", x.random_walk,
                sensor == 0 ? "rad/s^2/sqrt(Hz)" : "m/s^3/sqrt(Hz)", a.duration_s, rw_takes);
    s += advice(name, "bias instability", x.instability, sensor == 0 ? "rad/s" : "m/s^2",
                a.duration_s, floor_takes);
  }
  s += "  White noise is meaningful after minutes; the random walk needs the curve to turn "
       "upward, for MEMS parts typically an hour or more.\n";
  for (const std::string& note : a.notes) s += "note: " + note + "\n";
  return s;
}

std::string allan_csv(const ImuNoiseAnalysis& a) {
  std::string s =
      "#tau [s],gyro_x [rad s^-1],gyro_y [rad s^-1],gyro_z [rad s^-1],accel_x [m s^-2],"
      "accel_y [m s^-2],accel_z [m s^-2]\n";
  for (std::size_t k = 0; k < a.tau_s.size(); ++k) {
    s += format("%.9g", a.tau_s[k]);
    for (const auto& curve : a.adev) s += format(",%.9g", curve[k]);
    s += "\n";
  }
  return s;
}

}  // namespace mirrorcal::calibration
