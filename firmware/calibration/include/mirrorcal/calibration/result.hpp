// Files users and other tools read (docs/design.md, "File formats").
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "mirrorcal/calibration/history.hpp"
#include "mirrorcal/calibration/imu_result.hpp"
#include "mirrorcal/calibration/noise_estimate.hpp"
#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/io/files.hpp"
#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::calibration {

// A final calibration, in SI units, with 1-sigma from the filter.
struct CalibrationResult {
  Eigen::Vector3d p_b_c = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_b_c = Eigen::Quaterniond::Identity();
  std::vector<Eigen::Vector3d> markers;
  double t_d = 0.0;  // timeshift_cam_imu (s)
  Pinhole<double> intrinsics{};
  // 0, 4 (fu fv cu cv; skew held), 5 (with skew) or 8 (fu fv cu cv and the lens's coefficients)
  int estimated_intrinsics = 0;
  int width = 0, height = 0;
  std::string rostopic = io::kDefaultCameraTopic;  // camchain.yaml's, for Kalibr and OpenVINS
  std::string recording_fingerprint;  // of the recording calibrated (none for a simulation)
  std::vector<double> sigma;          // calibration block, in calibration_params() order (SI)
  Eigen::MatrixXd covariance;         // of the calibration block, same order
  std::vector<ParamInfo> params;
  // Over the last pass: markers used, gated, and those the model could not predict at the
  // estimate (their mirror image not in front of the camera).
  std::uint64_t markers_used = 0, markers_gated = 0, markers_invalid = 0;
  // Each marker's frames in the last pass whose reflection was withheld before the filter: its
  // step disagreed with the other markers' (a wrong blob or label; loop::MarkerScreen), or
  // the refinement found it an outlier at its converged solution (run.cpp, find_outliers).
  std::vector<std::uint64_t> markers_screened;
  std::uint64_t filter_failures = 0;  // predicts or updates the filter refused (numerically)
  int passes = 1;                     // passes over the data (run.hpp)
  bool from_untrusted = false;  // started from an earlier calibration that said consistent: false
  // The IMU model of the calibration it started from (--from): one with intrinsics found the IMU
  // a MEMS part, which a calibration assuming an ideal IMU (stage 2) cannot account for.
  ImuModel from_imu_model = ImuModel::kCalibrated;
  int restarted_pass = 0;  // 1-based; the pass restarted from the guesses (run.hpp), or 0
  // What the filter saw itself, for the self-check (no truth needed): the normalised innovation
  // squared per degree of freedom over the last pass once the gate was on.
  double nis_per_dof = 0.0;
  std::uint64_t nis_dof = 0;
  // The smallest ratio, over the calibration states, of the filter's own sigma to the reported
  // one, linearised along the final estimate (run.cpp): about 1 when the filter's path left
  // no false information.
  double sigma_ratio = 1.0;
  // The last Gauss-Newton step of the refinement (run.cpp), the distance it moved the
  // calibration in the reported covariance's sigmas (Mahalanobis): well under one when the
  // iteration has converged; 0 without a refinement.
  double refinement_step_sigmas = 0.0;
  // The refinement took no step (its replay met other frames than the passes', or fitted worse
  // than they did): the free passes' own estimate and sigmas are reported.
  bool refinement_refused = false;
  // Markers in the frames the loop was given (each pass offers them all; 0: detected on the fly).
  std::uint64_t markers_observed = 0;
  // What detection in the images did over the last pass (calibrate from images, sim --frames):
  // its frames, the markers it labelled, and the blobs it withheld in doubt or left unlabelled.
  // All 0 when the markers came labelled (features.csv, a simulation without frames).
  struct DetectionCounts {
    std::uint64_t frames = 0, labelled = 0, in_doubt = 0, unlabelled = 0;
  } detection;
  // The pair of markers whose labels look swapped most often over the last pass: in how many of
  // the frames that showed both (and the frame before) each one's reflection lies where the
  // other's was (record_label_swaps, run.cpp). a < 0: no frame did.
  struct LabelSwap {
    int a = -1, b = -1;
    std::uint64_t frames = 0, both_seen = 0;
  } label_swap;
  // The first frame against the priors' guess (record_prior_fit, run.cpp): the markers it showed,
  // those the guess could predict (their mirror image in front of the camera), and those it put
  // within an image's size of the image; the median distance of the predicted from the measured
  // (px), and the same with the priors' q_b_c read another way (its components x, y, z, w; its
  // conjugate, R_c_b; both) where one of those fits better than the priors as given.
  struct PriorFit {
    int seen = 0, predictable = 0, near_image = 0;
    double median_px = INFINITY;
    const char* better_reading = nullptr;  // a string literal; none fits better: nullptr
    double better_median_px = INFINITY;
  } prior_fit;
  // The calibration state the estimate lies furthest from its prior guess, in the prior's sigmas.
  double prior_offset_sigmas = 0.0;
  std::string prior_offset_state;
  // The IMU: its model and, when estimated, its intrinsics (outside the calibration block).
  ImuResult imu;
  // The noise levels estimated from the data, when asked (Passes::estimate_noise).
  NoiseEstimate noise;

  // Where sigma's and covariance's groups lie.
  CalibrationLayout layout() const {
    return calibration_layout(static_cast<int>(markers.size()), estimated_intrinsics);
  }
};

// The j-th camera parameter a result estimated (fu fv cu cv, then skew, or the lens's four
// coefficients when estimated_intrinsics is 8), as the calibration block orders them.
inline double estimated_camera_parameter(const CalibrationResult& r, int j) {
  const Pinhole<double>& k = r.intrinsics;
  const double fc[4] = {k.fu, k.fv, k.cu, k.cv};
  if (j < 4) return fc[j];
  return r.estimated_intrinsics == 8 ? k.coeffs[static_cast<std::size_t>(j - 4)] : k.skew;
}

// The self-check's thresholds below: docs/usage.md, "The self-check", says how each was set.
//
// A filter that calibrated consistently rejects about 0.1 % of the markers at its 99.9 % gate. One
// that rejected more than kSuspectGatedFraction, five times that, has most likely locked onto a
// wrong solution; good runs stay well below it. Such a pass is followed by another (run.hpp,
// Passes); a result that still gated too many is flagged. Tested by
// Cli.ARunThatDivergedIsFlaggedInTheOutputAndTheResult (tests/app/cli_test.cpp).
constexpr double kSuspectGatedFraction = 0.005;
// More than kSuspectGatedFraction of the markers offered to the filter were gated or could not be
// predicted at all (an estimate that puts them behind the camera is as lost).
bool gated_too_many(const CalibrationResult& r);
// The markers the filter used fit worse than its covariance says: the last pass's normalised
// innovation squared per degree of freedom above 1 + max(kSuspectNisExcess, 5 sqrt(2 / dof)) (a
// consistent filter's is within a few hundredths of 1, a little below it as the gate cuts the
// tail; 5 sqrt(2 / dof) is five standard deviations of a chi-square's mean, for short runs). It
// catches runs locked onto a wrong solution, not merely over-confident ones, which fit as well as
// good runs. Tested by Cli.ASecondPassThatFitsBadlyIsFollowedByAnother (cli_test.cpp).
constexpr double kSuspectNisExcess = 0.05;
bool innovations_too_large(const CalibrationResult& r);
// Any of the above, or a filter that refused predicts or updates as numerically broken (none does
// in a good run): the result should not be trusted, and another pass is worth making.
bool suspect(const CalibrationResult& r);
// The filter's own covariance was well below the one linearised along its final estimate: its
// path through early estimates gathered information the data do not hold, and its estimate is
// likely off by more than its sigmas. A good run's ratio is near 1, but the refinement's last step
// takes the measurement's Jacobian (run.hpp, kTangentAlphaScale), whose covariance is a little
// wider than the regression's, so good runs reach well below it; the limit sits where runs stop
// being consistent, and a higher one flags good runs. Tested by
// Cli.ARunThatGainedFalseInformationIsFlagged (cli_test.cpp).
constexpr double kSigmaRatioLimit = 0.3;
bool path_gained_false_information(const CalibrationResult& r);
// The refinement's last Gauss-Newton step (the one at the measurement's Jacobian, run.hpp) still
// moved the calibration by more than kRefinementStepLimit sigmas: the regression's and the
// Jacobian's linearisations disagree by more than the estimate's uncertainty, the posterior is
// not the Gaussian the covariance describes, and neither estimate nor covariance can be trusted.
// A converged iteration's last step is a fraction of a sigma; the limit leaves room for the
// longest good ones. Or the refinement took no step at all (refinement_refused): the free passes'
// estimate stands. Tested by Cli.ARefinementThatHasNotConvergedIsFlagged (cli_test.cpp).
constexpr double kRefinementStepLimit = 3.0;
bool refinement_unconverged(const CalibrationResult& r);
// The filter used under kMinUsedFraction of the markers in the data (the loop skipped the rest:
// frames at times the IMU data do not cover, markers outside the image): it calibrated on a
// sliver of the recording; good runs use nearly all. Tested by
// Cli.ARunThatUsedFewOfTheMarkersObservedIsFlagged (cli_test.cpp).
constexpr double kMinUsedFraction = 0.5;
bool used_too_few(const CalibrationResult& r);
// The estimate lies beyond kPriorContradictedSigmas of the prior's sigmas from its guess in some
// calibration state: the prior claimed far more than it knew, and the estimate, pulled towards
// it, is off by more than its own sigmas say. Guesses drawn from the priors as stated stay well
// inside the limit. Tested by Cli.APriorContradictedByTheDataIsFlagged (cli_test.cpp: p_b_c
// 2 cm off with a 1 mm sigma).
constexpr double kPriorContradictedSigmas = 5.0;
bool prior_contradicted(const CalibrationResult& r);
// The IMU's intrinsics lie beyond kPriorContradictedSigmas of their tolerances from the ideal IMU:
// the estimate has traded the markers' scale or the camera's pose against an IMU no part is (its
// scale factors far from 1 with the markers scaled to match, which every other check passes), or
// imu.yaml's tolerances are far too tight (docs/scenarios.md, "The mems family").
bool imu_contradicted(const CalibrationResult& r);
// A calibration that assumed an ideal IMU (model calibrated) on data that say otherwise: its
// ideal-IMU check (imu_result.hpp, IdealImuCheck) found the scale factors and axes beyond an
// ideal IMU's scatter. The estimate has absorbed them, and is off by more than its sigmas say.
bool imu_not_ideal(const CalibrationResult& r);
// The markers' common scale (marker_scale_sigma) known only to worse than kLooseMarkerScale: the
// motion hardly accelerated the rig, and the estimate is neither as good as the data nor as its
// sigmas say. The NEES hides it (the error lies along one direction), so the scale's own sigma
// is checked; only slow sweeps lie beyond the limit. Tested by
// Report.ExcitationSaysHowWellTheMarkersScaleIsKnown (tests/calibration/report_test.cpp).
constexpr double kLooseMarkerScale = 0.04;
bool scale_unresolved(const CalibrationResult& r);
// Detection in the images saw blobs but labelled few markers: fewer than kMinLabelledShare of
// the M a frame can show, while the blobs it withheld or left unlabelled outnumber them. The
// identification failed (a brightness code not in id order, identical LEDs, a prior of the wrong
// convention), not the motion; the calibration rests on a handful of markers, perhaps mislabelled.
constexpr double kMinLabelledShare = 0.25;
bool identification_failed(const CalibrationResult& r);
// Two markers' labels swapped in more than kSwappedShare of the frames showing both (and in at
// least kMinSwappedFrames): a detection that confuses them, or features.csv's ids. A frame counts
// when each reflection lies where the other's was in the frame before (run.cpp,
// record_label_swaps), its own step beyond kSwapResidualSigmas of the pixel noise.
constexpr double kSwappedShare = 0.01;
constexpr std::uint64_t kMinSwappedFrames = 5;
constexpr double kSwapResidualSigmas = 3.0;
bool labels_swapped(const CalibrationResult& r);
// The priors' guess put none of the first frame's markers within an image's size of the image:
// the priors contradict the data from the start (a quaternion given x, y, z, w; a transform
// inverted), which no motion mends.
bool priors_miss_first_frame(const CalibrationResult& r);
// Read another way (x, y, z, w; conjugated), the priors' q_b_c puts the first frame's markers
// within kConventionFitShare of the distance the priors as given leave, and that distance is
// beyond kConventionMinPx: a convention mistaken, though the markers land in the image. It names
// the cause of a result flagged for other reasons, and flags none itself.
constexpr double kConventionFitShare = 0.5;
constexpr double kConventionMinPx = 20.0;
bool priors_read_another_way(const CalibrationResult& r);
// Empty, or why the result should not be trusted and what to do (the first of these reasons;
// result_warnings gives each).
std::string convergence_warning(const CalibrationResult& r);
// No reason not to trust the result (mirrorcal-result.yaml's `consistent`).
bool consistent(const CalibrationResult& r);
// Empty, or that the estimated skew is significant (beyond kSignificantSkewSigmas of its sigmas
// from 0) and that Kalibr, OpenVINS and VINS-Fusion, which have no skew, will drop it.
constexpr double kSignificantSkewSigmas = 3.0;
std::string skew_warning(const CalibrationResult& r);
// The relative 1-sigma of the markers' common scale about the camera, all markers scaled
// together: sqrt(f^T P f) / |f|^2, f the markers stacked, P their block of the covariance. The
// mirror images fix the markers' directions; their size against the mirror's distance only the
// IMU's acceleration fixes, so slow motion leaves this the least known direction. 0 when there
// are no markers or no covariance.
double marker_scale_sigma(const CalibrationResult& r);
// Every warning a user of the result should read (the filter's fit, the markers used, the prior,
// the skew).
std::vector<std::string> result_warnings(const CalibrationResult& r);

template <class Filter>
CalibrationResult make_result(const Filter& f, int width, int height) {
  using State = typename Filter::State;
  CalibrationResult r;
  const State& x = f.state();
  r.p_b_c = x.p_b_c.template cast<double>();
  r.q_b_c = x.q_b_c.template cast<double>();
  for (int i = 0; i < State::kMarkers; ++i)
    r.markers.push_back(x.marker(i).template cast<double>());
  r.t_d = double(x.t_d);
  r.intrinsics = f.intrinsics().template cast<double>();
  r.estimated_intrinsics = State::kIntrinsics;
  r.width = width;
  r.height = height;
  constexpr int B = State::kCalibrationBegin, L = State::kCalibrationDim;
  for (int j = B; j < B + L; ++j) r.sigma.push_back(std::sqrt(double(f.covariance()(j, j))));
  r.covariance = f.covariance().template block<L, L>(B, B).template cast<double>();
  r.params = calibration_params(State::kMarkers, State::kIntrinsics, r.intrinsics.distortion);
  r.markers_used = f.counters().markers_used;
  r.nis_dof = f.counters().nis_dof;
  r.nis_per_dof = r.nis_dof > 0 ? f.counters().nis_sum / double(r.nis_dof) : 0.0;
  r.markers_gated = f.counters().markers_gated;
  r.markers_invalid = f.counters().markers_invalid;
  r.filter_failures = f.counters().failures;
  r.imu.model = State::kImuModel;
  r.imu.noise = f.config().imu;
  r.imu.accel_bias = x.b_a.template cast<double>();
  r.imu.gyro_bias = x.b_g.template cast<double>();
  for (int i = 0; i < 3; ++i) {
    r.imu.accel_bias_sigma(i) = std::sqrt(double(f.covariance()(State::kBa + i, State::kBa + i)));
    r.imu.gyro_bias_sigma(i) = std::sqrt(double(f.covariance()(State::kBg + i, State::kBg + i)));
  }
  r.imu.gravity_n = f.config().gravity_n;
  if constexpr (State::kImuIntrinsics > 0) {
    r.imu.intrinsics = x.imu.template cast<double>();
    constexpr int K = State::kImu, NI = State::kImuIntrinsics;
    for (int j = K; j < K + NI; ++j) r.imu.sigma.push_back(std::sqrt(double(f.covariance()(j, j))));
    r.imu.covariance.resize(NI, L + NI);
    r.imu.covariance << f.covariance().template block<NI, L>(K, B).template cast<double>(),
        f.covariance().template block<NI, NI>(K, K).template cast<double>();
  }
  return r;
}

// The YAML files' first lines, which PyYAML, OpenCV's FileStorage and yaml-cpp all read (a %YAML
// directive, a document start and a comment saying what the file is), and a matrix as a list of
// its rows (as Kalibr writes T_cam_imu and OpenVINS reads it).
void write_yaml_header(std::FILE* o, const char* what);
// Twelve decimals, or to the last bit with exact (%.17g: covariances, which span many orders of
// magnitude).
void write_matrix_rows(std::FILE* f, const Eigen::MatrixXd& m, const char* indent,
                       bool exact = false);

// Kalibr's camchain-imucam.yaml: T_cam_imu maps IMU coordinates into the camera's. Read unmodified
// by Kalibr (PyYAML) and OpenVINS (OpenCV's FileStorage) alike. A calibration that says
// consistent: false says so in comments at its top, with why.
// The writers add their file to out, which writes it when committed (files.hpp); false,
// with a message naming the file, if it cannot be created.
bool write_camchain_imucam(io::OutputSet& out, const std::string& path, const CalibrationResult& r,
                           std::string& error);

// What `mirrorcal export` writes for other tools to read directly.
enum class ExportFormat {
  kOpenVins,       // kalibr_imucam_chain.yaml with OpenVINS's T_imu_cam
  kVinsFusion,     // the camera-IMU keys of a VINS-Fusion config, and its camera file
  kRosCameraInfo,  // a ROS camera_info YAML (camera_calibration_parsers)
};
bool export_format_from_string(const std::string& name, ExportFormat& format);
// VINS-Fusion's camera file, written beside its config at config_path: "<stem>_cam0.yaml".
std::string vins_camera_file(const std::string& config_path);
// Writes the file (and VINS-Fusion's camera file) whole or not at all; untrusted: r said
// consistent: false and is exported anyway (a comment says so).
bool write_export(ExportFormat format, const std::string& path, const CalibrationResult& r,
                  std::string& error, bool untrusted = false);
// Everything estimated with its 1-sigma and the covariance of the calibration block; the estimate
// and covariance in full precision, so that `calibrate --from` starts exactly where this ended.
bool write_result_yaml(io::OutputSet& out, const std::string& path, const CalibrationResult& r,
                       std::string& error);

// estimates.csv: time and every calibration state with its 1-sigma (SI units, rotation as the
// quaternion q_b_c with the 1-sigma of its error vector's components); lens names the distortion
// coefficients a stage 2 with estimate_distortion estimates.
template <class Filter>
bool write_estimates_csv(io::OutputSet& out, const std::string& path,
                         const RecordStore<HistoryRow<Filter>>& rows, Distortion lens,
                         std::string& error);

// The markers each row's frame gave the filter, as a recording's features.csv (its header, the
// frame's timestamp, numbers that read back as the same doubles): what calibrate found in a
// recording's images, to check or to calibrate from again.
template <class Filter>
bool write_features_csv(io::OutputSet& out, const std::string& path,
                        const RecordStore<HistoryRow<Filter>>& rows, std::string& error);

}  // namespace mirrorcal::calibration
