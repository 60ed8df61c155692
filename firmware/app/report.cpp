#include "report.hpp"

#include <algorithm>
#include <cmath>

namespace mirrorcal::app {

std::vector<double> truth_display(const sim::Scenario& s, int intrinsics) {
  std::vector<double> t;
  for (int i = 0; i < 3; ++i) t.push_back(100.0 * s.truth.p_b_c(i));
  const Eigen::Vector3d angles = display_angles(s.truth.q_b_c);
  for (int i = 0; i < 3; ++i) t.push_back(angles(i));
  for (const auto& m : s.truth.markers)
    for (int i = 0; i < 3; ++i) t.push_back(100.0 * m(i));
  t.push_back(1e3 * s.truth.t_d);
  const Pinhole<double>& k = s.truth.intrinsics;
  const double all[5] = {k.fu, k.fv, k.cu, k.cv, k.skew};
  const CalibrationLayout layout = calibration_layout(int(s.truth.markers.size()), intrinsics);
  for (int j = 0; j < layout[CalibrationGroup::kIntrinsics].size; ++j) t.push_back(all[j]);
  // The lens's coefficients, in thousandths (calibration_params).
  for (int j = 0; j < layout[CalibrationGroup::kLens].size; ++j)
    t.push_back(1e3 * k.coeffs[std::size_t(j)]);
  return t;
}

Eigen::Vector3d display_angles(const Eigen::Quaterniond& q) {
  Eigen::Vector3d zyx = q.toRotationMatrix().eulerAngles(2, 1, 0);
  // Eigen returns the first angle in [0, pi]; (z, y, x) and (z - pi, pi - y, x - pi) are the same
  // rotation. Show the one with the middle angle in [-90, 90] deg, as the paper writes its
  // (-90, 0, -90).
  const auto wrap = [](double a) { return std::remainder(a, 2.0 * M_PI); };
  if (std::abs(zyx(1)) > M_PI / 2)
    zyx = Eigen::Vector3d(wrap(zyx(0) - M_PI), wrap(M_PI - zyx(1)), wrap(zyx(2) - M_PI));
  return Eigen::Vector3d(zyx(2), zyx(1), zyx(0)) * 180.0 / M_PI;
}

const std::vector<PaperRow>& paper_tables() {
  static const std::vector<PaperRow> rows = {
      {0.69, 0.53},
      {-5.08, 0.16},
      {10.12, 0.31},
      {-89.99, 0.01},
      {0.0, 0.02},
      {-89.98, 0.06},
      {1.98, 0.03},
      {-2.99, 0.03},
      {-3.00, 0.03},
      {4.98, 0.05},
      {4.00, 0.04},
      {-3.00, 0.03},
      {-8.01, 0.08},
      {6.00, 0.06},
      {0.99, 0.01},
      {NAN, NAN},  // the time offset: the paper's camera and IMU share a clock
      // Table III; the paper's centred cu, cv shifted to our top-left origin (640 x 480).
      {833.93, 1.26},
      {833.94, 1.33},
      {320.0 + 2.73, 0.92},
      {240.0 + 7.74, 0.95},
      {3.31, 0.50}};
  return rows;
}

double chi2_quantile(double p, double k) {
  // The standard normal quantile by bisection on its distribution function (0.5 erfc(-z/sqrt 2)),
  // then Wilson and Hilferty's cube-root approximation, accurate to 1e-3 relative at k >= 15.
  double lo = -10.0, hi = 10.0;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
  }
  const double z = 0.5 * (lo + hi);
  const double a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3.0);
}

}  // namespace mirrorcal::app
