// The batch maximum-likelihood solution of a calibration (`mirrorcal batch`, montecarlo --batch):
// the reference the filter is measured against, and the tool a user would otherwise reach for.
//
// The same model and priors as the filter (mirror_model.hpp, prior.hpp), solved over the whole
// recording at once by sparse Levenberg-Marquardt (Ceres): one IMU state [p, v, q_n_b, b_a, b_g]
// at every frame with markers (and one at the first IMU sample, where the priors' guesses hold),
// joined by the IMU's integration between them (propagate_imu, the filter's own Runge-Kutta) with
// its covariance, the bias random walks, every marker's reprojection through the mirror, and the
// priors. Its covariance is the inverse of the information at the solution, in the calibration
// block's layout (CalibrationLayout), so it writes mirrorcal-result.yaml as a calibration does.
// With an IMU model of intrinsics they are estimated too, as calibrate --imu-model does. Host
// only: it allocates freely and needs Ceres.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "mirrorcal/calibration/result.hpp"
#include "mirrorcal/estimator/calibration_filter.hpp"
#include "mirrorcal/io/recording.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mirrorcal::evaluation {

// What the batch solves: the streams, the filter's configuration for them (gravity, IMU noise,
// pixel noise, the camera where it is not estimated), the priors, and the camera parameters
// estimated as the filter's NK counts them (0, 4, 5 or 8; the app's camera_block). With NK > 0
// the camera's guess is priors.intrinsics_guess.
struct BatchInput {
  const std::vector<ImuSample>* imu = nullptr;
  const std::vector<io::ObservedFrame>* frames = nullptr;
  CalibrationConfig config;
  io::RecordingPriors priors;
  int camera_parameters = 0;
  // The IMU's intrinsics estimated (the filter's NI): the model, its guess and the datasheet's
  // tolerances as their 1-sigma (imu.yaml's; calibrate's start).
  ImuModel imu_model = ImuModel::kCalibrated;
  ImuIntrinsics<double> imu_guess{};
  ImuIntrinsicsSigma imu_tolerances{};
  int width = 640, height = 480;  // the image's, for the result files
};

struct BatchOptions {
  // The initial trajectory is grown window by window (batch.cpp, grow_trajectory): each new
  // stretch of this many seconds starts from the IMU integrated on from the last, and is solved
  // with the stretch before it.
  double window_s = 1.0;
  int max_iterations = 200;  // per Levenberg-Marquardt solve
  // One line per stage (the growth, each full solve), for a user waiting on a long recording.
  std::function<void(const std::string&)> progress;
};

// How the solution went.
struct BatchReport {
  std::size_t frames = 0;  // frames with markers: one state each
  std::size_t reprojections = 0;
  int solves = 0;            // Levenberg-Marquardt solves, growth included
  int iterations = 0;        // their iterations, in all
  int final_iterations = 0;  // the last full solve's
  bool converged = false;    // the last full solve met its tolerances, at the offset's own times
  int retimings = 0;         // the frames' IMU times moved to the time offset's estimate
  double reprojection_rms_px = 0.0;
  // The calling thread's CPU time (s), from the frames' selection to the covariance.
  double cpu_s = 0.0;
};

// Solves input; false with a message when it cannot (no frames within the IMU's span, a solver
// failure, a covariance that cannot be computed). result holds the estimate in the filter's format
// (mirrorcal-result.yaml; the self-check's fields that only a filter fills are left empty).
bool solve_batch(const BatchInput& input, const BatchOptions& options,
                 calibration::CalibrationResult& result, BatchReport& report, std::string& error);

// The batch's input for a simulated run of s on data, from the priors of the prior drawn for it
// (sim::simulation_prior, io::from_prior): the configuration the filter is given
// (scenario_config).
BatchInput simulated_batch_input(const sim::Scenario& s, const sim::SimData& data,
                                 const io::RecordingPriors& priors, int camera_parameters = 0,
                                 ImuModel imu_model = ImuModel::kCalibrated);

// A result's calibration block against the truth, as the filter's history judges its estimate
// (the rotation's error log(R_true^T R_est)), and its NEES under the result's covariance.
struct TruthError {
  Eigen::VectorXd error;  // calibration_params() order, SI
  double nees = 0.0;
};
TruthError truth_error(const calibration::CalibrationResult& r, const io::RecordingTruth& truth);

}  // namespace mirrorcal::evaluation
