// The calibration pipeline: one calibration through the deterministic loop, end to end, on data
// held in memory or replayed from a recording's files: the passes over the data, the refinement
// after them, the start from an earlier calibration, and the files a run writes.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "mirrorcal/calibration/history.hpp"
#include "mirrorcal/calibration/result.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/io/replay.hpp"
#include "mirrorcal/loop/loop.hpp"

namespace mirrorcal::calibration {

class ImageBlobs;  // image_markers.hpp
struct LedNaming;  // image_markers.hpp

// How detection did against the rendered truth (--frames only).
struct DetectionReport {
  std::uint64_t frames = 0;
  std::uint64_t markers_drawn = 0;        // reflections in the image
  std::uint64_t markers_labelled = 0;     // reflections the detection reported
  std::uint64_t wrong_labels = 0;         // reported under one marker's label at another's spot
  std::uint64_t wrong_labels_before = 0;  // the same in the passes before the last (the rest of
                                          // the report is the last pass's)
  std::uint64_t dropped_in_doubt = 0;     // labels withheld: ambiguous, crossing or merged
  std::uint64_t unlabelled_blobs = 0;     // blobs no marker took (spurious, merged, crowded)
  double centroid_rms_px = 0.0;           // correctly labelled, against where the spot was drawn
  double centroid_max_px = 0.0;
  double centroid_mean_px[2] = {0.0, 0.0};  // the mean error in u and v: detection's bias
  double ms_per_frame = 0.0;                // detection and identification, wall time
  double read_ms_per_frame = 0.0;           // reading the image first (calibrate from images)
};
// What the self-check needs of a detection report (CalibrationResult::detection).
inline CalibrationResult::DetectionCounts detection_counts(const DetectionReport& d) {
  return {d.frames, d.markers_labelled, d.dropped_in_doubt, d.unlabelled_blobs};
}

// The IMU's residual over one frame interval of the refinement's smoothed motion (run.cpp,
// smoothed_trajectory): the rotation and velocity the smoothed motion moved by beyond what the
// IMU's samples integrate to from its estimate at the interval's start (the smoothed process
// noise), as the body rate and specific force that would explain them over the interval, in the
// body frame at its end. Under the model each axis scatters with the white noise's 1-sigma over the
// interval, noise_density / sqrt(dt_s), less what the smoothing took out; a scale factor or axis
// the model lacks shows as structure that follows the motion (Kalibr's accelerometer and gyroscope
// errors, over the frame interval rather than one sample).
struct ImuResidual {
  std::int64_t t_ns = 0;  // the interval's end: the frame's stamp
  double dt_s = 0.0;
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();   // rad/s
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();  // m/s^2
};

// One calibration of M markers: its final estimate and result, the estimate after every frame
// (history), and what the loop, the filter and detection met on the way. NK camera parameters
// and NI of the IMU's are estimated (MirrorState).
template <int M, int NK, int NI = 0>
struct CalibrationRun {
  using Filter = CalibrationFilter<double, M, NK, NI>;
  using State = typename Filter::State;
  State truth{};
  // One row per frame, and the final one (last pass); in a temporary file (record_store.hpp).
  RecordStore<HistoryRow<Filter>> history;
  HistoryRow<Filter> first_frame;          // the first pass's first row: after one frame
  typename Filter::Covariance covariance;  // the final one (stage 2 starts from stage 1's)
  CalibrationResult result;
  FilterCounters filter_counters;
  loop::LoopCounters loop_counters;
  std::uint64_t markers_out_of_image = 0;
  std::size_t imu_samples = 0, frames = 0;
  DetectionReport detection;    // --frames, and calibrate from images
  bool features_found = false;  // the markers were found in images: features.csv with the results
  // For the report: the prior's 1-sigma of each calibration state (SI, calibration_params()
  // order), against which the data's narrowing of it is judged, and the pixel noise assumed.
  std::vector<double> prior_sigma;
  double pixel_sigma = 0.0;
  std::uint64_t gate_after_frames = 0;  // frames the estimate had to settle before the gate
  bool has_truth = false;               // the history rows carry the error against truth
  // Beside history, when a smoother asked for them (a temporary file too).
  std::optional<RecordStore<MotionRow<Filter>>> motion;
  // The markers the refinement found to be outliers at its converged solution, which its passes
  // and the ideal-IMU check drop (run.cpp, find_outliers).
  OutlierVeto<M> veto;
  // The IMU's residuals along the last refinement step's smoothed motion, one per frame interval
  // the filter propagated across (none across a restart); none without a refinement step.
  std::shared_ptr<const RecordStore<ImuResidual>> imu_residuals;
};

// What the loop consumes, filled before it starts (the loop itself never allocates): the streams
// held in memory, or read from a recording's files again in each pass (calibrate), so that memory
// does not grow with the recording.
struct LoopData {
  std::vector<ImuSample> imu;             // timestamp order
  std::vector<io::ObservedFrame> frames;  // timestamp order; any subset of markers each
  std::shared_ptr<const io::RecordingStreams> streams;  // instead of imu and frames
  io::RecordingStats stats;                             // of the streams
  std::int64_t imu_period_ns = 5'000'000;               // nominal IMU period
  int width = 640, height = 480;                        // image size, for the result files
  // Set: the markers are found in the streams' images (RecordingStreams::open_images) by the
  // board's detection, labelled with the filter's prediction, in every pass; it gets how that went
  // in the last pass over all the data.
  std::shared_ptr<DetectionReport> image_detection;
  std::shared_ptr<ImageBlobs> image_blobs;  // with image_detection: the images detected once
  io::MarkerLeds leds;  // the markers' LEDs, as the detection in images needs them
  // LEDs in images that do not blink their names: the names a look at the first frames gave the
  // reflections' tracks by the rig's shape (name_leds_by_shape), which every pass labels them by
  // from the first frame.
  std::shared_ptr<const LedNaming> led_naming;

  std::size_t imu_samples() const { return streams ? stats.imu_samples : imu.size(); }
  std::size_t frame_count() const { return streams ? stats.frames : frames.size(); }
  // A pass's sources, from the start of the streams.
  std::unique_ptr<hal::ImuSource> open_imu() const;
  template <int M>
  std::unique_ptr<hal::MarkerSource<M>> open_markers() const;
};

// The nominal period of an IMU sampled at rate_hz.
inline std::int64_t imu_period_ns(double rate_hz) {
  return static_cast<std::int64_t>(1e9 / rate_hz);
}

// What a run may add to the loop: marker frames from elsewhere than LoopData::frames (sim --frames:
// rendered frames through the board's detection, relabelled with the filter's prediction), and a
// profiler timing its stages.
template <int M>
struct LoopHooks {
  hal::MarkerSource<M>* source = nullptr;
  hal::MarkerRelabeler<M>* relabeler = nullptr;
  loop::LoopProfiler* profiler = nullptr;
  // With source: how its detection did over the pass (frames rendered and detected), which the
  // passes judge as they judge a recording's images (identification_failed).
  std::function<DetectionReport()> detection;
};

// The constants below are measured in docs/estimator.md, "Passes and refinement" and "Noise levels
// from the data", which link to the measurements that set them.
//
// Passes over the data that a calibration makes by default. The first pass linearises the
// measurements about the user's guesses (markers known to 10 cm while their mirror images are
// 60 cm away): those early linearisation errors stay in the estimate and make the filter
// over-confident. The second pass starts the calibration parameters at the first pass's estimate,
// with the prior's covariance; its estimate is consistent and as accurate as a run started at the
// truth. The data count twice only through the prior mean, whose weight against the data's is
// (final sigma / prior sigma)^2, negligible in stage 1. A parameter whose prior still weighs more
// than kNegligiblePriorWeight (stage 2's start from stage 1's covariance) keeps its prior mean:
// moving it counts stage 2's data twice and makes it over-confident.
constexpr int kDefaultPasses = 2;
constexpr double kNegligiblePriorWeight = 1e-2;
// A first pass that starts from guesses several sigma off can diverge badly enough that the second
// pass, started from it, still gates more than kSuspectGatedFraction of the markers, and a third
// from its estimate comes back. So a pass the self-check finds suspect (result.hpp) is followed by
// another, up to kMaxPasses; a good run stops at kDefaultPasses. Tested by
// Cli.ASecondPassThatFitsBadlyIsFollowedByAnother (tests/app/cli_test.cpp).
constexpr int kMaxPasses = 6;
// A run still suspect after kDefaultPasses has locked onto a wrong solution, and passes from its
// estimate rarely leave it; which runs lock on is chaotic (a slightly different guess of the time
// offset decides it). So the next pass starts again from the prior's guesses with the pixel noise
// taken kAnnealedPixelNoise times larger: each frame then pulls only as hard as its linearisation
// about guesses far off can bear, the estimate walks to the solution instead of locking on, and
// the pass after it, at the true noise, starts from its estimate. A factor of a few still locks
// on; this one lies inside the range that brought every such run back. Tested by
// Cli.ARunThatDivergedIsFlaggedInTheOutputAndTheResult (tests/app/cli_test.cpp).
constexpr double kAnnealedPixelNoise = 10.0;
// A run still suspect after that restart and the pass that followed it restarts once more (pass
// 5), and starts the IMU where the first frames put it with the calibration frozen at its guesses
// (imu_start_from under the prior's covariance with the calibration block times
// kFrozenCalibration), not at the prior's guess of the motion. On a slow sweep a guessed velocity
// off by more than the motion itself (0.4 m/s; the random family guesses it to 0.2 m/s per axis)
// is what locks a pass on: the images do not grow or shrink as that velocity says, and the filter
// trades it against the rig's weak scale, shrinking markers and distance together until the
// camera meets the mirror and no marker can be predicted (docs/campaign/batch, seed 3, runs 115
// and 152, which the batch solves; tests/calibration/restart_test.cpp). Under frozen guesses the
// scale cannot move, and the velocity the images show is taken instead. Only as the second
// restart, and kept only if the pass after it is no longer suspect (else the first restart's run
// stands): with guesses far off, the motion fitted under them can be far off too. As the first
// restart it lost a run of blinking identical LEDs that the guessed motion brings back; kept when
// still suspect, it left some runs of 10 % mis-detections better and one worse (flagged where
// the refinement had brought the first restart's back).
constexpr double kFrozenCalibration = 1e-6;
// Gauss-Newton refinements after the passes (run.cpp): each a tracking pass along the estimate,
// smoothed, and a pass linearised along it, repeated until a step moves the calibration by less
// than kConvergedStepSigmas of its sigmas (Mahalanobis), at most kMaxRefinements times. A second
// step moves the linearisation point from the free passes' estimate to the first step's solution,
// which leaves fewer runs far off; in a good run it is already next to nothing, and forcing more
// steps on every run changed nothing, so the cap only bounds what a run that does not converge
// costs.
constexpr int kMaxRefinements = 4;
constexpr double kConvergedStepSigmas = 1.0;
// A marker whose residual at the refinement's converged solution (its tracking pass) lies beyond
// kOutlierSigmas of the pixel noise is an outlier (a wrong blob the frame's screen let through):
// the refinement's passes drop it (run.cpp, find_outliers). Unless it lies beyond in more than
// kOutlierMaxShare of its frames: then its own model is off, not a blob (docs/estimator.md, "The
// update").
constexpr double kOutlierSigmas = 6.0;
constexpr double kOutlierMaxShare = 0.05;
// Those steps regress each frame's measurement over the filter's spread about the trajectory
// (SigmaPointParams::linearised_alpha_scale 1), which pulls the iteration in from estimates far
// off. But their fixed point is where the data's error follows the Jacobian while the covariance
// follows the regression's slopes, which the wide spread of the first seconds bends: the estimate
// keeps more of the prior's error than its covariance says, whatever the size of that error (a
// mismatch of the two linearisations, not a nonlinearity of the data). So one more step follows,
// linearised at the trajectory with alpha times kTangentAlphaScale: the measurement's Jacobian,
// the same for estimate and covariance (the Laplace approximation at the solution). Jacobian
// slopes in every step converge worse, so only the last step takes them. Its length is the
// self-check's refinement_step (result.hpp, kRefinementStepLimit). Tested by
// Refinement.KeepsOfTheGuessesErrorWhatItsCovarianceSays (tests/calibration/refinement_test.cpp).
constexpr double kTangentAlphaScale = 1.0 / 64.0;
// Noise estimation (Passes::estimate_noise): the calibrations it makes at most, and the change
// of the pixel noise's estimate under which it stops. The first starts from kNoiseStartScale
// times the stated pixel noise: a noise stated too small makes the gate reject the markers that
// would show it, and the estimate from those let through reads low; from above, the gate rejects
// nothing and the estimate comes down in a step or two. Tested by
// NoiseEstimation.FourRigsToldTheWrongNoiseCalibrateConsistently (noise_estimation_test.cpp).
constexpr int kMaxNoiseRuns = 4;
constexpr double kNoiseConvergedFraction = 0.03;
constexpr double kNoiseStartScale = 2.0;
// The ideal-IMU check (Passes::check_imu): the directions of the intrinsics it tests are those
// whose variance the data cut by at least kImuCheckMinInformation of the prior's (the others
// would divide by next to nothing), and it fails beyond the kImuCheckQuantile quantile.
constexpr double kImuCheckMinInformation = 0.1;
constexpr double kImuCheckQuantile = 0.999;
// The first pass number the check's passes ask hooks for (run_loop): after every other.
constexpr int kImuCheckPass = 1000;
// The stretch of data a later pass's IMU start is found from (run.cpp, imu_start_from): up to
// the kImuStartFrames-th frame with markers, at most kImuStartMaxS seconds.
constexpr int kImuStartFrames = 10;
constexpr double kImuStartMaxS = 2.0;

struct Passes {
  int min = kDefaultPasses;  // passes always made
  int max = kMaxPasses;      // passes made at most, while the last gated too many
  // Whether the Gauss-Newton refinement passes follow (run_loop): they replay the data twice more,
  // which a source that delivers its data once (a camera) cannot.
  bool refine = true;
  // Whether the noise levels are estimated from the data and the calibration made again with them
  // (noise_estimate.hpp, run_loop): the IMU's white-noise densities from its samples before the
  // passes, the pixel noise from the refinement's last linearised pass, until it moves by less
  // than kNoiseConvergedFraction (at most kMaxNoiseRuns calibrations). Needs the refinement.
  bool estimate_noise = false;
  // Whether a calibration that assumes an ideal IMU (stage 1, NI = 0) checks that assumption with
  // one more pass, the scale factors and axes estimated from these tolerances (imu_result.hpp,
  // IdealImuCheck; the self-check's imu_not_ideal). Needs the refinement, and a build with the
  // scale-misalignment model.
  bool check_imu = true;
  ImuIntrinsicsSigma imu_tolerances{};
  static Passes exactly(int n) { return {n, n, true}; }
  static Passes once() { return {1, 1, false}; }
};

// Runs the loop on data from the initial estimate (x0, p0), passes.min times and then again while
// the last pass gated too many (see Passes); the result is the last pass's. With truth, each
// history row carries the error and NEES against it. progress(f) is called with the fraction done
// now and then (an extra pass starts it again from the fraction the passes before it make);
// hooks(pass), if given, adds a marker source or profiler to a pass.
template <int M, int NK, int NI = 0>
CalibrationRun<M, NK, NI> run_loop(const CalibrationConfig& config,
                                   const typename CalibrationRun<M, NK, NI>::State& x0,
                                   const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0,
                                   const LoopData& data,
                                   const typename CalibrationRun<M, NK, NI>::State* truth,
                                   const std::function<void(double)>& progress = {},
                                   const std::function<LoopHooks<M>(int pass)>& hooks = {},
                                   Passes passes = {});

// One pass of the loop over the data from (x0, p0), nothing more: no further pass, no refinement
// (what a filter linearised at the truth ends with: evaluation's data_limit_sigmas).
template <int M, int NK, int NI = 0>
CalibrationRun<M, NK, NI> run_single_pass(
    const CalibrationConfig& config, const typename CalibrationRun<M, NK, NI>::State& x0,
    const typename CalibrationRun<M, NK, NI>::Filter::Covariance& p0, const LoopData& data,
    const typename CalibrationRun<M, NK, NI>::State* truth);
// The filters the product instantiates for each built M and IMU model (MIRRORCAL_FOR_EACH_FILTER):
// stage 1 (NK = 0), stage 2 (NK = 5), stage 2 with the skew held at the configured value (NK = 4:
// Kalibr and OpenVINS have no slot for skew), and stage 2 with the lens's coefficients too, skew
// held (NK = 8, estimate_distortion).
#define MIRRORCAL_RUN_LOOP(M, NK, NI)                                              \
  CalibrationRun<M, NK, NI> run_loop<M, NK, NI>(                                   \
      const CalibrationConfig&, const CalibrationRun<M, NK, NI>::State&,           \
      const CalibrationRun<M, NK, NI>::Filter::Covariance&, const LoopData&,       \
      const CalibrationRun<M, NK, NI>::State*, const std::function<void(double)>&, \
      const std::function<LoopHooks<M>(int)>&, Passes)
#define MIRRORCAL_RUN_SINGLE_PASS(M, NI)                                    \
  CalibrationRun<M, 0, NI> run_single_pass<M, 0, NI>(                       \
      const CalibrationConfig&, const CalibrationRun<M, 0, NI>::State&,     \
      const CalibrationRun<M, 0, NI>::Filter::Covariance&, const LoopData&, \
      const CalibrationRun<M, 0, NI>::State*)
#define MIRRORCAL_EXTERN_RUN_LOOP_(M, NK, NI) extern template MIRRORCAL_RUN_LOOP(M, NK, NI);
MIRRORCAL_FOR_EACH_FILTER(MIRRORCAL_EXTERN_RUN_LOOP_)
#undef MIRRORCAL_EXTERN_RUN_LOOP_
#define MIRRORCAL_EXTERN_RUN_SINGLE_PASS_(M, NI) extern template MIRRORCAL_RUN_SINGLE_PASS(M, NI);
MIRRORCAL_FOR_EACH_STAGE1_FILTER(MIRRORCAL_EXTERN_RUN_SINGLE_PASS_)
#undef MIRRORCAL_EXTERN_RUN_SINGLE_PASS_

// An earlier calibration's camera pose and markers with their covariance, as a later one starts
// from them (stage 2 from stage 1; `calibrate --from`).
io::CalibrationStart calibration_start(const CalibrationResult& earlier);
// What a result started from an earlier calibration owes to it, for its self-check: whether that
// one said consistent, and the IMU model it estimated.
void note_start(const io::CalibrationStart& earlier, CalibrationResult& r);

// Starts the camera pose, markers and time offset at an earlier calibration's estimate and
// covariance in place of the prior's guesses, and the IMU's intrinsics too where it estimated the
// state's model (jointly with them: the gyro's axes and the camera's rotation are seen together).
// The IMU's motion state and the camera's intrinsics keep the prior's, and so does the time offset
// if the earlier result has none. The markers must be as many as the state's.
template <class State, class Covariance>
void start_from(const io::CalibrationStart& earlier, State& x0, Covariance& p0) {
  // The earlier block is the state's calibration block up to the intrinsics.
  constexpr int B = State::kCalibrationBegin, K = State::kImu, NI = State::kImuIntrinsics;
  const int l = calibration_layout(State::kMarkers, 0, earlier.has_t_d).size();
  x0.p_b_c = earlier.p_b_c;
  x0.q_b_c = earlier.q_b_c;
  for (int i = 0; i < State::kMarkers; ++i)
    x0.markers.template segment<3>(3 * i) = earlier.features_c[static_cast<std::size_t>(i)];
  if (earlier.has_t_d) x0.t_d = earlier.t_d;
  p0.block(B, 0, l, State::kDim).setZero();
  p0.block(0, B, State::kDim, l).setZero();
  p0.block(B, B, l, l) = earlier.covariance;
  if constexpr (NI > 0) {
    if (earlier.imu_model != State::kImuModel || earlier.imu_covariance.rows() != NI ||
        earlier.imu_covariance.cols() != l + NI)
      return;  // the prior's, independent of the earlier block
    x0.imu = earlier.imu_intrinsics.template cast<typename State::Scalar>();
    p0.template block<NI, State::kDim>(K, 0).setZero();
    p0.template block<State::kDim, NI>(0, K).setZero();
    p0.template block<NI, NI>(K, K) = earlier.imu_covariance.rightCols(NI);
    p0.block(K, B, NI, l) = earlier.imu_covariance.leftCols(l);
    p0.block(B, K, l, NI) = earlier.imu_covariance.leftCols(l).transpose();
  }
}

// camchain-imucam.yaml, mirrorcal-result.yaml and estimates.csv of a run, in dir, and imu.yaml when
// it estimated the noise: added to out, or written.
template <int M, int NK, int NI>
bool add_run_outputs(io::OutputSet& out, const std::string& dir,
                     const CalibrationRun<M, NK, NI>& run, std::string& error) {
  return write_camchain_imucam(out, dir + "/camchain-imucam.yaml", run.result, error) &&
         (!run.result.noise.estimated ||
          add_estimated_imu_yaml(out, dir + "/imu.yaml", run.result.noise, error)) &&
         write_result_yaml(out, dir + "/mirrorcal-result.yaml", run.result, error) &&
         (!run.result.imu.estimated() ||
          write_openvins_imu_chain(out, dir + "/kalibr_imu_chain.yaml", run.result.imu, error)) &&
         write_estimates_csv(out, dir + "/estimates.csv", run.history,
                             run.result.intrinsics.distortion, error) &&
         (!run.features_found ||
          write_features_csv(out, dir + "/features.csv", run.history, error));
}
template <int M, int NK, int NI>
bool write_run_outputs(const std::string& dir, const CalibrationRun<M, NK, NI>& run,
                       std::string& error) {
  io::OutputSet out;
  return add_run_outputs(out, dir, run, error) && out.commit(error);
}

}  // namespace mirrorcal::calibration
