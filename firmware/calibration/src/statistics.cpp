#include "mirrorcal/calibration/statistics.hpp"

#include <cmath>

namespace mirrorcal::calibration {

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

}  // namespace mirrorcal::calibration
