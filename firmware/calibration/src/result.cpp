#include "mirrorcal/calibration/result.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/io/version.hpp"

namespace mirrorcal::calibration {

std::array<const char*, 4> distortion_coeff_names(Distortion lens) {
  if (lens == Distortion::kEquidistant) return {"k1", "k2", "k3", "k4"};
  return {"k1", "k2", "p1", "p2"};
}

namespace {

// The j-th parameter of a group (j < the group's size in the layout).
ParamInfo calibration_param(CalibrationGroup group, int j, Distortion lens) {
  constexpr double kCm = 100.0, kDeg = 180.0 / M_PI;
  const std::string axis(1, "xyz"[j % 3]);
  switch (group) {
    case CalibrationGroup::kCameraPosition:
      return {"p_" + axis, "cm", kCm, group};
    case CalibrationGroup::kCameraRotation:
      return {"rot_" + axis, "deg", kDeg, group};
    case CalibrationGroup::kMarkers:
      return {"f" + std::to_string(j / 3 + 1) + "_" + axis, "cm", kCm, group};
    case CalibrationGroup::kTimeOffset:
      return {"timeshift_cam_imu", "ms", 1e3, group};
    case CalibrationGroup::kIntrinsics:
      return {std::array<const char*, 5>{"fu", "fv", "cu", "cv", "skew"}[std::size_t(j)], "px", 1.0,
              group};
    case CalibrationGroup::kLens:  // in thousandths (p2 of EuRoC's lens is 1.8e-5); files in SI
      return {distortion_coeff_names(lens)[std::size_t(j)], "1e-3", 1e3, group};
  }
  return {};
}

}  // namespace

std::vector<ParamInfo> calibration_params(int markers, int intrinsics, Distortion lens) {
  const CalibrationLayout layout = calibration_layout(markers, intrinsics);
  std::vector<ParamInfo> p;
  for (int g = 0; g < kCalibrationGroups; ++g) {
    const auto group = static_cast<CalibrationGroup>(g);
    for (int j = 0; j < layout[group].size; ++j) p.push_back(calibration_param(group, j, lens));
  }
  return p;
}

void write_matrix_rows(std::FILE* f, const Eigen::MatrixXd& m, const char* indent, bool exact) {
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    std::fprintf(f, "%s- [", indent);
    for (Eigen::Index j = 0; j < m.cols(); ++j)
      std::fprintf(f, exact ? "%s%.17g" : "%s%.12f", j > 0 ? ", " : "", m(i, j));
    std::fprintf(f, "]\n");
  }
}

// First lines every parser takes: OpenCV's FileStorage needs a %YAML directive first, and PyYAML
// refuses OpenCV's own "%YAML:1.0"; this form PyYAML, OpenCV and yaml-cpp all read.
void write_yaml_header(std::FILE* o, const char* what) {
  std::fprintf(o, "%%YAML 1.0\n---\n# %s\n# written by %s\n", what, io::written_by().c_str());
}

namespace {

// The camera's pose in the IMU frame: maps camera coordinates into the IMU's.
Eigen::Matrix4d t_imu_cam(const CalibrationResult& r) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = r.q_b_c.toRotationMatrix();
  t.topRightCorner<3, 1>() = r.p_b_c;
  return t;
}

Eigen::Matrix4d t_cam_imu(const CalibrationResult& r) {
  const Eigen::Matrix3d r_c_b = r.q_b_c.toRotationMatrix().transpose();
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = r_c_b;
  t.topRightCorner<3, 1>() = -r_c_b * r.p_b_c;
  return t;
}

// Skew is where a tool has no slot for it: said in a comment rather than silently dropped.
void write_skew_note(std::FILE* o, const Pinhole<double>& k, const char* indent,
                     const char* tools) {
  std::fprintf(o, "%s# skew %.6f px (u = fu x + skew y + cu): %s\n", indent, k.skew, tools);
}

// cam0 of Kalibr's camchain-imucam.yaml, with the transform under the key OpenVINS prefers
// (T_imu_cam) or Kalibr's (T_cam_imu). Nested keys are indented deeper than their key, as OpenCV
// requires; comments stand on lines of their own (OpenCV keeps a trailing one in a string).
void write_imucam_chain(std::FILE* o, const CalibrationResult& r, bool imu_from_cam) {
  const Pinhole<double>& k = r.intrinsics;
  std::fprintf(o, "cam0:\n  camera_model: pinhole\n");
  std::fprintf(o, "  intrinsics: [%.6f, %.6f, %.6f, %.6f]\n", k.fu, k.fv, k.cu, k.cv);
  write_skew_note(o, k, "  ", "Kalibr and OpenVINS have no skew and drop it");
  std::fprintf(o, "  # (intrinsics_skew: mirrorcal's own key, which it reads back)\n");
  std::fprintf(o, "  intrinsics_skew: %.6f\n", k.skew);
  std::fprintf(o, "  distortion_model: %s\n  distortion_coeffs: [%.12g, %.12g, %.12g, %.12g]\n",
               io::kalibr_lens_name(k.distortion), k.coeffs[0], k.coeffs[1], k.coeffs[2],
               k.coeffs[3]);
  std::fprintf(o, "  resolution: [%d, %d]\n", r.width, r.height);
  std::fprintf(o, "  # s per row (a rolling shutter; 0: a global shutter)\n  line_delay: %.9g\n",
               k.line_delay_s);
  std::fprintf(o,
               "  # s, the frames' exposure, the stamp at its middle (0: not modelled)\n"
               "  exposure_time: %.9g\n",
               k.exposure_s);
  std::fprintf(o, "  rostopic: %s\n  cam_overlaps: []\n", r.rostopic.c_str());
  std::fprintf(o, "  # s: t_imu = t_cam + timeshift_cam_imu\n  timeshift_cam_imu: %.9f\n", r.t_d);
  if (imu_from_cam) {
    std::fprintf(o, "  # the camera's pose in the IMU frame (R_CtoI, p_CinI)\n  T_imu_cam:\n");
    write_matrix_rows(o, t_imu_cam(r), "    ");
  } else {
    std::fprintf(o, "  # maps IMU coordinates into the camera's\n  T_cam_imu:\n");
    write_matrix_rows(o, t_cam_imu(r), "    ");
  }
}

}  // namespace

namespace {

// That the file holds a calibration not to be trusted, and why, as comment lines a reader sees
// first (the tools that read the file skip them).
void write_distrust_comment(std::FILE* o, const std::string& why) {
  std::fprintf(o, "# NOT TO BE TRUSTED: mirrorcal's self-check says consistent: false.\n");
  constexpr std::size_t kWidth = 96;
  for (std::size_t start = 0; start < why.size();) {
    std::size_t end = std::min(start + kWidth, why.size());
    if (end < why.size()) {
      const std::size_t space = why.rfind(' ', end);
      if (space != std::string::npos && space > start) end = space;
    }
    std::fprintf(o, "# %s\n", why.substr(start, end - start).c_str());
    start = end + 1;
  }
}

}  // namespace

bool write_camchain_imucam(io::OutputSet& out, const std::string& path, const CalibrationResult& r,
                           std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  write_yaml_header(o, "mirrorcal calibration, Kalibr camchain-imucam format");
  if (!consistent(r)) write_distrust_comment(o, convergence_warning(r));
  write_imucam_chain(o, r, false);
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

bool refinement_unconverged(const CalibrationResult& r) {
  return r.refinement_refused || r.refinement_step_sigmas > kRefinementStepLimit;
}

bool used_too_few(const CalibrationResult& r) {
  return r.markers_observed > 0 &&
         double(r.markers_used) < kMinUsedFraction * double(r.markers_observed);
}

bool identification_failed(const CalibrationResult& r) {
  const CalibrationResult::DetectionCounts& d = r.detection;
  const double possible = double(d.frames) * double(r.markers.size());
  return d.frames > 0 && double(d.labelled) < kMinLabelledShare * possible &&
         d.in_doubt + d.unlabelled > d.labelled;
}

bool labels_swapped(const CalibrationResult& r) {
  const CalibrationResult::LabelSwap& w = r.label_swap;
  return w.a >= 0 && w.frames >= kMinSwappedFrames &&
         double(w.frames) > kSwappedShare * double(w.both_seen);
}

bool priors_miss_first_frame(const CalibrationResult& r) {
  return r.prior_fit.seen > 0 && r.prior_fit.near_image == 0;
}

bool priors_read_another_way(const CalibrationResult& r) {
  const CalibrationResult::PriorFit& f = r.prior_fit;
  return f.better_reading != nullptr && f.median_px > kConventionMinPx &&
         f.better_median_px < kConventionFitShare * f.median_px;
}

bool prior_contradicted(const CalibrationResult& r) {
  return r.prior_offset_sigmas > kPriorContradictedSigmas;
}

bool imu_contradicted(const CalibrationResult& r) {
  return r.imu.estimated() && r.imu.prior_offset_sigmas > kPriorContradictedSigmas;
}

bool imu_not_ideal(const CalibrationResult& r) {
  return !r.imu.estimated() && r.imu.ideal_check.failed();
}

bool scale_unresolved(const CalibrationResult& r) {
  return marker_scale_sigma(r) > kLooseMarkerScale;
}

namespace {

std::string fit_warning(const CalibrationResult& r) {
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
    if (r.refinement_refused) {
      std::snprintf(text, sizeof text,
                    "the refinement could take no Gauss-Newton step (its replay of the data met "
                    "other frames than the passes, or fitted worse than they did): the free "
                    "passes' own estimate and sigmas are reported, and those can be far more "
                    "confident than the data allow. Move the rig more (tilts and moves toward the "
                    "mirror), start from better guesses, and check the recording.");
      return text;
    }
    if (refinement_unconverged(r)) {
      std::snprintf(text, sizeof text,
                    "the last Gauss-Newton step of the refinement still moved the calibration by "
                    "%.1f of its sigmas (a converged one moves well under 1): the linearisation "
                    "does not hold where the estimate is, and neither the estimate nor its "
                    "sigmas can be trusted. Move the rig more (tilts and moves toward the "
                    "mirror), start from better guesses, and check the recording.",
                    r.refinement_step_sigmas);
      return text;
    }
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

// Said first: the other checks then fail for this reason, and their advice (move more briskly,
// check the timestamps) would send the user the wrong way.
std::string identification_warning(const CalibrationResult& r) {
  if (!identification_failed(r)) return {};
  const CalibrationResult::DetectionCounts& d = r.detection;
  // More blobs a frame than the rig has LEDs: something else in view looks like one, and may be
  // as bright as the LED it stands in for.
  const double blobs_a_frame = double(d.labelled + d.in_doubt + d.unlabelled) / double(d.frames);
  const bool spare_blobs = blobs_a_frame > double(r.markers.size()) + 0.5;
  char spare[240] = "";
  if (spare_blobs)
    std::snprintf(spare, sizeof spare,
                  " It saw %.1f blobs a frame where the rig has %zu LEDs: a light of the room, its "
                  "reflection or the glass's ghost looks like an LED. Darken the room or cover "
                  "it, and calibrate again.",
                  blobs_a_frame, r.markers.size());
  char text[1000];
  std::snprintf(text, sizeof text,
                "the detection labelled %llu markers in %llu frames (of up to %zu a frame), "
                "though it saw %llu blobs it withheld in doubt and %llu it left unlabelled: the "
                "markers were not told apart, which no motion mends.%s The labels come from the "
                "LEDs' brightness code (mirrorcal.yaml's led_brightness, in features_c's order; "
                "1 : 1.5 : 2.25 ... if absent), the rig's shape over the first seconds and the "
                "filter's prediction: check the LEDs' order and brightness against "
                "mirrorcal.yaml, the exposure (a saturated LED's flux is only a lower bound), and "
                "the priors' conventions (q_b_c_wxyz is w first; p_b_c in the IMU frame, in "
                "metres).",
                static_cast<unsigned long long>(d.labelled),
                static_cast<unsigned long long>(d.frames), r.markers.size(),
                static_cast<unsigned long long>(d.in_doubt),
                static_cast<unsigned long long>(d.unlabelled), spare);
  return text;
}

// Why a result flagged for other reasons is: the priors' q_b_c read another way fits the first
// frame far better (priors_read_another_way).
std::string quaternion_reading_warning(const CalibrationResult& r) {
  const CalibrationResult::PriorFit& f = r.prior_fit;
  char text[720];
  std::snprintf(text, sizeof text,
                "the priors' q_b_c_wxyz fits the first frame far better read %s: its %d markers "
                "lie a median %.0f px from where that reading puts them, and %.0f px as given. "
                "The quaternion's convention is most likely mistaken, and the checks below fail "
                "for that: mirrorcal.yaml's quaternions are Hamilton and w first (q_b_c_wxyz: "
                "[w, x, y, z]), and R_b_c takes the camera's vectors into the IMU frame.",
                f.better_reading, f.predictable, f.better_median_px, f.median_px);
  return text;
}

std::string prior_convention_warning(const CalibrationResult& r) {
  const CalibrationResult::PriorFit& f = r.prior_fit;
  char text[720];
  if (!priors_miss_first_frame(r)) return {};
  std::snprintf(text, sizeof text,
                "the priors put none of the first frame's %d markers near the image (%d of them "
                "with their mirror image behind the camera): they contradict the data from the "
                "start, and every later check fails for that. Check mirrorcal.yaml's "
                "conventions: quaternions are Hamilton and w first (q_n_b_wxyz, q_b_c_wxyz, not "
                "x, y, z, w), R_b_c takes the camera's vectors into the IMU frame, p_b_c is the "
                "camera in the IMU frame and features_c the markers in the camera frame, in "
                "metres, and gravity_n points down in the mirror's frame (z along its normal).",
                f.seen, f.seen - f.predictable);
  std::string warning = text;
  if (std::isfinite(f.better_median_px)) {
    std::snprintf(text, sizeof text,
                  " Read %s, q_b_c_wxyz puts them a median %.0f px from where they are.",
                  f.better_reading, f.better_median_px);
    warning += text;
  }
  return warning;
}

std::string label_swap_warning(const CalibrationResult& r) {
  if (!labels_swapped(r)) return {};
  const CalibrationResult::LabelSwap& w = r.label_swap;
  char text[600];
  std::snprintf(text, sizeof text,
                "markers %d and %d (feature_id %d and %d) look swapped in %llu of the %llu frames "
                "that showed both: in those, each one's reflection lies where the other's was in "
                "the frame before. The detection confuses them (LEDs of like brightness?) or "
                "features.csv's ids swap them, and the calibration took the swapped labels as "
                "data. Tell them apart (the brightness code in features_c's order) and calibrate "
                "again.",
                w.a, w.b, w.a, w.b, static_cast<unsigned long long>(w.frames),
                static_cast<unsigned long long>(w.both_seen));
  return text;
}

std::string markers_used_warning(const CalibrationResult& r) {
  if (!used_too_few(r)) return {};
  char text[400];
  std::snprintf(text, sizeof text,
                "the filter used %llu of the %llu markers in the data (%.1f %%): it calibrated "
                "on a sliver of the recording. Check that the frames' timestamps lie within the "
                "IMU data and in its unit (ns), and the camera's resolution.",
                static_cast<unsigned long long>(r.markers_used),
                static_cast<unsigned long long>(r.markers_observed),
                100.0 * double(r.markers_used) / double(r.markers_observed));
  return text;
}

std::string prior_warning(const CalibrationResult& r) {
  if (!prior_contradicted(r)) return {};
  char text[400];
  std::snprintf(text, sizeof text,
                "the estimate of %s lies %.1f of the prior's sigmas from its guess (more than "
                "%.0f): the prior (mirrorcal.yaml, or --from) claimed far more than it knew, and "
                "the estimate is pulled towards it. Give that guess a sigma as large as its "
                "error can be, and calibrate again.",
                r.prior_offset_state.c_str(), r.prior_offset_sigmas, kPriorContradictedSigmas);
  return text;
}

std::string imu_warning(const CalibrationResult& r) {
  char text[520];
  if (imu_not_ideal(r)) {
    const IdealImuCheck& c = r.imu.ideal_check;
    std::snprintf(text, sizeof text,
                  "the IMU is not an ideal one, as the calibration assumed (model calibrated): "
                  "with its scale factors and axes estimated, they lie a chi-square of %.1f from "
                  "an ideal IMU's (bound %.1f over %d dof), the furthest %s at %.3g +- %.2g. The "
                  "estimate has absorbed them and is off by more than its sigmas say. Calibrate "
                  "with --imu-model scale-misalignment (or imu.yaml's imu_model).",
                  c.statistic, c.bound, c.dof, c.largest_name.c_str(), c.largest_value,
                  c.largest_sigma);
    return text;
  }
  if (!imu_contradicted(r)) return {};
  std::snprintf(text, sizeof text,
                "the IMU's %s lies %.1f of its tolerance's sigmas from an ideal IMU (more than "
                "%.0f; model %s): no part is off that far, so the calibration has traded the "
                "markers' scale or the camera's pose against the IMU's scale factors and axes. "
                "Check imu.yaml's tolerances (1-sigma, 0.01 is 1 %%), move the rig through wider "
                "tilts, and calibrate again.",
                r.imu.prior_offset_name.c_str(), r.imu.prior_offset_sigmas,
                kPriorContradictedSigmas, to_string(r.imu.model));
  return text;
}

std::string scale_warning(const CalibrationResult& r) {
  if (!scale_unresolved(r)) return {};
  char text[480];
  std::snprintf(text, sizeof text,
                "the markers' size against the mirror's distance, which only the IMU's "
                "acceleration fixes, is known to %.1f %% (more than %.0f %%): the rig was hardly "
                "accelerated, and on simulated rigs like this the estimates were off by more "
                "than their sigmas say. Move the rig more briskly (quicker sweeps along and "
                "toward the mirror) and calibrate again.",
                100.0 * marker_scale_sigma(r), 100.0 * kLooseMarkerScale);
  return text;
}

// A calibration that started from one its own self-check did not trust (stage 2 from a stage 1
// that locked on, or used no marker) rests on a prior that may hold information it does not have,
// and its own checks cannot see that: its fit to the prior and the data can look as good.
std::string start_warning(const CalibrationResult& r) {
  if (!r.from_untrusted) return {};
  return "it started from an earlier calibration (--from) that said consistent: false: whatever "
         "that one got wrong with confidence, this one took as its prior. Calibrate that stage "
         "again until it is consistent, then this one from it.";
}

// A calibration that assumes an ideal IMU, started from one that estimated the IMU's intrinsics
// (stage 2 after a stage 1 with an IMU model): the IMU is a part whose scale factors and axes
// are off the ideal by more than this calibration's sigmas can hold, and stage 2 has no ideal-IMU
// check of its own.
std::string start_imu_warning(const CalibrationResult& r) {
  if (r.from_imu_model == ImuModel::kCalibrated || r.imu.estimated()) return {};
  return std::string(
             "it started from a calibration (--from) that estimated the IMU's scale "
             "factors and axes (imu model ") +
         to_string(r.from_imu_model) +
         "), and assumes an ideal IMU itself: a MEMS part's errors, which that model was chosen "
         "for, are not in its sigmas. Calibrate with the same model (--imu-model " +
         to_string(r.from_imu_model) +
         ", or imu.yaml's imu_model), which starts from the earlier calibration's intrinsics.";
}

}  // namespace

// The self-check's reasons not to trust r, each empty or its WARNING, the most telling first.
std::array<std::string, 10> self_check_reasons(const CalibrationResult& r) {
  std::array<std::string, 10> reasons = {prior_convention_warning(r),
                                         identification_warning(r),
                                         label_swap_warning(r),
                                         fit_warning(r),
                                         markers_used_warning(r),
                                         prior_warning(r),
                                         imu_warning(r),
                                         scale_warning(r),
                                         start_warning(r),
                                         start_imu_warning(r)};
  // A reading of q_b_c that fits the first frame far better names the cause of a result the
  // other reasons flag; alone it flags nothing, as a prior's guesses may be far off.
  const bool flagged =
      std::any_of(reasons.begin(), reasons.end(), [](const std::string& s) { return !s.empty(); });
  if (reasons[0].empty() && flagged && priors_read_another_way(r))
    reasons[0] = quaternion_reading_warning(r);
  return reasons;
}

std::string convergence_warning(const CalibrationResult& r) {
  for (std::string& w : self_check_reasons(r))
    if (!w.empty()) return std::move(w);
  return {};
}

double marker_scale_sigma(const CalibrationResult& r) {
  const IndexRange markers = r.layout()[CalibrationGroup::kMarkers];
  if (markers.size == 0 || r.covariance.rows() < markers.end()) return 0.0;
  Eigen::VectorXd f(markers.size);
  for (std::size_t m = 0; m < r.markers.size(); ++m)
    f.segment<3>(3 * Eigen::Index(m)) = r.markers[m];
  const double size2 = f.squaredNorm();
  if (!(size2 > 0.0)) return 0.0;
  const Eigen::MatrixXd p =
      r.covariance.block(markers.begin, markers.begin, markers.size, markers.size);
  return std::sqrt(std::max(0.0, f.dot(p * f))) / size2;
}

bool consistent(const CalibrationResult& r) {
  return convergence_warning(r).empty();
}

std::string skew_warning(const CalibrationResult& r) {
  if (r.estimated_intrinsics != 5) return {};
  // fu fv cu cv skew
  const auto j = std::size_t(r.layout()[CalibrationGroup::kIntrinsics].begin + 4);
  const double sigma = j < r.sigma.size() ? r.sigma[j] : 0.0;
  if (!(std::abs(r.intrinsics.skew) > kSignificantSkewSigmas * sigma)) return {};
  char text[400];
  std::snprintf(text, sizeof text,
                "the estimated skew, %.3f px +- %.3f px, is significant (beyond %.0f sigma from "
                "0): Kalibr, OpenVINS and VINS-Fusion have no skew and will use the camera "
                "without it (camchain-imucam.yaml states it in a comment). If the camera has "
                "none, calibrate with --hold-skew.",
                r.intrinsics.skew, sigma, kSignificantSkewSigmas);
  return text;
}

std::vector<std::string> result_warnings(const CalibrationResult& r) {
  std::vector<std::string> w;
  for (std::string& s : self_check_reasons(r))
    if (!s.empty()) w.push_back(std::move(s));
  if (std::string s = skew_warning(r); !s.empty()) w.push_back(std::move(s));
  return w;
}

static void write_noise_estimate(std::FILE* o, const NoiseEstimate& n) {
  if (!n.estimated) return;
  std::fprintf(o,
               "noise_estimate:  # from the data (noise_estimate.hpp) and used by the calibration; "
               "each with its 1-sigma, beside what imu.yaml and mirrorcal.yaml stated\n");
  std::fprintf(o, "  gyroscope_noise_density: %.9g  # rad/s/sqrt(Hz)\n", n.imu.gyro_noise_density);
  std::fprintf(o, "  gyroscope_noise_density_sigma: %.3g\n", n.gyro_density_sigma);
  std::fprintf(o, "  gyroscope_noise_density_stated: %.9g\n", n.told.gyro_noise_density);
  std::fprintf(o, "  accelerometer_noise_density: %.9g  # m/s^2/sqrt(Hz)\n",
               n.imu.accel_noise_density);
  std::fprintf(o, "  accelerometer_noise_density_sigma: %.3g\n", n.accel_density_sigma);
  std::fprintf(o, "  accelerometer_noise_density_stated: %.9g\n", n.told.accel_noise_density);
  std::fprintf(
      o,
      "  densities_estimated: [%s, %s]  # gyroscope, accelerometer; false: the samples' "
      "noise is not white from sample to sample (a low-pass filter in the part?), the "
      "stated density kept\n"
      "  stride2_ratio: [%.3f, %.3f]  # the test: the density over every other sample over "
      "the one from sample to sample, 1 for white noise (within 5 %%)\n",
      n.gyro_estimated ? "true" : "false", n.accel_estimated ? "true" : "false",
      n.gyro_stride2_ratio, n.accel_stride2_ratio);
  std::fprintf(o, "  pixel_sigma: %.6g  # px\n", n.pixel_sigma);
  std::fprintf(o, "  pixel_sigma_sigma: %.3g\n", n.pixel_sigma_sigma);
  std::fprintf(o, "  pixel_sigma_stated: %.6g\n", n.told_pixel_sigma);
  std::fprintf(o,
               "  random_walks: stated  # 60 s hardly see them: imu.yaml's, as given\n"
               "  imu_differences: %llu  # fourth differences of the samples the densities rest "
               "on\n  pixel_redundancy: %.1f  # degrees of freedom of the pixel noise's estimate\n"
               "  calibrations: %d  # made with the estimates until the pixel noise settled\n"
               "  converged: %s\n",
               static_cast<unsigned long long>(n.imu_differences), n.pixel_redundancy,
               n.refinements, n.converged ? "true" : "false");
}

bool write_result_yaml(io::OutputSet& out, const std::string& path, const CalibrationResult& r,
                       std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  std::fprintf(o,
               "# mirrorcal result: SI units (m, rad, px); sigma is 1-sigma, rotations as the\n"
               "# components of the error vector log(R_b_c,true^T R_b_c,estimated)\n"
               "# written by %s\n",
               io::written_by().c_str());
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
  const bool lens_estimated = r.estimated_intrinsics == 8;
  std::fprintf(o, "distortion_model: %s  # %s\n", to_string(r.intrinsics.distortion),
               lens_estimated ? "as camchain.yaml gave it, its coefficients estimated"
                              : "held as camchain.yaml gave it");
  std::fprintf(o, "distortion_coeffs: [%.17g, %.17g, %.17g, %.17g]\n", r.intrinsics.coeffs[0],
               r.intrinsics.coeffs[1], r.intrinsics.coeffs[2], r.intrinsics.coeffs[3]);
  if (lens_estimated) {
    const std::array<const char*, 4> names = distortion_coeff_names(r.intrinsics.distortion);
    std::fprintf(o, "distortion_estimate:  # distortion_coeffs by name; 1-sigma under sigma\n");
    for (std::size_t j = 0; j < 4; ++j)
      std::fprintf(o, "  %s: %.17g\n", names[j], r.intrinsics.coeffs[j]);
  }
  std::fprintf(o, "line_delay: %.17g  # s per row, held as camchain.yaml gave it\n",
               r.intrinsics.line_delay_s);
  std::fprintf(o, "exposure_time: %.17g  # s, held as camchain.yaml gave it\n",
               r.intrinsics.exposure_s);
  std::fprintf(o,
               "intrinsics_estimated: %s\nskew_estimated: %s\ndistortion_estimated: %s\n"
               "resolution: [%d, %d]\n",
               r.estimated_intrinsics > 0 ? "true" : "false",
               r.estimated_intrinsics == 5 ? "true" : "false", lens_estimated ? "true" : "false",
               r.width, r.height);
  std::fprintf(o, "rostopic: %s\n", r.rostopic.c_str());
  if (!r.recording_fingerprint.empty())
    std::fprintf(o, "recording_fingerprint: \"%s\"  # of the data calibrated (calibrate --from)\n",
                 r.recording_fingerprint.c_str());
  std::fprintf(o, "passes: %d", r.passes);
  if (r.restarted_pass > 0)
    std::fprintf(o, "  # pass %d restarted from the guesses, the pixel noise inflated: locked on",
                 r.restarted_pass);
  std::fprintf(o,
               "\nmarkers_used: %llu\nmarkers_gated: %llu  # in the last pass\n"
               "markers_invalid: %llu  # once the gate is on: behind the camera\n",
               static_cast<unsigned long long>(r.markers_used),
               static_cast<unsigned long long>(r.markers_gated),
               static_cast<unsigned long long>(r.markers_invalid));
  if (r.markers_observed > 0)
    std::fprintf(o, "markers_observed: %llu  # in the data the loop was given\n",
                 static_cast<unsigned long long>(r.markers_observed));
  if (!r.markers_screened.empty()) {
    std::fprintf(o, "markers_screened: [");
    for (std::size_t i = 0; i < r.markers_screened.size(); ++i)
      std::fprintf(o, "%s%llu", i > 0 ? ", " : "",
                   static_cast<unsigned long long>(r.markers_screened[i]));
    std::fprintf(o,
                 "]  # per marker, last pass: withheld before the filter, their step against the "
                 "other markers' or their residual at the refined solution (a wrong blob or "
                 "label)\n");
  }
  if (!r.prior_offset_state.empty())
    std::fprintf(o, "prior_offset: %.2f  # sigmas of the prior, at its furthest: %s\n",
                 r.prior_offset_sigmas, r.prior_offset_state.c_str());
  std::fprintf(o,
               "nis_per_dof: %.4f  # last pass, gate on: about 1 when the covariance is right\n"
               "sigma_ratio: %.4f  # the filter's own sigmas against those reported, at least\n"
               "refinement_step: %.4f  # the last Gauss-Newton step, in sigmas: well under 1 "
               "when converged\n",
               r.nis_per_dof, r.sigma_ratio, r.refinement_step_sigmas);
  if (r.refinement_refused)
    std::fprintf(o,
                 "refinement_refused: true  # no Gauss-Newton step taken: the free passes' "
                 "estimate and sigmas\n");
  std::fprintf(o,
               "marker_scale_sigma: %.4f  # the markers' common scale, relative 1-sigma: only "
               "the IMU's acceleration fixes it\n",
               marker_scale_sigma(r));
  std::fprintf(o,
               "consistent: %s  # false: more than 0.5 %% of the markers gated, nis_per_dof well "
               "above 1, sigma_ratio below %g, refinement_step above %g or no refinement step, "
               "under half the markers "
               "used, a prior or the IMU's tolerances contradicted by 5 sigma, marker_scale_sigma "
               "above %g, priors that put no marker of the first frame near the image or a start "
               "(--from) that said false: do not trust it\n",
               consistent(r) ? "true" : "false", kSigmaRatioLimit, kRefinementStepLimit,
               kLooseMarkerScale);
  write_imu_result_yaml(o, r.imu);
  write_noise_estimate(o, r.noise);
  std::fprintf(o, "sigma:\n");
  for (std::size_t j = 0; j < r.params.size(); ++j)
    std::fprintf(o, "  %s: %.9g\n", r.params[j].name.c_str(), r.sigma[j]);
  std::fprintf(o, "# covariance of the calibration states, rows and columns in sigma's order\n");
  std::fprintf(o, "covariance:\n");
  write_matrix_rows(o, r.covariance, "  ", true);
  return true;
}

namespace {

// VINS-Fusion's camera file (camodocal's PINHOLE, or KANNALA_BRANDT for an equidistant lens).
void write_vins_camera(std::FILE* o, const CalibrationResult& r) {
  const Pinhole<double>& k = r.intrinsics;
  const std::array<double, 4>& d = k.coeffs;
  write_yaml_header(o, "mirrorcal calibration: VINS-Fusion camera file (camodocal)");
  write_skew_note(o, k, "", "VINS-Fusion's camera models have no skew and drop it");
  const bool fisheye = k.distortion == Distortion::kEquidistant;
  std::fprintf(o, "model_type: %s\ncamera_name: camera\nimage_width: %d\nimage_height: %d\n",
               fisheye ? "KANNALA_BRANDT" : "PINHOLE", r.width, r.height);
  if (fisheye) {
    // Kannala-Brandt's theta + k2 theta^3 + ... + k5 theta^9 is Kalibr's equidistant k1..k4.
    std::fprintf(o, "projection_parameters:\n   k2: %.12g\n   k3: %.12g\n   k4: %.12g\n", d[0],
                 d[1], d[2]);
    std::fprintf(o, "   k5: %.12g\n   mu: %.6f\n   mv: %.6f\n   u0: %.6f\n   v0: %.6f\n", d[3],
                 k.fu, k.fv, k.cu, k.cv);
    return;
  }
  std::fprintf(o,
               "distortion_parameters:\n   k1: %.12g\n   k2: %.12g\n   p1: %.12g\n"
               "   p2: %.12g\n",
               d[0], d[1], d[2], d[3]);
  std::fprintf(o, "projection_parameters:\n   fx: %.6f\n   fy: %.6f\n   cx: %.6f\n   cy: %.6f\n",
               k.fu, k.fv, k.cu, k.cv);
}

// The camera-IMU keys of a VINS-Fusion config; camera_file as cam0_calib names it (beside it).
void write_vins_config(std::FILE* o, const CalibrationResult& r, const std::string& camera_file) {
  write_yaml_header(o, "mirrorcal calibration: the camera-IMU keys of a VINS-Fusion config");
  std::fprintf(o,
               "# (add the IMU noise and feature tracker keys of a VINS-Fusion example config)\n");
  std::fprintf(o, "imu: 1\nnum_of_cam: 1\nimage0_topic: \"%s\"\ncam0_calib: \"%s\"\n",
               r.rostopic.c_str(), camera_file.c_str());
  std::fprintf(o, "image_width: %d\nimage_height: %d\n", r.width, r.height);
  std::fprintf(o,
               "# the camera's pose in the IMU (body) frame: p_imu = body_T_cam0 p_cam\n"
               "estimate_extrinsic: 0\nbody_T_cam0: !!opencv-matrix\n   rows: 4\n   cols: 4\n"
               "   dt: d\n   data: [");
  const Eigen::Matrix4d t = t_imu_cam(r);
  for (int i = 0; i < 16; ++i)
    std::fprintf(o, "%s%.12f", i == 0 ? "" : i % 4 == 0 ? ",\n           " : ", ", t(i / 4, i % 4));
  std::fprintf(o, "]\n# s: t_imu = t_cam + td (Kalibr's timeshift_cam_imu)\n");
  std::fprintf(o, "estimate_td: 0\ntd: %.9f\n", r.t_d);
}

void write_ros_matrix(std::FILE* o, const char* key, int rows, int cols, const double* v) {
  std::fprintf(o, "%s:\n  rows: %d\n  cols: %d\n  data: [", key, rows, cols);
  for (int i = 0; i < rows * cols; ++i) std::fprintf(o, "%s%.12g", i == 0 ? "" : ", ", v[i]);
  std::fprintf(o, "]\n");
}

// ROS's camera_info as camera_calibration_parsers reads it; K holds the skew.
void write_ros_camera_info(std::FILE* o, const CalibrationResult& r) {
  const Pinhole<double>& k = r.intrinsics;
  std::fprintf(o, "# mirrorcal calibration: ROS camera_info (camera_calibration_parsers)\n");
  std::fprintf(o, "# written by %s\n", io::written_by().c_str());
  std::fprintf(o, "image_width: %d\nimage_height: %d\ncamera_name: cam0\n", r.width, r.height);
  const double kk[9] = {k.fu, k.skew, k.cu, 0.0, k.fv, k.cv, 0.0, 0.0, 1.0};
  write_ros_matrix(o, "camera_matrix", 3, 3, kk);
  // plumb_bob is k1 k2 p1 p2 k3 (radtan with k3 = 0); equidistant is k1..k4.
  const bool fisheye = k.distortion == Distortion::kEquidistant;
  std::fprintf(o, "distortion_model: %s\n", fisheye ? "equidistant" : "plumb_bob");
  const double d[5] = {k.coeffs[0], k.coeffs[1], k.coeffs[2], k.coeffs[3], 0.0};
  write_ros_matrix(o, "distortion_coefficients", 1, fisheye ? 4 : 5, d);
  const double identity[9] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  write_ros_matrix(o, "rectification_matrix", 3, 3, identity);
  const double p[12] = {k.fu, k.skew, k.cu, 0.0, 0.0, k.fv, k.cv, 0.0, 0.0, 0.0, 1.0, 0.0};
  write_ros_matrix(o, "projection_matrix", 3, 4, p);
}

}  // namespace

bool export_format_from_string(const std::string& name, ExportFormat& format) {
  if (name == "openvins")
    format = ExportFormat::kOpenVins;
  else if (name == "vins-fusion")
    format = ExportFormat::kVinsFusion;
  else if (name == "ros-camera-info")
    format = ExportFormat::kRosCameraInfo;
  else
    return false;
  return true;
}

std::string vins_camera_file(const std::string& config_path) {
  const std::filesystem::path p(config_path);
  return (p.parent_path() / (p.stem().string() + "_cam0.yaml")).string();
}

bool write_export(ExportFormat format, const std::string& path, const CalibrationResult& r,
                  std::string& error, bool untrusted) {
  io::OutputSet out;
  if (format == ExportFormat::kVinsFusion) {
    std::FILE* camera = out.add(vins_camera_file(path), error);
    if (camera == nullptr) return false;
    write_vins_camera(camera, r);
  }
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  switch (format) {
    case ExportFormat::kOpenVins:
      write_yaml_header(o, "mirrorcal calibration: OpenVINS kalibr_imucam_chain.yaml");
      write_imucam_chain(o, r, true);
      break;
    case ExportFormat::kVinsFusion:
      write_vins_config(o, r, std::filesystem::path(vins_camera_file(path)).filename().string());
      break;
    case ExportFormat::kRosCameraInfo:
      write_ros_camera_info(o, r);
      break;
  }
  // At the end: VINS-Fusion's reader (OpenCV's FileStorage) wants its %YAML line first.
  if (untrusted)
    write_distrust_comment(o,
                           "Exported with --force from a mirrorcal-result.yaml that says so (its "
                           "report.txt and WARNINGs say why).");
  return out.commit(error);
}

template <class Filter>
bool write_estimates_csv(io::OutputSet& out, const std::string& path,
                         const RecordStore<HistoryRow<Filter>>& rows, Distortion lens,
                         std::string& error) {
  using State = typename Filter::State;
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  const auto params = calibration_params(State::kMarkers, State::kIntrinsics, lens);
  std::fprintf(o, "#time [s],p_x [m],p_y [m],p_z [m],q_w,q_x,q_y,q_z");
  for (int i = 0; i < State::kMarkers; ++i)
    for (const char* a : {"x", "y", "z"}) std::fprintf(o, ",f%d_%s [m]", i + 1, a);
  std::fprintf(o, ",timeshift_cam_imu [s]");
  const auto first_intrinsic =
      std::size_t(State::kCalibration[CalibrationGroup::kIntrinsics].begin);
  const auto si_unit = [](const ParamInfo& p) {
    return p.unit == "cm"     ? "m"
           : p.unit == "deg"  ? "rad"
           : p.unit == "ms"   ? "s"
           : p.unit == "1e-3" ? "-"
                              : "px";
  };
  for (std::size_t j = first_intrinsic; j < params.size(); ++j)
    std::fprintf(o, ",%s [%s]", params[j].name.c_str(), si_unit(params[j]));
  for (const auto& p : params) std::fprintf(o, ",sigma_%s [%s]", p.name.c_str(), si_unit(p));
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

template <class Filter>
bool write_features_csv(io::OutputSet& out, const std::string& path,
                        const RecordStore<HistoryRow<Filter>>& rows, std::string& error) {
  std::FILE* o = out.add(path, error);
  if (o == nullptr) return false;
  std::fprintf(o, "%s\n", io::kFeaturesHeader);
  for (const auto& r : rows)
    for (std::size_t i = 0; i < r.seen.size(); ++i) {
      if (!r.seen[i]) continue;
      char line[128];
      char* p = line;
      char* const end = line + sizeof line - 1;
      p = std::to_chars(p, end, r.t_ns).ptr;
      *p++ = ',';
      p = std::to_chars(p, end, i).ptr;
      *p++ = ',';
      p = std::to_chars(p, end, r.measured[i].x()).ptr;
      *p++ = ',';
      p = std::to_chars(p, end, r.measured[i].y()).ptr;
      *p++ = '\n';
      std::fwrite(line, 1, std::size_t(p - line), o);
    }
  return true;
}

// For every filter the product instantiates (run.hpp).
#define MIRRORCAL_RESULT_CSV_(M, NK, NI)                                                   \
  template bool write_features_csv(                                                        \
      io::OutputSet&, const std::string&,                                                  \
      const RecordStore<HistoryRow<CalibrationFilter<double, M, NK, NI>>>&, std::string&); \
  template bool write_estimates_csv(                                                       \
      io::OutputSet&, const std::string&,                                                  \
      const RecordStore<HistoryRow<CalibrationFilter<double, M, NK, NI>>>&, Distortion,    \
      std::string&);
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_RESULT_CSV_)
#undef MIRRORCAL_RESULT_CSV_

}  // namespace mirrorcal::calibration
