#include "mirrorcal/evaluation/paper_tables.hpp"

#include "mirrorcal/calibration/statistics.hpp"

#include <algorithm>
#include <cmath>

namespace mirrorcal::evaluation {

using namespace calibration;

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

}  // namespace mirrorcal::evaluation
