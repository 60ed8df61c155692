#include "mirrorcal/evaluation/campaign_statistics.hpp"

#include <algorithm>
#include <cmath>

#include "mirrorcal/calibration/report.hpp"
#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/evaluation/rendered_markers.hpp"

namespace mirrorcal::evaluation {

namespace {

// The mean, as the sum of each value over their count (the order the reports' figures were
// always computed in, so that they do not move in their last digit).
double mean_of(const std::vector<double>& values) {
  double m = 0.0;
  for (const double v : values) m += v / double(values.size());
  return m;
}

// A group's figures in its display unit from the runs' (the markers in mm, from cm).
double display_unit(std::size_t group) {
  return group == 2 ? 10.0 : 1.0;
}

}  // namespace

double worst_sigmas(const RunOutcome& run) {
  double worst = 0.0;
  for (std::size_t j = 0; j < run.error.size(); ++j)
    worst = std::max(worst, std::abs(run.error[j]) / run.sigma[j]);
  return worst;
}

NeesInterval average_nees_interval(double runs, std::size_t states, double tail) {
  const double dof = runs * double(states);
  return {calibration::chi2_quantile(tail, dof) / runs,
          calibration::chi2_quantile(1.0 - tail, dof) / runs};
}

ErrorStatistics error_statistics(const std::vector<RunOutcome>& runs, std::size_t states) {
  const double n = double(runs.size());
  ErrorStatistics st;
  st.runs = runs.size();
  st.mean.assign(states, 0.0);
  st.var.assign(states, 0.0);
  st.mean_square.assign(states, 0.0);
  st.sigma_square.assign(states, 0.0);
  for (const RunOutcome& run : runs)
    for (std::size_t j = 0; j < states; ++j) {
      st.mean[j] += run.error[j] / n;
      st.mean_square[j] += run.error[j] * run.error[j] / n;
      st.sigma_square[j] += run.sigma[j] * run.sigma[j] / n;
    }
  for (const RunOutcome& run : runs)
    for (std::size_t j = 0; j < states; ++j)
      st.var[j] +=
          (run.error[j] - st.mean[j]) * (run.error[j] - st.mean[j]) / std::max(1.0, n - 1.0);
  std::vector<double> nees;
  for (const RunOutcome& run : runs) nees.push_back(run.nees);
  st.nees = mean_of(nees);
  st.nees95 = average_nees_interval(n, states, kTail95);
  return st;
}

TrustedNees trusted_nees(const std::vector<RunOutcome>& runs) {
  TrustedNees t;
  double sum = 0.0;
  for (const RunOutcome& run : runs)
    if (!run.suspect) {
      sum += run.nees;
      ++t.runs;
    }
  t.nees = t.runs > 0 ? sum / double(t.runs) : 0.0;
  return t;
}

const char* group_label(std::size_t group) {
  static const char* const kLabel[kGroups] = {"p_b_c [cm]",     "rot_b_c [deg]",   "markers [mm]",
                                              "timeshift [ms]", "intrinsics [px]", "lens [1e-3]"};
  return kLabel[group];
}

std::size_t reported_groups(const CalibrationLayout& layout) {
  return layout[CalibrationGroup::kLens].size > 0         ? 6
         : layout[CalibrationGroup::kIntrinsics].size > 0 ? 5
                                                          : 4;
}

void GroupStatistics::add(const RunOutcome& run) {
  nees_.push_back(run.nees);
  const bool far = worst_sigmas(run) > 4.0;
  beyond_ += far ? 1 : 0;
  flagged_ += run.suspect ? 1 : 0;
  missed_ += far && !run.suspect ? 1 : 0;
  PerGroup run_lim{};
  for (std::size_t j = 0; j < run.error.size(); ++j) {
    const auto k = static_cast<std::size_t>(layout_.group_of(static_cast<int>(j)));
    const double e2 = run.error[j] * run.error[j];
    const double l2 = j < run.limit.size() ? run.limit[j] * run.limit[j] : 0.0;
    sq_[k] += e2;
    var_[k] += run.sigma[j] * run.sigma[j];
    lim_[k] += l2;
    count_[k] += 1.0;
    if (!run.suspect) {
      sq_ok_[k] += e2;
      lim_ok_[k] += l2;
      run_lim[k] += l2;
      if (l2 > 0.0) {
        per_run_ok_[k] += e2 / l2;
        count_ok_[k] += 1.0;
      }
    }
  }
  for (std::size_t k = 0; k < kGroups; ++k) run_lim_sq_ok_[k] += run_lim[k] * run_lim[k];
}

double GroupStatistics::mean_nees() const {
  return mean_of(nees_);
}

double GroupStatistics::median_nees() const {
  return calibration::sample_stats(nees_).median;
}

GroupStatistics::PerGroup GroupStatistics::rms() const {
  PerGroup r{};
  for (std::size_t k = 0; k < kGroups; ++k)
    r[k] = count_[k] > 0 ? display_unit(k) * std::sqrt(sq_[k] / count_[k]) : 0.0;
  return r;
}

GroupStatistics::PerGroup GroupStatistics::sigma() const {
  PerGroup r{};
  for (std::size_t k = 0; k < kGroups; ++k)
    r[k] = count_[k] > 0 ? display_unit(k) * std::sqrt(var_[k] / count_[k]) : 0.0;
  return r;
}

GroupStatistics::PerGroup GroupStatistics::over_limit(bool consistent_only) const {
  PerGroup r{};
  for (std::size_t k = 0; k < kGroups; ++k) {
    const double e = consistent_only ? sq_ok_[k] : sq_[k],
                 l = consistent_only ? lim_ok_[k] : lim_[k];
    r[k] = l > 0.0 ? std::sqrt(e / l) : 0.0;
  }
  return r;
}

GroupStatistics::PerGroup GroupStatistics::effective_runs() const {
  PerGroup r{};
  for (std::size_t k = 0; k < kGroups; ++k)
    r[k] = run_lim_sq_ok_[k] > 0.0 ? lim_ok_[k] * lim_ok_[k] / run_lim_sq_ok_[k] : 0.0;
  return r;
}

GroupStatistics::PerGroup GroupStatistics::per_run_over_limit() const {
  PerGroup r{};
  for (std::size_t k = 0; k < kGroups; ++k)
    r[k] = count_ok_[k] > 0.0 ? std::sqrt(per_run_ok_[k] / count_ok_[k]) : 0.0;
  return r;
}

std::vector<FamilyGroup> family_groups(std::size_t groups) {
  using S = sim::Scenario;
  std::vector<FamilyGroup> slices = {
      {"all", "all", [](const S&) { return true; }},
      {"mirror", "wall", [](const S& s) { return s.mirror == "wall"; }},
      {"mirror", "floor", [](const S& s) { return s.mirror == "floor"; }},
      {"motion", "slow", [](const S& s) { return s.motion_kind == "slow"; }},
      {"motion", "fast", [](const S& s) { return s.motion_kind == "fast"; }},
      {"camera", "20-40 Hz", [](const S& s) { return s.camera_rate_hz < 40.0; }},
      {"camera", "40-60 Hz", [](const S& s) { return s.camera_rate_hz >= 40.0; }},
      {"pixel noise", "0.25-0.6 px", [](const S& s) { return s.pixel_sigma < 0.6; }},
      {"pixel noise", "0.6-1 px", [](const S& s) { return s.pixel_sigma >= 0.6; }},
      {"imu noise", "1-3x", [](const S& s) { return s.imu_noise_scale < 3.0; }},
      {"imu noise", "3-5x", [](const S& s) { return s.imu_noise_scale >= 3.0; }},
      {"marker prior", "3-6.5 cm", [](const S& s) { return s.priors.marker < 0.065; }},
      {"marker prior", "6.5-10 cm", [](const S& s) { return s.priors.marker >= 0.065; }},
  };
  if (groups > 4) {  // the camera's prior too
    slices.push_back(
        {"camera prior", "20-60 px", [](const S& s) { return s.priors.intrinsics[0] < 60.0; }});
    slices.push_back(
        {"camera prior", "60-100 px", [](const S& s) { return s.priors.intrinsics[0] >= 60.0; }});
  }
  return slices;
}

void BatchComparison::add(const Eigen::VectorXd& filter_error, const Eigen::VectorXd& batch_error,
                          double batch_nees) {
  for (int j = 0; j < layout_.size(); ++j) {
    const std::size_t g = index(layout_.group_of(j));
    filter_sq_[g] += filter_error(j) * filter_error(j);
    batch_sq_[g] += batch_error(j) * batch_error(j);
    count_[g] += 1.0;
  }
  batch_nees_.push_back(batch_nees);
}

double BatchComparison::filter_rms(CalibrationGroup g) const {
  return count_[index(g)] > 0.0 ? std::sqrt(filter_sq_[index(g)] / count_[index(g)]) : 0.0;
}

double BatchComparison::batch_rms(CalibrationGroup g) const {
  return count_[index(g)] > 0.0 ? std::sqrt(batch_sq_[index(g)] / count_[index(g)]) : 0.0;
}

double BatchComparison::ratio(CalibrationGroup g) const {
  return batch_rms(g) > 0.0 ? filter_rms(g) / batch_rms(g) : 0.0;
}

double BatchComparison::mean_batch_nees() const {
  double sum = 0.0;
  for (const double n : batch_nees_) sum += n;
  return batch_nees_.empty() ? 0.0 : sum / static_cast<double>(batch_nees_.size());
}

DetectionReport combined_detection(const std::vector<RunOutcome>& runs) {
  std::vector<DetectionReport> each;
  for (const RunOutcome& run : runs) each.push_back(run.detection);
  return combine(each);
}

}  // namespace mirrorcal::evaluation
