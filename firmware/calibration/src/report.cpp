#include "mirrorcal/calibration/report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/estimator/so3.hpp"
#include "mirrorcal/io/version.hpp"
#include "text_format.hpp"

namespace mirrorcal::calibration {

namespace {

constexpr double kDeg = 180.0 / M_PI;

// A Euclidean calibration state's value (j in calibration_params() order; the rotation's are 0).
template <class State>
double euclidean_value(const State& x, int j) {
  constexpr CalibrationLayout kLayout = State::kCalibration;
  const CalibrationGroup group = kLayout.group_of(j);
  const int i = j - kLayout[group].begin;  // within its group
  switch (group) {
    case CalibrationGroup::kCameraPosition:
      return x.p_b_c(i);
    case CalibrationGroup::kCameraRotation:
      return 0.0;
    case CalibrationGroup::kMarkers:
      return x.markers(i);
    case CalibrationGroup::kTimeOffset:
      return x.t_d;
    case CalibrationGroup::kIntrinsics:
    case CalibrationGroup::kLens:  // after the intrinsics
      break;
  }
  return x.intrinsics(j - kLayout[CalibrationGroup::kIntrinsics].begin);
}

}  // namespace

template <int M, int NK, int NI>
ReportData report_data(const CalibrationRun<M, NK, NI>& run, const std::string& title) {
  using State = typename CalibrationRun<M, NK, NI>::State;
  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  ReportData d = report_data_without_history(run.result, title);
  d.pixel_sigma = run.pixel_sigma;
  d.prior_sigma = run.prior_sigma;
  d.has_truth = run.has_truth;
  d.loop = run.loop_counters;
  d.imu_residuals = run.imu_residuals;
  if (run.history.empty()) return d;
  d.final_nees = run.history.back().nees;
  d.settled_from_s =
      double(
          run.history[std::min<std::size_t>(run.gate_after_frames, run.history.size() - 1)].t_ns) *
      1e-9;
  static_assert(L <= kMaxReportStates, "a report row holds every calibration state");
  const std::vector<ParamInfo>& params = run.result.params;
  const State last = run.history.back().state;
  const Eigen::Quaterniond q0 = run.history.front().state.q_n_b;
  for (std::size_t k = 0; k < run.history.size(); ++k) {
    const HistoryRow<typename CalibrationRun<M, NK, NI>::Filter> row = run.history[k];
    ReportRow out;
    out.t_s = double(row.t_ns) * 1e-9;
    const Eigen::Matrix<double, L, 1> from_last = row.state.template boxminus_block<B, L>(last);
    for (int j = 0; j < L && std::size_t(j) < params.size(); ++j) {
      const bool rotation = State::kCalibration.group_of(j) == CalibrationGroup::kCameraRotation;
      const double value = rotation ? from_last(j) : euclidean_value(row.state, j);
      out.estimate[std::size_t(j)] = value * params[std::size_t(j)].scale;
      out.sigma[std::size_t(j)] = row.sigma(j) * params[std::size_t(j)].scale;
    }
    out.accel_bias = row.state.b_a;
    out.gyro_bias = row.state.b_g;
    out.rotation = so3::boxminus<double>(row.state.q_n_b, q0);
    out.normal_position = row.state.p.z();
    out.normal_velocity = row.state.v.z();
    const bool final_row = k + 1 == run.history.size();
    out.markers_seen = final_row ? -1 : row.markers_seen;
    out.nis = row.nis;
    out.nis_dof = row.nis_dof;
    d.rows.push_back(out);
    for (int m = 0; m < State::kMarkers; ++m)
      if (row.residual_valid[std::size_t(m)] && !row.withheld[std::size_t(m)])
        d.residuals.push_back({out.t_s, m, row.residual[std::size_t(m)].x(),
                               row.residual[std::size_t(m)].y(), k >= run.gate_after_frames});
  }
  return d;
}

#define MIRRORCAL_REPORT_DATA_(M, NK, NI) \
  template ReportData report_data<M, NK, NI>(const CalibrationRun<M, NK, NI>&, const std::string&);
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_REPORT_DATA_)
#undef MIRRORCAL_REPORT_DATA_

ReportData report_data_without_history(const CalibrationResult& r, const std::string& title) {
  ReportData d;
  d.title = title;
  d.result = r;
  return d;
}

double kth_smallest(const Sample& sample, std::size_t k) {
  // Bins a pass counts into, and the values left in play that are sorted in memory instead.
  constexpr std::size_t kBins = 4096, kBatch = 65536;
  // Each level narrows the values in play to one bin of the level before.
  struct Level {
    double lo = 0.0, span = 1.0;
    std::size_t bin = 0;
    std::size_t of(double x) const {
      const double b = std::floor((x - lo) / span * double(kBins));
      return b > 0.0 ? std::min(kBins - 1, std::size_t(b)) : 0;  // the greatest in the last
    }
  };
  std::vector<Level> levels;
  const auto in_play = [&levels](double x) {
    for (const Level& l : levels)
      if (l.of(x) != l.bin) return false;
    return true;
  };
  double lo = INFINITY, hi = -INFINITY;
  std::size_t n = 0;
  sample([&](double x) {
    lo = std::min(lo, x);
    hi = std::max(hi, x);
    ++n;
  });
  std::vector<std::size_t> count(kBins);
  std::vector<double> least(kBins), greatest(kBins);
  // Every level leaves fewer values in play: the least falls in the first bin, the greatest in
  // the last. Values too far apart to bin (an infinite span) and a pass that narrows nothing end
  // the narrowing: what is in play is then sorted in memory, larger than a batch, but it ends.
  while (lo < hi && n > kBatch && std::isfinite(hi - lo)) {
    const Level level{lo, hi - lo, 0};
    std::fill(count.begin(), count.end(), 0);
    std::fill(least.begin(), least.end(), INFINITY);
    std::fill(greatest.begin(), greatest.end(), -INFINITY);
    sample([&](double x) {
      if (!in_play(x)) return;
      const std::size_t b = level.of(x);
      ++count[b];
      least[b] = std::min(least[b], x);
      greatest[b] = std::max(greatest[b], x);
    });
    std::size_t b = 0;
    for (; k >= count[b]; ++b) k -= count[b];
    if (count[b] == n) break;
    levels.push_back({lo, hi - lo, b});
    n = count[b];
    lo = least[b];
    hi = greatest[b];
  }
  if (!(lo < hi)) return lo;  // every value in play is the same
  std::vector<double> batch;
  batch.reserve(n);
  sample([&](double x) {
    if (in_play(x)) batch.push_back(x);
  });
  std::nth_element(batch.begin(), batch.begin() + std::ptrdiff_t(k), batch.end());
  return batch[k];
}

SampleStats sample_stats(const Sample& sample) {
  SampleStats s;
  double sum = 0.0, max = -INFINITY;
  sample([&](double v) {
    ++s.n;
    sum += v;
    max = std::max(max, v);
  });
  if (s.n == 0) return s;
  s.max = max;
  s.mean = sum / double(s.n);
  double squares = 0.0;
  sample([&](double v) { squares += (v - s.mean) * (v - s.mean); });
  s.std = std::sqrt(squares / double(s.n));
  s.median = s.n % 2 == 1
                 ? kth_smallest(sample, s.n / 2)
                 : 0.5 * (kth_smallest(sample, s.n / 2 - 1) + kth_smallest(sample, s.n / 2));
  return s;
}

SampleStats sample_stats(const std::vector<double>& values) {
  return sample_stats([&values](const std::function<void(double)>& f) {
    for (double v : values) f(v);
  });
}

void for_each_imu_residual(const ReportData& d, int sensor, int axis,
                           const std::function<void(double, double)>& f) {
  if (!d.imu_residuals) return;
  const ImuNoise& noise = d.result.imu.noise;
  const double density = sensor == 0 ? noise.gyro_noise_density : noise.accel_noise_density;
  for (const ImuResidual r : *d.imu_residuals) {
    if (!(r.dt_s > 0.0)) continue;  // across a restart
    const double value = sensor == 0 ? r.gyro(axis) : r.accel(axis);
    f(value, value * std::sqrt(r.dt_s) / density);
  }
}

void for_each_nis_window(const ReportData& d, const std::function<void(const NisWindow&)>& f) {
  NisWindow w;
  int frames = 0;
  double first_t = 0.0, last_t = 0.0;
  const auto close = [&] {
    w.t_s = 0.5 * (first_t + last_t);
    f(w);
    w = NisWindow{};
    frames = 0;
  };
  for (const ReportRow row : d.rows) {
    if (row.nis_dof <= 0) continue;
    if (frames == 0) first_t = row.t_s;
    last_t = row.t_s;
    w.nis += row.nis;
    w.dof += row.nis_dof;
    if (++frames == kNisWindowFrames) close();
  }
  if (frames > 0) close();
}

namespace {

int marker_count(const ReportData& d) {
  return static_cast<int>(d.result.markers.size());
}

// The residual's length |(du, dv)| of each settled sample of marker m (all markers: m < 0; with
// the samples before the estimate settled: all_frames).
Sample residual_lengths(const ReportData& d, int m, bool all_frames = false) {
  return [&d, m, all_frames](const std::function<void(double)>& f) {
    for (const ResidualSample r : d.residuals)
      if ((m < 0 || r.marker == m) && (r.settled || all_frames)) {
        const double length = std::hypot(r.du, r.dv);
        if (std::isfinite(length)) f(length);  // the statistics' samples are numbers
      }
  };
}

// The largest |value| of a sample (0 when it is empty).
double largest_magnitude(const Sample& sample) {
  double m = 0.0;
  sample([&m](double v) { m = std::max(m, std::abs(v)); });
  return m;
}

// Each settled residual's u (axis 0) or v (axis 1) coordinate, px.
Sample residual_axis(const ReportData& d, int axis) {
  return [&d, axis](const std::function<void(double)>& f) {
    for (const ResidualSample r : d.residuals) {
      const double x = axis == 0 ? r.du : r.dv;
      if (r.settled && std::isfinite(x)) f(x);
    }
  };
}

// The acceleration along the mirror's normal, from the velocity estimates about 0.1 s apart.
Sample normal_acceleration(const ReportData& d) {
  return [&d](const std::function<void(double)>& f) {
    ReportRow from = d.rows.front();
    for (std::size_t j = 1; j < d.rows.size(); ++j) {
      const ReportRow to = d.rows[j];
      const double dt = to.t_s - from.t_s;
      if (dt < 0.1) continue;
      f((to.normal_velocity - from.normal_velocity) / dt);
      from = to;
    }
  };
}

std::string verdict_line(const CalibrationResult& r) {
  return consistent(r) ? "VERDICT: consistent -- the self-check found no reason to doubt this "
                         "calibration: use it."
                       : "VERDICT: NOT consistent -- do not trust this calibration (reasons "
                         "below).";
}

void add_verdict(std::string& t, const ReportData& d) {
  const CalibrationResult& r = d.result;
  t += verdict_line(r) + "\n";
  for (const std::string& w : result_warnings(r)) t += "  WARNING: " + w + "\n";
  for (const std::string& w : d.input_warnings) t += "  WARNING (the input): " + w + "\n";
  t += format(
      "  self-check: %d pass(es); normalised innovation squared per dof %.3f over %llu dof (about "
      "1: the markers fit as the covariance says); sigma_ratio %.3f (at least %.1f); last "
      "refinement step %.2f sigmas (at most %.0f); markers used %llu, gated %llu, not "
      "predictable %llu",
      r.passes, r.nis_per_dof, static_cast<unsigned long long>(r.nis_dof), r.sigma_ratio,
      kSigmaRatioLimit, r.refinement_step_sigmas, kRefinementStepLimit,
      static_cast<unsigned long long>(r.markers_used),
      static_cast<unsigned long long>(r.markers_gated),
      static_cast<unsigned long long>(r.markers_invalid));
  if (r.markers_observed > 0)
    t += format(" of %llu observed", static_cast<unsigned long long>(r.markers_observed));
  if (!r.prior_offset_state.empty())
    t += format("; furthest from its prior guess: %s, %.2f prior sigmas",
                r.prior_offset_state.c_str(), r.prior_offset_sigmas);
  t += "\n\n";
}

// The noise levels estimated from the data (Passes::estimate_noise), against those stated.
void add_noise(std::string& t, const ReportData& d) {
  const NoiseEstimate& n = d.result.noise;
  if (!n.estimated) return;
  t += "NOISE (estimated from the data and used; the stated levels beside them)\n";
  const auto row = [&t](const char* name, double est, double sigma, double told, const char* unit) {
    t += format("  %-28s %11.4g +- %-9.2g %s  (stated %.4g: %.2f times the estimate)\n", name, est,
                sigma, unit, told, est > 0.0 ? told / est : 0.0);
  };
  const auto kept = [&t](const char* name, double told, double ratio, const char* unit) {
    t += format(
        "  %-28s %11.4g %s as stated: NOT estimated, the samples' noise is not white from sample "
        "to sample (it reads %.2f times more over every other sample, "
        "white noise 1: a low-pass filter in the part?); measure it with imu-noise\n",
        name, told, unit, ratio);
  };
  if (n.gyro_estimated)
    row("gyroscope_noise_density", n.imu.gyro_noise_density, n.gyro_density_sigma,
        n.told.gyro_noise_density, "rad/s/sqrt(Hz)");
  else
    kept("gyroscope_noise_density", n.imu.gyro_noise_density, n.gyro_stride2_ratio,
         "rad/s/sqrt(Hz)");
  if (n.accel_estimated)
    row("accelerometer_noise_density", n.imu.accel_noise_density, n.accel_density_sigma,
        n.told.accel_noise_density, "m/s^2/sqrt(Hz)");
  else
    kept("accelerometer_noise_density", n.imu.accel_noise_density, n.accel_stride2_ratio,
         "m/s^2/sqrt(Hz)");
  row("pixel_sigma", n.pixel_sigma, n.pixel_sigma_sigma, n.told_pixel_sigma, "px");
  t += format(
      "  the densities from %llu fourth differences of the IMU's samples, the pixel noise from "
      "the refinement's last pass (%.0f dof); %d calibration(s) with the estimates, %s; the "
      "random walks as stated (60 s hardly see them); imu.yaml beside this report has the "
      "estimated densities\n\n",
      static_cast<unsigned long long>(n.imu_differences), n.pixel_redundancy, n.refinements,
      n.converged ? "converged" : "NOT converged");
}

void add_calibration(std::string& t, const ReportData& d) {
  const CalibrationResult& r = d.result;
  const Eigen::Matrix3d r_c_b = r.q_b_c.toRotationMatrix().transpose();
  const Eigen::Vector3d p_c_b = -r_c_b * r.p_b_c;
  t += "CALIBRATION (SI; mirrorcal-result.yaml holds it in full precision)\n";
  t += "T_cam_imu (maps IMU coordinates into the camera's):\n";
  for (int i = 0; i < 3; ++i)
    t += format("  [%12.9f, %12.9f, %12.9f, %12.9f]\n", r_c_b(i, 0), r_c_b(i, 1), r_c_b(i, 2),
                p_c_b(i));
  t += "  [ 0.000000000,  0.000000000,  0.000000000,  1.000000000]\n";
  const Eigen::Vector3d angles = display_angles(r.q_b_c);
  t += format("R_b_c as Rz(c) Ry(b) Rx(a): a %.4f, b %.4f, c %.4f deg\n", angles(0), angles(1),
              angles(2));
  t += format("\n%-17s %-5s %14s %12s %12s %12s\n", "state", "unit", "estimate", "1-sigma",
              "prior sigma", "sigma/prior");
  const CalibrationLayout layout = r.layout();
  for (std::size_t j = 0; j < r.params.size(); ++j) {
    const ParamInfo& p = r.params[j];
    const int i = int(j) - layout[p.group].begin;  // within its group
    double value = 0.0;
    if (p.group == CalibrationGroup::kCameraPosition)
      value = r.p_b_c(i) * p.scale;
    else if (p.group == CalibrationGroup::kCameraRotation)
      value = angles(i);
    else if (p.group == CalibrationGroup::kMarkers)
      value = r.markers[std::size_t(i / 3)](i % 3) * p.scale;
    else if (p.group == CalibrationGroup::kTimeOffset)
      value = r.t_d * p.scale;
    else  // the intrinsics, and the lens's coefficients after them
      value = estimated_camera_parameter(r, int(j) - layout[CalibrationGroup::kIntrinsics].begin) *
              p.scale;
    t += format("%-17s %-5s %14.4f %12.4f", p.name.c_str(), p.unit.c_str(), value,
                r.sigma[j] * p.scale);
    if (j < d.prior_sigma.size())
      t += format(" %12.4f %12.3f", d.prior_sigma[j] * p.scale, r.sigma[j] / d.prior_sigma[j]);
    t += "\n";
  }
  t +=
      "(rotations: the angles a, b, c; their sigma is of the rotation error vector's components)\n";
  if (d.has_truth && !d.rows.empty())
    t += format(
        "NEES of the %zu calibration states against the truth: %.2f (95 %% interval "
        "%.2f..%.2f)\n",
        r.params.size(), d.final_nees, chi2_quantile(0.025, double(r.params.size())),
        chi2_quantile(0.975, double(r.params.size())));
  t += "\n";
}

// The IMU's intrinsics, each with its sigma against the prior's: one the motion left near its
// prior is weak (kept near the prior's guess; what the data did not see).
void add_imu(std::string& t, const ReportData& d) {
  const ImuResult& imu = d.result.imu;
  t += format("IMU (model %s", to_string(imu.model));
  if (!imu.estimated()) {
    t += ": an ideal IMU assumed, its scale factors and axes taken as exact)\n\n";
    return;
  }
  t += "; its frame is the accelerometer's; measured = T true + bias)\n";
  t += format("%-19s %14s %12s %12s %12s\n", "intrinsic (T)", "estimate", "1-sigma", "prior sigma",
              "sigma/prior");
  const std::vector<std::string> names = imu_intrinsic_names(imu.model);
  const std::vector<double> values = imu_intrinsic_values(imu);
  int weak = 0;
  for (std::size_t j = 0; j < names.size() && j < imu.sigma.size(); ++j) {
    const double prior = j < imu.prior_sigma.size() ? imu.prior_sigma[j] : 0.0;
    const double ratio = prior > 0.0 ? imu.sigma[j] / prior : 0.0;
    const bool is_weak = ratio > kWeakImuIntrinsic;
    weak += is_weak ? 1 : 0;
    t += format("%-19s %14.6f %12.6f %12.6f %12.3f%s\n", names[j].c_str(), values[j], imu.sigma[j],
                prior, ratio, is_weak ? "  weak" : "");
  }
  t += "(scale factors as T(i, i) - 1; the axes' angles in rad; kalibr_imu_chain.yaml has them as "
       "OpenVINS reads them)\n";
  if (weak > 0)
    t += format(
        "%d of %zu intrinsics weak (sigma above %.0f %% of the prior's): the motion did not "
        "excite them and they stay near the prior's guess\n",
        weak, names.size(), 100.0 * kWeakImuIntrinsic);
  t += "\n";
}

void add_residual_row(std::string& t, const char* label, const SampleStats& s, double sigma) {
  t += format("%-10s %8zu %9.3f %9.3f %9.3f %9.3f   %9.3f %9.3f %9.3f %9.3f\n", label, s.n, s.mean,
              s.median, s.std, s.max, s.mean / sigma, s.median / sigma, s.std / sigma,
              s.max / sigma);
}

void add_residuals(std::string& t, const ReportData& d) {
  double first_settled_s = 0.0, squares = 0.0;
  std::size_t settled = 0;
  for (const ResidualSample r : d.residuals) {
    if (!r.settled) continue;
    if (settled++ == 0) first_settled_s = r.t_s;
    squares += r.du * r.du + r.dv * r.dv;
  }
  t += format(
      "REPROJECTION RESIDUALS (|measured - predicted| of each marker in each frame of the final "
      "pass, at the estimate after that frame's update; from %.2f s, once the estimate settled "
      "and the gate is on; gated markers included; pixel sigma %.3f px; residuals.csv lists "
      "them all)\n",
      first_settled_s, d.pixel_sigma);
  t += format("%-10s %8s %9s %9s %9s %9s   %9s %9s %9s %9s\n", "marker", "n", "mean px", "median",
              "std", "max", "mean sig", "median", "std", "max");
  for (int m = 0; m < marker_count(d); ++m)
    add_residual_row(t, format("f%d", m + 1).c_str(), sample_stats(residual_lengths(d, m)),
                     d.pixel_sigma);
  add_residual_row(t, "all", sample_stats(residual_lengths(d, -1)), d.pixel_sigma);
  add_residual_row(t, "+settling", sample_stats(residual_lengths(d, -1, true)), d.pixel_sigma);
  const double rms = settled == 0 ? 0.0 : std::sqrt(squares / (2.0 * double(settled)));
  t += format(
      "RMS per coordinate: %.4f px = %.4f sigma (about 1 when the pixel sigma is right: a 2-D "
      "normal residual's length has median 1.18 sigma; '+settling' adds the first frames)\n",
      rms, rms / d.pixel_sigma);
  const Sample u_values = residual_axis(d, 0), v_values = residual_axis(d, 1);
  const SampleStats u = sample_stats(u_values), v = sample_stats(v_values);
  t += format(
      "per axis [px]: u mean %+.4f std %.4f max |u| %.3f, v mean %+.4f std %.4f max |v| %.3f (a "
      "mean off zero by more than a few std/sqrt(n) is a bias the model does not hold)\n\n",
      u.mean, u.std, largest_magnitude(u_values), v.mean, v.std, largest_magnitude(v_values));
}

void add_nis(std::string& t, const ReportData& d) {
  double nis = 0.0;
  long dof = 0;
  int outside = 0;
  std::size_t windows = 0;
  for_each_nis_window(d, [&](const NisWindow& w) {
    ++windows;
    nis += w.nis;
    dof += w.dof;
    if (w.nis < chi2_quantile(0.025, w.dof) || w.nis > chi2_quantile(0.975, w.dof)) ++outside;
  });
  t += "NORMALISED INNOVATION SQUARED (markers used once the gate is on, final pass)\n";
  if (dof == 0) {
    t += "none: no frame was used with the gate on\n\n";
    return;
  }
  t += format(
      "per dof %.4f over %ld dof (95 %% band %.4f..%.4f); windows of %d frames outside their 95 "
      "%% band: %d of %zu (about 5 %% for a consistent filter)\n\n",
      nis / double(dof), dof, chi2_quantile(0.025, double(dof)) / double(dof),
      chi2_quantile(0.975, double(dof)) / double(dof), kNisWindowFrames, outside, windows);
}

// One sensor's line of the IMU residuals (for_each_imu_residual's sensor): the statistics of the
// residual's length, and each axis's mean and RMS, in the sensor's units and in white-noise sigmas.
void add_imu_residual_line(std::string& t, const ReportData& d, int sensor) {
  std::array<double, 3> mean{}, rms{}, mean_sigmas{}, rms_sigmas{};
  std::size_t n = 0;
  for (int axis = 0; axis < 3; ++axis)
    for_each_imu_residual(d, sensor, axis, [&](double value, double sigmas) {
      n += axis == 0 ? 1 : 0;
      mean[std::size_t(axis)] += value;
      rms[std::size_t(axis)] += value * value;
      mean_sigmas[std::size_t(axis)] += sigmas;
      rms_sigmas[std::size_t(axis)] += sigmas * sigmas;
    });
  const double count = std::max<double>(double(n), 1.0);
  for (std::size_t axis = 0; axis < 3; ++axis) {
    mean[axis] /= count;
    rms[axis] = std::sqrt(rms[axis] / count);
    mean_sigmas[axis] /= count;
    rms_sigmas[axis] = std::sqrt(rms_sigmas[axis] / count);
  }
  const SampleStats length = sample_stats([&](const std::function<void(double)>& f) {
    if (!d.imu_residuals) return;
    for (const ImuResidual r : *d.imu_residuals)
      if (r.dt_s > 0.0) f(sensor == 0 ? r.gyro.norm() : r.accel.norm());
  });
  t += format("%s |r| mean %.3g, median %.3g, std %.3g, max %.3g\n",
              sensor == 0 ? "gyro residual [rad/s]:         " : "accelerometer residual [m/s^2]:",
              length.mean, length.median, length.std, length.max);
  t += format(
      "  per axis x y z: mean %+.3g %+.3g %+.3g, RMS %.3g %.3g %.3g; in white-noise sigmas: mean "
      "%+.3f %+.3f %+.3f, RMS %.3f %.3f %.3f\n",
      mean[0], mean[1], mean[2], rms[0], rms[1], rms[2], mean_sigmas[0], mean_sigmas[1],
      mean_sigmas[2], rms_sigmas[0], rms_sigmas[1], rms_sigmas[2]);
}

void add_imu_residuals(std::string& t, const ReportData& d) {
  std::vector<double> intervals;
  if (d.imu_residuals)
    for (const ImuResidual r : *d.imu_residuals)
      if (r.dt_s > 0.0) intervals.push_back(r.dt_s);
  t +=
      "IMU RESIDUALS (the body rate and specific force the refinement's smoothed motion has beyond "
      "the IMU's samples, over each frame interval; imu_residuals.csv lists them)\n";
  if (intervals.empty()) {
    t += "none: no refinement step smoothed the motion (none was taken, or this calibration makes "
         "none)\n\n";
    return;
  }
  const ImuNoise& noise = d.result.imu.noise;
  const double dt = sample_stats(intervals).median;
  t += format(
      "%zu intervals, median %.1f ms; the white noise's 1-sigma over it: gyro %.3g rad/s, "
      "accelerometer %.3g m/s^2 (imu.yaml's densities / sqrt(interval))\n",
      intervals.size(), 1e3 * dt, noise.gyro_noise_density / std::sqrt(dt),
      noise.accel_noise_density / std::sqrt(dt));
  add_imu_residual_line(t, d, 0);
  add_imu_residual_line(t, d, 1);
  t += "(in white-noise sigmas the RMS is about 1 or less when imu.yaml's densities hold: the "
       "smoothing takes some of the noise out; well above 1, the IMU is noisier than imu.yaml "
       "says, or has scale factors or axes the IMU model lacks, which show as residuals that "
       "follow the motion in imu_residuals.png; a mean off zero is a bias the estimate missed)\n\n";
}

void add_biases(std::string& t, const ReportData& d) {
  if (d.rows.empty()) return;
  const ImuResult& imu = d.result.imu;
  const Eigen::Vector3d& a = imu.accel_bias;
  const Eigen::Vector3d& sa = imu.accel_bias_sigma;
  const Eigen::Vector3d g = imu.gyro_bias * kDeg;
  const Eigen::Vector3d sg = imu.gyro_bias_sigma * kDeg;
  t += "IMU BIASES (final estimate +- 1-sigma)\n";
  t += format("accelerometer [m/s^2]: x %.5f +- %.5f, y %.5f +- %.5f, z %.5f +- %.5f\n", a(0),
              sa(0), a(1), sa(1), a(2), sa(2));
  t += format("gyro [deg/s]:          x %.5f +- %.5f, y %.5f +- %.5f, z %.5f +- %.5f\n", g(0),
              sg(0), g(1), sg(1), g(2), sg(2));
  t += format("gravity in the mirror's frame [m/s^2]: %.4f %.4f %.4f (given, not estimated)\n\n",
              imu.gravity_n(0), imu.gravity_n(1), imu.gravity_n(2));
}

// How well the data fixed the markers' size against the mirror's distance (scale_unresolved()
// beyond kLooseMarkerScale).
void add_marker_scale(std::string& t, const CalibrationResult& r) {
  const double sigma = marker_scale_sigma(r);
  if (!(sigma > 0.0)) return;
  t += format(
      "the markers' common scale about the camera (only the IMU's acceleration fixes it): known "
      "to %.2f %% (1 sigma)",
      100.0 * sigma);
  if (scale_unresolved(r))
    t += format("; beyond %.0f %%: not trusted (the WARNING above)", 100.0 * kLooseMarkerScale);
  t += "\n";
}

void add_excitation(std::string& t, const ReportData& d) {
  if (d.rows.empty()) return;
  t += "EXCITATION (what the motion offered the calibration)\n";
  std::vector<int> per_count(std::size_t(marker_count(d)) + 1, 0);
  int frames = 0, markers = 0;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  double p_lo = INFINITY, p_hi = -INFINITY;
  for (const ReportRow row : d.rows) {
    lo = lo.cwiseMin(row.rotation);
    hi = hi.cwiseMax(row.rotation);
    p_lo = std::min(p_lo, row.normal_position);
    p_hi = std::max(p_hi, row.normal_position);
    const int n = row.markers_seen;
    if (n < 0) continue;
    ++frames;
    markers += n;
    if (std::size_t(n) < per_count.size()) ++per_count[std::size_t(n)];
  }
  t += format("%.2f s, %d frames, %.2f markers per frame (frames with",
              d.rows.back().t_s - d.rows.front().t_s, frames,
              frames > 0 ? double(markers) / frames : 0.0);
  for (std::size_t n = 0; n < per_count.size(); ++n)
    t += format(" %zu: %d%s", n, per_count[n], n + 1 < per_count.size() ? "," : ")\n");
  const loop::LoopCounters& l = d.loop;
  t += format(
      "IMU: %llu samples, %llu gaps (%llu too long to cross: the motion restarted, the calibration "
      "kept), %llu frames behind the filter skipped\n",
      static_cast<unsigned long long>(l.imu_samples), static_cast<unsigned long long>(l.imu_gaps),
      static_cast<unsigned long long>(l.imu_restarts),
      static_cast<unsigned long long>(l.frames_before_filter));
  const Eigen::Vector3d range = (hi - lo) * kDeg;
  t += format(
      "rotation range about the IMU's axes (from the first pose): x %.1f, y %.1f, z %.1f deg\n",
      range(0), range(1), range(2));
  std::size_t a_count = 0;
  double a_squares = 0.0, a_max = 0.0;
  normal_acceleration(d)([&](double x) {
    ++a_count;
    a_squares += x * x;
    a_max = std::max(a_max, std::abs(x));
  });
  t += format(
      "along the mirror's normal: position range %.1f cm, acceleration RMS %.3f m/s^2, largest "
      "%.3f m/s^2\n",
      100.0 * (p_hi - p_lo), a_count == 0 ? 0.0 : std::sqrt(a_squares / double(a_count)), a_max);
  add_marker_scale(t, d.result);
  std::string weak;
  const std::vector<ParamInfo>& params = d.result.params;
  // The camera pose, markers and time offset: the block before the intrinsics.
  const std::size_t from_earlier =
      d.from_earlier ? std::size_t(d.result.layout()[CalibrationGroup::kIntrinsics].begin) : 0;
  for (std::size_t j = 0; j < params.size() && j < d.prior_sigma.size(); ++j) {
    const double ratio = d.result.sigma[j] / d.prior_sigma[j];
    if (ratio > (j < from_earlier ? kWeaklyObservedFromEarlierRatio : kWeaklyObservedRatio))
      weak += format("%s%s (%.2f)", weak.empty() ? "" : ", ", params[j].name.c_str(), ratio);
  }
  if (d.prior_sigma.empty()) {
    t += "weakly observed states: unknown (no prior)\n\n";
    return;
  }
  t += format(
      "weakly observed (final sigma above %.1f of the prior's; more motion about the axes that "
      "move them helps): %s\n",
      kWeaklyObservedRatio, weak.empty() ? "none" : weak.c_str());
  if (d.from_earlier)
    t += format(
        "(the camera pose, markers and time offset started from an earlier calibration, stage 1 "
        "or --from: judged against it, above %.1f; at 0.71 these data held as much as that "
        "one's)\n",
        kWeaklyObservedFromEarlierRatio);
  t += "\n";
}

}  // namespace

std::string report_text(const ReportData& d) {
  // The verdict stays the third line (after the title and a blank): what a reader looks for first.
  std::string t =
      "mirrorcal calibration report: " + d.title + "; written by " + io::written_by() + "\n\n";
  add_verdict(t, d);
  add_noise(t, d);
  add_calibration(t, d);
  add_imu(t, d);
  if (d.rows.empty()) {
    t += "No frame was calibrated from: no residuals, innovations or excitation to report.\n";
    return t;
  }
  add_residuals(t, d);
  add_nis(t, d);
  add_imu_residuals(t, d);
  add_biases(t, d);
  add_excitation(t, d);
  return t;
}

std::string base64(const std::string& bytes) {
  static const char* const kAlphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const std::size_t n = std::min<std::size_t>(3, bytes.size() - i);
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < 3; ++k)
      v = (v << 8) | (k < n ? static_cast<unsigned char>(bytes[i + k]) : 0u);
    for (std::size_t k = 0; k < 4; ++k) out += k <= n ? kAlphabet[(v >> (18 - 6 * k)) & 63u] : '=';
  }
  return out;
}

namespace {

std::string html_escaped(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string figure_html(const std::string& caption, const std::string& png) {
  return "<figure><img alt=\"" + html_escaped(caption) + "\" src=\"data:image/png;base64," +
         base64(png) + "\"/><figcaption>" + html_escaped(caption) + "</figcaption></figure>\n";
}

std::string report_html(const ReportData& d, const std::string& text, const ReportPlots& plots) {
  std::string h =
      "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\"/>\n<title>" +
      html_escaped("mirrorcal report: " + d.title) +
      "</title>\n<style>\nbody { font-family: sans-serif; margin: 1em auto; max-width: 1250px; "
      "padding: 0 1em; }\n"
      // Long lines (the warnings, the advice) wrap: a side-scrolling block hid them at 1200 px.
      "pre { background: #f4f4f4; padding: 1em; white-space: pre-wrap; overflow-wrap: anywhere; "
      "}\n"
      ".ok { color: #176b2c; }\n.bad { color: #b3261e; }\nimg { max-width: 100%; }\n"
      "figure { margin: 1.5em 0; }\n</style>\n</head>\n<body>\n<h1>" +
      html_escaped("mirrorcal calibration report: " + d.title) + "</h1>\n<p class=\"" +
      (consistent(d.result) ? "ok" : "bad") + "\"><strong>" + html_escaped(verdict_line(d.result)) +
      "</strong></p>\n<pre>" + html_escaped(text) + "</pre>\n<h2>Plots</h2>\n";
  if (!plots.draw)
    return h + "<p>Plots unavailable: not drawn (--no-plots).</p>\n</body>\n</html>\n";
  std::string why = "not in this build (the board's: gnuplot's plots are the host's)";
  const std::vector<ReportFigure> drawn =
      plots.drawer != nullptr ? plots.drawer(d, why) : std::vector<ReportFigure>{};
  if (drawn.empty()) h += "<p>Plots unavailable: " + html_escaped(why) + ".</p>\n";
  for (const ReportFigure& figure : drawn) h += figure_html(figure.caption, figure.png);
  for (const std::string& path : plots.extra_pngs) {
    std::string png, error;
    if (io::read_file(path, png, error))
      h += figure_html("Error against the truth with +-3 sigma: " +
                           std::filesystem::path(path).filename().string(),
                       png);
  }
  return h + "</body>\n</html>\n";
}

bool write_residuals_csv(io::OutputSet& out, const std::string& path, const ReportData& d,
                         std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  std::fprintf(o, "#time [s],marker,du [px],dv [px],settled\n");
  for (const ResidualSample r : d.residuals)
    std::fprintf(o, "%.9f,%d,%.17g,%.17g,%d\n", r.t_s, r.marker + 1, r.du, r.dv, r.settled ? 1 : 0);
  return true;
}

bool write_imu_residuals_csv(io::OutputSet& out, const std::string& path, const ReportData& d,
                             std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  std::fprintf(o,
               "#time [s],interval [s],gyro x [rad/s],gyro y [rad/s],gyro z [rad/s],accel x "
               "[m/s^2],accel y [m/s^2],accel z [m/s^2]\n");
  if (!d.imu_residuals) return true;
  for (const ImuResidual r : *d.imu_residuals)
    if (r.dt_s > 0.0)
      std::fprintf(o, "%.9f,%.9f,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", double(r.t_ns) * 1e-9,
                   r.dt_s, r.gyro(0), r.gyro(1), r.gyro(2), r.accel(0), r.accel(1), r.accel(2));
  return true;
}

bool write_text(io::OutputSet& out, const std::string& path, const std::string& text,
                std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  std::fputs(text.c_str(), o);
  return true;
}

}  // namespace

bool write_report(io::OutputSet& out, const std::string& dir, const ReportData& d,
                  const ReportPlots& plots, std::string& error) {
  const std::string text = report_text(d);
  return write_residuals_csv(out, dir + "/residuals.csv", d, error) &&
         write_imu_residuals_csv(out, dir + "/imu_residuals.csv", d, error) &&
         write_text(out, dir + "/report.txt", text, error) &&
         write_text(out, dir + "/report.html", report_html(d, text, plots), error);
}

}  // namespace mirrorcal::calibration
