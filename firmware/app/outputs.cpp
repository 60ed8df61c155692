#include "outputs.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "mirrorcal/estimator/calibration_filter.hpp"

namespace mirrorcal::app {

std::vector<ParamInfo> calibration_params(int markers, int intrinsics) {
  constexpr double kCm = 100.0, kDeg = 180.0 / M_PI;
  std::vector<ParamInfo> p;
  for (const char* a : {"x", "y", "z"}) p.push_back({std::string("p_") + a, "cm", kCm});
  for (const char* a : {"x", "y", "z"}) p.push_back({std::string("rot_") + a, "deg", kDeg});
  for (int i = 0; i < markers; ++i)
    for (const char* a : {"x", "y", "z"})
      p.push_back({"f" + std::to_string(i + 1) + "_" + a, "cm", kCm});
  p.push_back({"timeshift_cam_imu", "ms", 1e3});
  const char* k[5] = {"fu", "fv", "cu", "cv", "skew"};
  for (int j = 0; j < intrinsics; ++j) p.push_back({k[j], "px", 1.0});
  return p;
}

namespace {

void write_matrix_rows(std::FILE* f, const Eigen::Matrix4d& t, const char* indent) {
  for (int i = 0; i < 4; ++i)
    std::fprintf(f, "%s- [%.12f, %.12f, %.12f, %.12f]\n", indent, t(i, 0), t(i, 1), t(i, 2),
                 t(i, 3));
}

Eigen::Matrix4d t_cam_imu(const CalibrationResult& r) {
  const Eigen::Matrix3d r_c_b = r.q_b_c.toRotationMatrix().transpose();
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = r_c_b;
  t.topRightCorner<3, 1>() = -r_c_b * r.p_b_c;
  return t;
}

}  // namespace

bool write_camchain_imucam(files::OutputSet& out, const std::string& path,
                           const CalibrationResult& r, std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  std::fprintf(o, "# mirrorcal calibration, Kalibr camchain-imucam format\ncam0:\n");
  std::fprintf(o, "  camera_model: pinhole\n");
  std::fprintf(o, "  intrinsics: [%.6f, %.6f, %.6f, %.6f]\n", r.intrinsics.fu, r.intrinsics.fv,
               r.intrinsics.cu, r.intrinsics.cv);
  std::fprintf(o, "  intrinsics_skew: %.6f\n", r.intrinsics.skew);
  const std::array<double, 4>& d = r.intrinsics.coeffs;
  std::fprintf(o, "  distortion_model: %s\n  distortion_coeffs: [%.12g, %.12g, %.12g, %.12g]\n",
               to_string(r.intrinsics.distortion == Distortion::kNone ? Distortion::kRadtan
                                                                      : r.intrinsics.distortion),
               d[0], d[1], d[2], d[3]);
  std::fprintf(o, "  resolution: [%d, %d]\n", r.width, r.height);
  std::fprintf(o, "  timeshift_cam_imu: %.9f\n  T_cam_imu:\n", r.t_d);
  write_matrix_rows(o, t_cam_imu(r), "  ");
  return true;
}

namespace {

// Markers offered to the filter in the last pass, and those it could not use.
double markers_offered(const CalibrationResult& r) {
  return double(r.markers_used + r.markers_gated + r.markers_invalid);
}
double markers_rejected(const CalibrationResult& r) {
  return double(r.markers_gated + r.markers_invalid);
}

}  // namespace

bool gated_too_many(const CalibrationResult& r) {
  const double seen = markers_offered(r);
  return seen > 0.0 && markers_rejected(r) > kSuspectGatedFraction * seen;
}

bool innovations_too_large(const CalibrationResult& r) {
  if (r.nis_dof == 0) return false;
  const double band = std::max(kSuspectNisExcess, 5.0 * std::sqrt(2.0 / double(r.nis_dof)));
  return r.nis_per_dof > 1.0 + band;
}

bool suspect(const CalibrationResult& r) {
  return gated_too_many(r) || innovations_too_large(r) || r.filter_failures > 0;
}

bool path_gained_false_information(const CalibrationResult& r) {
  return r.sigma_ratio < kSigmaRatioLimit;
}

std::string convergence_warning(const CalibrationResult& r) {
  const double seen = markers_offered(r);
  if (seen == 0.0) return "no marker was seen: nothing was calibrated beyond the priors";
  char text[480];
  if (r.filter_failures > 0 && !gated_too_many(r)) {
    std::snprintf(text, sizeof text,
                  "the filter refused %llu predicts or updates in the last pass (of %d) as "
                  "numerically broken (a covariance no longer positive definite): the result is "
                  "not a calibration. Start from better guesses and check the recording.",
                  static_cast<unsigned long long>(r.filter_failures), r.passes);
    return text;
  }
  if (!gated_too_many(r) && !innovations_too_large(r)) {
    if (!path_gained_false_information(r)) return {};
    std::snprintf(text, sizeof text,
                  "the filter's own sigmas came down to %.2f of what the data hold along its "
                  "final estimate: its way there, from guesses far off, gathered information the "
                  "data do not hold, and the estimate is likely off by more than the sigmas "
                  "reported. Move the rig more (tilts and moves toward the mirror), start from "
                  "better guesses, and check the recording.",
                  r.sigma_ratio);
    return text;
  }
  if (!gated_too_many(r)) {
    std::snprintf(text, sizeof text,
                  "the markers fit %.2f times worse than the filter's covariance says (normalised "
                  "innovation squared per degree of freedom over the last pass, of %d; about 1 "
                  "for a consistent calibration): it is over-confident or has locked onto a "
                  "wrong solution. Move the rig more (tilts and moves toward the mirror), start "
                  "from better guesses, and check the recording.",
                  r.nis_per_dof, r.passes);
    return text;
  }
  std::snprintf(text, sizeof text,
                "%.1f %% of the markers were rejected by the 99.9 %% gate or could not be "
                "predicted in the last pass (of %d) (a consistent calibration rejects about "
                "0.1 %%): it has most likely locked onto a wrong solution. Start from better "
                "guesses (or estimate the intrinsics in a second stage, calibrate --from), and "
                "check the recording.",
                100.0 * markers_rejected(r) / seen, r.passes);
  return text;
}

bool write_result_yaml(files::OutputSet& out, const std::string& path, const CalibrationResult& r,
                       std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  std::fprintf(o,
               "# mirrorcal result: SI units (m, rad, px); sigma is 1-sigma, rotations as the\n"
               "# components of the error vector log(R_b_c,true^T R_b_c,estimated)\n");
  std::fprintf(o, "T_cam_imu:\n");
  write_matrix_rows(o, t_cam_imu(r), "  ");
  std::fprintf(o, "p_b_c: [%.17g, %.17g, %.17g]\n", r.p_b_c.x(), r.p_b_c.y(), r.p_b_c.z());
  const Eigen::Matrix3d rbc = r.q_b_c.toRotationMatrix();
  std::fprintf(o, "R_b_c:\n");
  for (int i = 0; i < 3; ++i)
    std::fprintf(o, "  - [%.12f, %.12f, %.12f]\n", rbc(i, 0), rbc(i, 1), rbc(i, 2));
  std::fprintf(o, "q_b_c_wxyz: [%.17g, %.17g, %.17g, %.17g]\n", r.q_b_c.w(), r.q_b_c.x(),
               r.q_b_c.y(), r.q_b_c.z());
  std::fprintf(o, "features_c:\n");
  for (const auto& m : r.markers)
    std::fprintf(o, "  - [%.17g, %.17g, %.17g]\n", m.x(), m.y(), m.z());
  std::fprintf(o, "timeshift_cam_imu: %.17g  # s: t_imu = t_cam + timeshift_cam_imu\n", r.t_d);
  std::fprintf(o, "intrinsics: [%.6f, %.6f, %.6f, %.6f]\nskew: %.6f\n", r.intrinsics.fu,
               r.intrinsics.fv, r.intrinsics.cu, r.intrinsics.cv, r.intrinsics.skew);
  std::fprintf(o, "distortion_model: %s  # held as camchain.yaml gave it\n",
               to_string(r.intrinsics.distortion));
  std::fprintf(o, "distortion_coeffs: [%.17g, %.17g, %.17g, %.17g]\n", r.intrinsics.coeffs[0],
               r.intrinsics.coeffs[1], r.intrinsics.coeffs[2], r.intrinsics.coeffs[3]);
  std::fprintf(o, "intrinsics_estimated: %s\nskew_estimated: %s\nresolution: [%d, %d]\n",
               r.estimated_intrinsics > 0 ? "true" : "false",
               r.estimated_intrinsics == 5 ? "true" : "false", r.width, r.height);
  std::fprintf(o,
               "passes: %d\nmarkers_used: %llu\nmarkers_gated: %llu  # in the last pass\n"
               "markers_invalid: %llu  # not predictable at the estimate (behind the camera)\n",
               r.passes, static_cast<unsigned long long>(r.markers_used),
               static_cast<unsigned long long>(r.markers_gated),
               static_cast<unsigned long long>(r.markers_invalid));
  std::fprintf(o,
               "nis_per_dof: %.4f  # last pass, gate on: about 1 when the covariance is right\n"
               "sigma_ratio: %.4f  # the filter's own sigmas against those reported, at least\n",
               r.nis_per_dof, r.sigma_ratio);
  std::fprintf(o,
               "consistent: %s  # false: more than 0.5 %% of the markers gated, nis_per_dof well "
               "above 1 or sigma_ratio below 0.8: do not trust it\n",
               convergence_warning(r).empty() ? "true" : "false");
  std::fprintf(o, "sigma:\n");
  for (std::size_t j = 0; j < r.params.size(); ++j)
    std::fprintf(o, "  %s: %.9g\n", r.params[j].name.c_str(), r.sigma[j]);
  std::fprintf(o, "# covariance of the calibration states, rows and columns in sigma's order\n");
  std::fprintf(o, "covariance:\n");
  for (long i = 0; i < r.covariance.rows(); ++i) {
    std::fprintf(o, "  - [");
    for (long j = 0; j < r.covariance.cols(); ++j)
      std::fprintf(o, "%s%.17g", j > 0 ? ", " : "", r.covariance(i, j));
    std::fprintf(o, "]\n");
  }
  return true;
}

template <class Filter>
bool write_estimates_csv(files::OutputSet& out, const std::string& path,
                         const std::vector<HistoryRow<Filter>>& rows, std::string& error) {
  using State = typename Filter::State;
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  const auto params = calibration_params(State::kMarkers, State::kIntrinsics);
  std::fprintf(o, "#time [s],p_x [m],p_y [m],p_z [m],q_w,q_x,q_y,q_z");
  for (int i = 0; i < State::kMarkers; ++i)
    for (const char* a : {"x", "y", "z"}) std::fprintf(o, ",f%d_%s [m]", i + 1, a);
  std::fprintf(o, ",timeshift_cam_imu [s]");
  const char* k[5] = {"fu [px]", "fv [px]", "cu [px]", "cv [px]", "skew [px]"};
  for (int j = 0; j < State::kIntrinsics; ++j) std::fprintf(o, ",%s", k[j]);
  for (const auto& p : params)
    std::fprintf(o, ",sigma_%s [%s]", p.name.c_str(),
                 p.unit == "cm"    ? "m"
                 : p.unit == "deg" ? "rad"
                 : p.unit == "ms"  ? "s"
                                   : "px");
  std::fprintf(o, "\n");
  for (const auto& r : rows) {
    const State& x = r.state;
    std::fprintf(o, "%.9f,%.9g,%.9g,%.9g,%.12g,%.12g,%.12g,%.12g", double(r.t_ns) * 1e-9,
                 double(x.p_b_c.x()), double(x.p_b_c.y()), double(x.p_b_c.z()), double(x.q_b_c.w()),
                 double(x.q_b_c.x()), double(x.q_b_c.y()), double(x.q_b_c.z()));
    for (int j = 0; j < 3 * State::kMarkers; ++j) std::fprintf(o, ",%.9g", double(x.markers(j)));
    std::fprintf(o, ",%.9g", double(x.t_d));
    for (int j = 0; j < State::kIntrinsics; ++j) std::fprintf(o, ",%.9g", double(x.intrinsics(j)));
    for (int j = 0; j < r.sigma.size(); ++j) std::fprintf(o, ",%.6g", r.sigma(j));
    std::fprintf(o, "\n");
  }
  return true;
}

template bool write_estimates_csv(files::OutputSet&, const std::string&,
                                  const std::vector<HistoryRow<CalibrationFilter<double, 3, 0>>>&,
                                  std::string&);
template bool write_estimates_csv(files::OutputSet&, const std::string&,
                                  const std::vector<HistoryRow<CalibrationFilter<double, 3, 4>>>&,
                                  std::string&);
template bool write_estimates_csv(files::OutputSet&, const std::string&,
                                  const std::vector<HistoryRow<CalibrationFilter<double, 3, 5>>>&,
                                  std::string&);

}  // namespace mirrorcal::app
