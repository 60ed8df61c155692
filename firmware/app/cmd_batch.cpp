// mirrorcal batch: the batch maximum-likelihood solution of a recording (evaluation/batch.hpp),
// the reference the filter is measured against. Host only: it needs Ceres (MIRRORCAL_BATCH;
// host_tools.cpp and board_tools.cpp say so in builds without it).
#include <cstdio>
#include <string>

#include "build_tools.hpp"
#include "cli.hpp"
#include "mirrorcal/calibration/recording_run.hpp"
#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/evaluation/batch.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// The estimate as calibrate prints it, with the error against truth.yaml when there is one.
void print_solution(const CalibrationResult& r, const io::Recording& rec) {
  const evaluation::TruthError t =
      rec.has_truth ? evaluation::truth_error(r, rec.truth) : evaluation::TruthError{};
  const CalibrationLayout layout = r.layout();
  const Eigen::Vector3d angles = display_angles(r.q_b_c);
  std::printf("\n%-17s %-5s %24s%s\n", "param", "unit", "estimate +-1sigma",
              rec.has_truth ? "  error/sig (truth.yaml)" : "");
  for (std::size_t j = 0; j < r.params.size(); ++j) {
    const ParamInfo& p = r.params[j];
    const int i = static_cast<int>(j) - layout[p.group].begin;  // within its group
    double value = 0.0;
    switch (p.group) {
      case CalibrationGroup::kCameraPosition:
        value = r.p_b_c(i) * p.scale;
        break;
      case CalibrationGroup::kCameraRotation:
        value = angles(i);
        break;
      case CalibrationGroup::kMarkers:
        value = r.markers[static_cast<std::size_t>(i / 3)](i % 3) * p.scale;
        break;
      case CalibrationGroup::kTimeOffset:
        value = r.t_d * p.scale;
        break;
      default:
        value = estimated_camera_parameter(
                    r, static_cast<int>(j) - layout[CalibrationGroup::kIntrinsics].begin) *
                p.scale;
    }
    std::printf("%-17s %-5s %14.4f +-%-8.4f", p.name.c_str(), p.unit.c_str(), value,
                r.sigma[j] * p.scale);
    if (rec.has_truth) std::printf(" %+10.2f", t.error(static_cast<long>(j)) / r.sigma[j]);
    std::printf("\n");
  }
  if (rec.has_truth) print_final_nees(r.params.size(), t.nees, " against truth.yaml");
}

}  // namespace

int cmd_batch(int argc, char** argv) {
  Options o;
  std::string err;
  if (!parse(argc, argv, 2, {"out", "imu-model"}, {"intrinsics", "hold-skew"}, o, err, 1))
    return refuse(err);
  if (o.positional.size() != 1)
    return refuse("batch needs a recording folder DIR\n" + usage("batch"));
  const std::string in = o.positional[0];
  int markers = kDefaultMarkerCount;
  if (!io::recording_marker_count(in, markers, err)) return refuse(err);
  if (!io::has_features_csv(in))
    return refuse(
        in +
        " has no mav0/cam0/features.csv: batch solves labelled markers. Calibrate the recording "
        "first (calibrate finds the markers in its images and writes them to its features.csv)");
  io::Recording rec;
  if (!io::read_recording(in, markers, rec, err)) return refuse(err, 1);
  for (const auto& note : rec.notes) std::fprintf(stderr, "mirrorcal: note: %s\n", note.c_str());
  for (const auto& w : rec.warnings) std::fprintf(stderr, "mirrorcal: WARNING: %s\n", w.c_str());
  const bool intrinsics = o.flag("intrinsics") || rec.priors.estimate_intrinsics;
  const bool hold_skew = o.flag("hold-skew") || rec.priors.hold_skew;
  if (o.flag("hold-skew") && !intrinsics)
    return refuse("--hold-skew applies when the intrinsics are estimated (--intrinsics)");
  // The IMU model as calibrate takes it: --imu-model, imu.yaml's imu_model, or a MEMS part's.
  ImuModel imu_model = kDefaultImuModel;
  if (!calibration_imu_model(o, rec.sensors, in, imu_model, err)) return refuse(err);
  std::string out;
  if (!make_out_dir(o, "out/batch", out, err)) return refuse(err, 1);

  evaluation::BatchInput input;
  input.imu = &rec.imu;
  input.frames = &rec.frames;
  input.config = recording_config(rec);
  input.priors = rec.priors;
  input.camera_parameters = camera_block(intrinsics, hold_skew, rec.priors.estimate_distortion);
  input.imu_model = imu_model;
  input.imu_tolerances = rec.sensors.imu_tolerances;
  input.width = rec.sensors.width;
  input.height = rec.sensors.height;
  evaluation::BatchOptions options;
  options.progress = [](const std::string& line) { std::printf("%s\n", line.c_str()); };
  std::printf("mirrorcal batch: %s: %zu IMU samples, %zu frames; IMU model %s; %s\n", in.c_str(),
              rec.imu.size(), rec.frames.size(), to_string(imu_model),
              input.camera_parameters > 0 ? "camera intrinsics estimated too"
                                          : "camera intrinsics from camchain.yaml");
  std::fflush(stdout);
  CalibrationResult r;
  evaluation::BatchReport report;
  if (!evaluation::solve_batch(input, options, r, report, err)) return refuse(in + ": " + err, 1);
  r.recording_fingerprint = rec.fingerprint;
  r.rostopic = rec.sensors.rostopic;
  print_solution(r, rec);
  std::printf(
      "batch: %zu states, %zu marker reprojections (rms %.3f px), %d solves, %d iterations "
      "(%d in the last, %s), %d retimings; %.2f s CPU\n",
      report.frames + 1, report.reprojections, report.reprojection_rms_px, report.solves,
      report.iterations, report.final_iterations, report.converged ? "converged" : "NOT converged",
      report.retimings, report.cpu_s);
  print_result_warnings(r);
  // An unconverged solution is not the reference: its files, which say nothing of it, are not
  // written, so that neither export nor a campaign takes it for one (an earlier result stays).
  if (!report.converged) {
    std::fprintf(stderr,
                 "mirrorcal: the batch solution did not converge (the solver's last solve met none "
                 "of its tolerances in %d iterations, or the time offset still moved): it is not "
                 "the maximum-likelihood solution, and no files were written (exit status %d)\n",
                 report.final_iterations, kExitNotConsistent);
    return kExitNotConsistent;
  }
  io::OutputSet files;
  if (!write_camchain_imucam(files, out + "/camchain-imucam.yaml", r, err) ||
      !write_result_yaml(files, out + "/mirrorcal-result.yaml", r, err) || !files.commit(err))
    return refuse(err, 1);
  std::printf("wrote %s/camchain-imucam.yaml, mirrorcal-result.yaml\n", out.c_str());
  return calibration_exit_status(r);
}

}  // namespace mirrorcal::app
