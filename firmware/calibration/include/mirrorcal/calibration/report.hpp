// The report a user judges a calibration by, without ground truth. report.txt opens with the
// verdict (the calibration, its sigmas, and whether the self-check of result.hpp trusts it), then
// the reprojection residuals, the normalised innovation squared against its chi-square band, the
// IMU's residuals and biases and the excitation the data had; report.html holds the same text and
// its plots (base64 PNG: one self-contained file); residuals.csv and imu_residuals.csv the
// residuals the statistics are of.
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "mirrorcal/calibration/record_store.hpp"
#include "mirrorcal/calibration/result.hpp"
#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::calibration {

// A calibration state whose final sigma is still above this fraction of its prior's is reported as
// weakly observed: the motion left it mostly to the prior.
constexpr double kWeaklyObservedRatio = 0.5;
// The same for a state that started from an earlier calibration's estimate and covariance (stage
// 1, --from): data as informative as the earlier ones bring it to 0.71 of that.
constexpr double kWeaklyObservedFromEarlierRatio = 0.9;
// The normalised innovation squared is judged over windows of this many frames with markers used.
constexpr int kNisWindowFrames = 60;

// One marker's residual in one frame: measured minus predicted at the estimate after the frame's
// update (px).
struct ResidualSample {
  double t_s = 0.0;
  int marker = 0;  // 0-based
  double du = 0.0, dv = 0.0;
  // After the frames the estimate needs to settle from the prior's guesses (the gate's start,
  // CalibrationConfig::gate_after_frames): the statistics are of these.
  bool settled = true;
};

// The most calibration states a report shows: stage 2 with the lens's coefficients (p_b_c, the
// rotation, the most markers this build has, the time offset, fu fv cu cv and four coefficients).
constexpr int kMaxReportStates = calibration_layout(kMaxMarkerCount, 8).size();

// One history row as the report plots it: the estimate after one frame (or the final estimate).
struct ReportRow {
  double t_s = 0.0;
  // Each calibration state in display units (ParamInfo::scale); the rotation as the components of
  // log(R_final^T R), deg.
  std::array<double, kMaxReportStates> estimate{}, sigma{};
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero(), gyro_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d rotation = Eigen::Vector3d::Zero();   // log(R_n_b(0)^T R_n_b(t)), rad
  double normal_position = 0.0, normal_velocity = 0.0;  // along the mirror's normal (z of n)
  int markers_seen = -1;                                // in the row's frame; -1: the final row
  double nis = 0.0;
  int nis_dof = 0;
};

// What the report shows, in SI units unless said otherwise. Its series (a row per history row:
// each frame, and the final estimate; each marker's residual in each frame) are held in temporary
// files like the history itself (record_store.hpp): memory does not grow with the recording.
struct ReportData {
  std::string title;  // the command and what it ran on
  CalibrationResult result;
  double pixel_sigma = 1.0;         // px, what the filter assumed
  std::vector<double> prior_sigma;  // calibration_params() order; empty if unknown
  // The camera pose, markers and time offset started from an earlier calibration (stage 1,
  // calibrate --from): their prior sigmas are its.
  bool from_earlier = false;
  bool has_truth = false;
  double final_nees = 0.0;  // against the truth, if any
  RecordStore<ResidualSample> residuals{"the report's residuals"};
  // The IMU's residuals along the refinement's smoothed motion (CalibrationRun's); none without it.
  std::shared_ptr<const RecordStore<ImuResidual>> imu_residuals;
  RecordStore<ReportRow> rows{"the report's series"};
  double settled_from_s = 0.0;  // the first frame after those the estimate needed to settle
  loop::LoopCounters loop{};    // what the last pass met on its streams: IMU gaps, restarts
  // What the checks of the input found doubtful but not wrong (calibrate: a noise density unlike
  // the data's, ...), said beside the verdict: the self-check cannot see them.
  std::vector<std::string> input_warnings;
};

template <int M, int NK, int NI>
ReportData report_data(const CalibrationRun<M, NK, NI>& run, const std::string& title);

// A sample visited value by value: sample(f) calls f with each of its values (not NaN), in the
// same order each time it is called (one pass over a file-backed store, or over a vector).
using Sample = std::function<void(const std::function<void(double)>&)>;

// The k-th smallest (0-based, k < the sample's size) of a sample's values, exactly, in memory that
// does not grow with the sample: each pass counts the values into bins between the least and the
// greatest value still in play and keeps the bin that holds the k-th, until at most a batch of
// values is left, which is sorted.
double kth_smallest(const Sample& sample, std::size_t k);

// Mean, median (exact), standard deviation and maximum of a sample (all 0 when it is empty), in
// passes over it (memory bounded whatever its size).
struct SampleStats {
  std::size_t n = 0;
  double mean = 0.0, median = 0.0, std = 0.0, max = 0.0;
};
SampleStats sample_stats(const Sample& sample);
SampleStats sample_stats(const std::vector<double>& values);

// The IMU's residuals (ImuResidual) as the report states them: each axis's value, and the same in
// the white noise's 1-sigma over its interval (noise_density / sqrt(dt)), for the gyro (sensor 0)
// or the accelerometer (1); f(value, in_sigmas) for the axis of each interval there is.
void for_each_imu_residual(const ReportData& d, int sensor, int axis,
                           const std::function<void(double, double)>& f);

// The normalised innovation squared summed over windows of kNisWindowFrames frames with markers
// used (the last window may be shorter), handed to f in time order.
struct NisWindow {
  double t_s = 0.0;  // its middle
  double nis = 0.0;
  int dof = 0;
};
void for_each_nis_window(const ReportData& d, const std::function<void(const NisWindow&)>& f);

// A figure of report.html: its caption and its PNG's bytes.
struct ReportFigure {
  std::string caption, png;
};
// Draws report.html's figures; none, with the reason in why, if it cannot. The host's program
// draws them with gnuplot (firmware/evaluation's report_plots.hpp); the board's has no drawer.
using ReportDrawer = std::vector<ReportFigure> (*)(const ReportData& d, std::string& why);
// Whether report.html gets plots and what draws them, and PNGs drawn already (sim's error plots)
// to embed.
struct ReportPlots {
  bool draw = true;
  ReportDrawer drawer = nullptr;
  std::vector<std::string> extra_pngs;
};

// report.txt's text.
std::string report_text(const ReportData& d);
// report.txt, report.html, residuals.csv and imu_residuals.csv in dir, added to out (written when
// it commits). The plots are drawn in a temporary folder; without gnuplot the page says so and the
// text is whole.
bool write_report(io::OutputSet& out, const std::string& dir, const ReportData& d,
                  const ReportPlots& plots, std::string& error);
// For a run without data (`run` without frames): the verdict and the calibration only.
ReportData report_data_without_history(const CalibrationResult& r, const std::string& title);

// camchain-imucam.yaml, mirrorcal-result.yaml, estimates.csv (add_run_outputs) and the report of
// a run, in dir, written as one set; input_warnings: ReportData's.
template <int M, int NK, int NI>
bool write_run_outputs_and_report(const std::string& dir, const CalibrationRun<M, NK, NI>& run,
                                  const std::string& title, bool from_earlier,
                                  const ReportPlots& plots, std::string& error,
                                  const std::vector<std::string>& input_warnings = {}) {
  ReportData report = report_data(run, title);
  report.from_earlier = from_earlier;
  report.input_warnings = input_warnings;
  io::OutputSet out;
  return add_run_outputs(out, dir, run, error) && write_report(out, dir, report, plots, error) &&
         out.commit(error);
}

// RFC 4648 base64 of bytes, for data: URIs.
std::string base64(const std::string& bytes);

}  // namespace mirrorcal::calibration
