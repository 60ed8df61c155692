#include "report.hpp"

#include <cmath>

namespace mirrorcal::app {

std::vector<double> truth_display(const sim::Scenario& s) {
  std::vector<double> t;
  for (int i = 0; i < 3; ++i) t.push_back(100.0 * s.truth.p_b_c(i));
  const Eigen::Vector3d angles = display_angles(s.truth.q_b_c);
  for (int i = 0; i < 3; ++i) t.push_back(angles(i));
  for (const auto& m : s.truth.markers)
    for (int i = 0; i < 3; ++i) t.push_back(100.0 * m(i));
  return t;
}

Eigen::Vector3d display_angles(const Eigen::Quaterniond& q) {
  const Eigen::Vector3d zyx = q.toRotationMatrix().eulerAngles(2, 1, 0);
  return Eigen::Vector3d(zyx(2), zyx(1), zyx(0)) * 180.0 / M_PI;
}

const std::vector<PaperRow>& paper_tables() {
  static const std::vector<PaperRow> rows = {
      {0.69, 0.53},   {-5.08, 0.16}, {10.12, 0.31}, {-89.99, 0.01}, {0.0, 0.02},
      {-89.98, 0.06}, {1.98, 0.03},  {-2.99, 0.03}, {-3.00, 0.03},  {4.98, 0.05},
      {4.00, 0.04},   {-3.00, 0.03}, {-8.01, 0.08}, {6.00, 0.06},   {0.99, 0.01}};
  return rows;
}

double chi2_quantile(double p, double k) {
  const double z = p < 0.5 ? -1.959963985 : 1.959963985;  // the 2.5 % and 97.5 % normal points
  const double a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3.0);
}

}  // namespace mirrorcal::app
